"""uPokeDB: set variables in a MOOSDB from the command line, and exit once the DB confirmed them.

`VAR=value` posts a double when the value reads as a number, else a string; `VAR:=value` always
posts a string. The prior value is what the DB answers to the registration, which it sends before
the echo of our own post (a client's messages are handled in order), so no waiting on timers.

Pokes are stamped on the DB's clock (our MOOS time plus the skew the DB's welcome reports), as
the C++ client corrects its MOOS time by that skew: a poke stamped with another time warp than
the community's (say the mission file on disk says 1, pAntler ran it with --MOOSTimeWarp=10)
would be dropped as skewed by the helm and the PID.
"""
from __future__ import annotations

import argparse
import asyncio
import sys
from dataclasses import dataclass

from .client import MOOSClient
from .formats import print_page, version_page
from .message import MOOSMsg
from .mission import add_db_arguments, db_address, read_mission
from .source import MissionFileError
from .xms import Scope, connect, format_table

DEFAULT_TIMEOUT = 5.0


@dataclass(frozen=True)
class Poke:
    var: str
    value: float | str


def parse_poke(text: str) -> Poke:
    """`VAR=value` (number if it reads as one) or `VAR:=value` (always a string)."""
    var, sep, value = text.partition("=")
    if not sep or not var or var == ":":
        raise ValueError(f"bad poke '{text}': expected VAR=value or VAR:=value")
    if var.endswith(":"):
        return Poke(var[:-1], value)
    try:
        return Poke(var, float(value))
    except ValueError:
        return Poke(var, value)


def pokes_from_block(mission, alias: str) -> list[Poke]:
    """--cache: the `poke = VAR=value` lines of the mission's uPokeDB block."""
    block = mission.process_config(alias) if mission is not None else None
    if block is None:
        raise ValueError(f"--cache: the mission has no ProcessConfig = {alias} block")
    pokes = []
    for entry in (e for e in block.entries if e.key.lower() == "poke"):
        try:
            pokes.append(parse_poke(entry.value))
        except ValueError as exc:
            raise entry.source.error(str(exc)) from None
    return pokes


EXAMPLE = """\
ProcessConfig = uPokeDB
{
  poke = DEPLOY=true         // used with --cache: VAR=value or VAR:=string, repeatable (default none)
  poke = RETURN:=false
}
"""
INTERFACE = """\
SUBSCRIPTIONS:
  every poked variable (to show its value before and after)
PUBLICATIONS:
  every poked variable
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="uPokeDB", description=__doc__.split("\n\n")[0])
    p.add_argument("args", nargs="*", help="[mission.moos] VAR=value | VAR:=string ...")
    add_db_arguments(p, "our time warp (default: mission or 1); pokes carry the DB's time whatever it is")
    p.add_argument("--cache", action="store_true", help="also poke the poke = lines of the mission's uPokeDB block")
    p.add_argument("--alias", default="uPokeDB", help="MOOS name of this client (default uPokeDB)")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT,
                   help="seconds to wait for the DB (default 5)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing when all went well")
    p.add_argument("-e", "--example", action="store_true", help="print an example uPokeDB config block")
    p.add_argument("-i", "--interface", action="store_true", help="print subscriptions and publications")
    p.add_argument("--version", action="version", version=version_page("uPokeDB"), help="print the release")
    return p


async def poke_db(host: str, port: int, pokes: list[Poke], *, name: str = "uPokeDB", time_warp: float = 1.0,
                  timeout: float = DEFAULT_TIMEOUT) -> tuple[Scope, Scope]:
    """Post each poke and wait for the DB's echo; returns (before, after).

    ConnectionError when no DB answers or it refuses us, TimeoutError when the echo does not come.
    """
    names = list(dict.fromkeys(p.var for p in pokes))
    before, after = Scope(names), Scope(names)
    confirmed = asyncio.Event()
    pending = {p.var: p.value for p in pokes}   # the last poke of a variable is the one confirmed
    posted = False

    def on_mail(mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if msg.key not in names:
                continue
            if posted and msg.source == name and msg.key in pending and msg.value == pending[msg.key]:
                after.take([msg])
                del pending[msg.key]
            elif msg.key in pending:
                before.take([msg])     # the DB's answer to our registration: the prior value
            else:
                after.take([msg])      # a later write by someone else
        if not pending:
            confirmed.set()

    def on_connect() -> None:
        nonlocal posted
        db_time = client.moos_time() + client.db_skew
        before.start = after.start = db_time
        for var in names:
            client.register(var)
        for poke in pokes:
            client.notify(poke.var, poke.value, time=db_time)
        posted = True

    client = MOOSClient(name, host, port, on_mail=on_mail, on_connect=on_connect, time_warp=time_warp)
    runner = asyncio.create_task(client.run())
    try:
        await connect(client, runner, timeout)
        await asyncio.wait_for(confirmed.wait(), timeout)
    finally:
        client.close()
        await asyncio.wait([runner], timeout=2.0)
    return before, after


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_intermixed_args(argv)
    if args.example or args.interface:
        print_page(EXAMPLE if args.example else INTERFACE)
        return 0
    words = list(args.args)
    try:
        mission = read_mission(words.pop(0)) if words and words[0].endswith(".moos") else None
        pokes = [parse_poke(w) for w in words] + (pokes_from_block(mission, args.alias) if args.cache else [])
        if not pokes:
            raise ValueError("nothing to poke: give VAR=value or VAR:=string")
        host, port, warp = db_address(mission, args.host, args.port, args.time_warp)
    except (ValueError, MissionFileError) as exc:
        print(f"uPokeDB: {exc}", file=sys.stderr)
        return 1
    try:
        before, after = asyncio.run(poke_db(host, port, pokes, name=args.alias, time_warp=warp,
                                            timeout=args.timeout))
    except (asyncio.TimeoutError, TimeoutError):
        print(f"uPokeDB: no confirmation from the MOOSDB on {host}:{port} within {args.timeout:g} s",
              file=sys.stderr)
        return 1
    except ConnectionError as exc:
        print(f"uPokeDB: {exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print("PRIOR to Poking the MOOSDB")
        print(format_table(before, {"source", "time"}))
        print("AFTER Poking the MOOSDB")
        print(format_table(after, {"source", "time"}), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
