"""uXMS: a terminal scope on a MOOSDB, plus non-interactive output for scripts.

Watches named variables and wildcard patterns (`NAV_*`), filtered by source; shows a table of
VarName / (S)ource / (T)ime / (C)ommunity / VarValue, as MOOS-IvP's uXMS does, or one line per
post in history mode. `--once` prints the table a single time and exits, for scripts.
"""
from __future__ import annotations

import argparse
import asyncio
import signal
import sys
import time
from dataclasses import dataclass, field

from .client import MOOSClient
from .message import SERVER_REQUEST_ID, MOOSMsg
from .formats import is_pattern, parse_bool, print_page, version_page, wild_match
from .mission import Mission, add_db_arguments, db_address, read_mission
from .source import MissionFileError

SHOW_FIELDS = ("source", "time", "community", "aux")
NOT_SET = "n/a"
DEFAULT_WAIT = 2.0


def value_text(msg: MOOSMsg, trunc: int = 0) -> str:
    """Strings in double quotes (as uXMS shows them), doubles compactly, binary by size."""
    if msg.is_binary():
        text = f"<binary: {len(msg.binary)} bytes>"
    elif msg.is_double():
        text = f"{msg.double:.12g}"
    else:
        text = f'"{msg.string}"'
    return text if trunc <= 0 or len(text) <= trunc else text[:trunc] + "..."


@dataclass
class Scope:
    """What uXMS has seen: the latest message of every watched variable, in watch order."""

    names: list[str]                                   # exact names and wildcard patterns
    sources: list[str] = field(default_factory=list)   # source patterns; empty = any
    start: float = 0.0        # (T)ime counts from here: the DB's start, as the C++ uXMS's time column
    db_started: bool = False  # start comes from DB_UPTIME (until then: our own start on the DB's clock)
    latest: dict[str, MOOSMsg] = field(default_factory=dict)

    def watches(self, msg: MOOSMsg) -> bool:
        if self.sources and not any(wild_match(p, msg.source) for p in self.sources):
            return False
        return any(wild_match(n, msg.key) if is_pattern(n) else n == msg.key for n in self.names)

    def note_db_start(self, mail: list[MOOSMsg]) -> None:
        """The first DB_UPTIME fixes `start` at the DB's start; call it before the mail is shown.

        (The DB's answer to ALL carries its variables stamped with their age, not their time: skipped.)"""
        uptime = next((m for m in mail if m.key == "DB_UPTIME" and m.is_double() and m.id != SERVER_REQUEST_ID), None)
        if uptime is not None and not self.db_started:
            self.start, self.db_started = uptime.time - uptime.double, True

    def take(self, mail: list[MOOSMsg]) -> list[MOOSMsg]:
        """Keep the watched messages; return them (for history and events output)."""
        seen = [m for m in mail if self.watches(m)]
        for msg in seen:
            self.latest[msg.key] = msg
        return seen

    def rows(self, novirgins: bool = False) -> list[tuple[str, MOOSMsg | None]]:
        rows = [(n, self.latest.get(n)) for n in self.names if not is_pattern(n)]
        matched = sorted(k for k in self.latest if k not in self.names)
        rows += [(k, self.latest[k]) for k in matched]
        return [(k, m) for k, m in rows if m is not None or not novirgins]


def format_table(scope: Scope, show: set[str], trunc: int = 0, novirgins: bool = False) -> str:
    """The uXMS table: VarName, then the chosen columns, then VarValue."""
    header = ["VarName"] + [label for key, label in (("source", "(S)ource"), ("time", "(T)ime"),
                                                     ("community", "(C)ommunity"), ("aux", "(A)ux Source"))
                            if key in show] + ["VarValue"]
    table = []
    for name, msg in scope.rows(novirgins):
        cells = [name]
        for key in SHOW_FIELDS:
            if key in show:
                cells.append(NOT_SET if msg is None else _field(msg, key, scope.start))
        cells.append(NOT_SET if msg is None else value_text(msg, trunc))
        table.append(cells)
    widths = [max(len(row[i]) for row in [header, *table]) for i in range(len(header))]
    lines = [header, ["-" * len(h) for h in header], *table]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in lines) + "\n"


def _field(msg: MOOSMsg, key: str, start: float) -> str:
    if key == "source":
        return msg.source
    if key == "time":
        return f"{msg.time - start:.2f}"
    if key == "community":
        return msg.community
    return msg.source_aux


def history_line(msg: MOOSMsg, start: float, trunc: int = 0) -> str:
    return f"{msg.time - start:<10.2f} {msg.key:<20} {msg.source:<15} {value_text(msg, trunc)}"


async def connect(client: MOOSClient, runner: asyncio.Task, timeout: float) -> None:
    """Wait for the handshake; ConnectionError saying why (no DB answering, or the DB refused us)."""
    waiting = asyncio.create_task(client.wait_connected(timeout))
    await asyncio.wait({waiting, runner}, return_when=asyncio.FIRST_COMPLETED)
    if client.poisoned:
        waiting.cancel()
        raise ConnectionError(f"the MOOSDB on {client.host}:{client.port} refused {client.name}: {client.poisoned}")
    if not await waiting:
        raise ConnectionError(f"no MOOSDB answering on {client.host}:{client.port}")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="uXMS", description=__doc__.split("\n\n")[0])
    p.add_argument("args", nargs="*", help="[mission.moos] then variables to watch (wildcards * and ? allowed)")
    p.add_argument("-a", "--all", action="store_true", help="watch every variable (same as the pattern *)")
    p.add_argument("--history", metavar="VAR", help="print one line per post of VAR (history mode)")
    p.add_argument("--src", default="", help="only posts from these sources (comma list, wildcards allowed)")
    p.add_argument("--show", default="source,time",
                   help="columns: any of source,time,community,aux (default source,time)")
    p.add_argument("--mode", choices=("paused", "events", "streaming"), default="events",
                   help="events: reprint when something changes; streaming: reprint every refresh; paused: once")
    p.add_argument("--once", "--one-shot", action="store_true",
                   help="print the current values once and exit (for scripts)")
    p.add_argument("--wait", type=float, default=DEFAULT_WAIT,
                   help="seconds to wait for the MOOSDB to connect and answer (default 2)")
    p.add_argument("--duration", type=float, default=0.0, help="exit after this many seconds (default: run until Ctrl-C)")
    p.add_argument("--refresh", type=float, default=1.0, help="seconds between table refreshes (default 1)")
    p.add_argument("--trunc", type=int, default=0, help="truncate values to N characters (default: no)")
    p.add_argument("-g", "--novirgins", action="store_true", help="hide variables never written")
    p.add_argument("-c", "--clean", action="store_true", help="ignore the var = lines of the uXMS block")
    add_db_arguments(p, "our time warp (default: mission or 1); (T)ime counts on the DB's clock whatever it is")
    p.add_argument("--alias", default="uXMS", help="MOOS name of this client (default uXMS)")
    p.add_argument("-e", "--example", action="store_true", help="print an example uXMS config block")
    p.add_argument("-i", "--interface", action="store_true", help="print subscriptions and publications")
    p.add_argument("--version", action="version", version=version_page("uXMS"), help="print the release")
    return p


EXAMPLE = """\
ProcessConfig = uXMS
{
  var     = NAV_X, NAV_Y    // variables to watch (repeatable, wildcards allowed; default none)
  source  = uSimMarine      // only posts from these sources (repeatable; default any)
  history_var = DEPLOY      // history mode on this variable (default none)
  display_source    = true  // (S)ource column (default true)
  display_time      = true  // (T)ime column (default true)
  display_community = false // (C)ommunity column (default false)
  display_aux_source = false // (A)ux Source column (default false)
}
"""
INTERFACE = """\
SUBSCRIPTIONS:
  every watched variable (wildcard patterns through wildcard registration), the history variable
PUBLICATIONS:
  none
"""


@dataclass
class Options:
    mission: Mission | None
    names: list[str]
    sources: list[str]
    show: set[str]
    history: str | None
    host: str
    port: int
    time_warp: float


def options_from(args: argparse.Namespace) -> Options:
    """Merge command line and the mission's uXMS block; ValueError/MissionFileError on bad input."""
    words = list(args.args)
    mission = read_mission(words.pop(0)) if words and words[0].endswith(".moos") else None
    names = list(words)
    sources = [s for s in args.src.split(",") if s]
    show = {s.strip() for s in args.show.split(",") if s.strip()}
    unknown = show - set(SHOW_FIELDS)
    if unknown:
        raise ValueError(f"--show: unknown column {', '.join(sorted(unknown))} (use {','.join(SHOW_FIELDS)})")
    history = args.history
    block = mission.process_config(args.alias) if mission is not None and not args.clean else None
    if block is not None:
        if not names:
            names = [v.strip() for line in block.get_all("var") for v in line.split(",") if v.strip()]
        sources = sources or [v.strip() for line in block.get_all("source") for v in line.split(",") if v.strip()]
        history = history or block.get("history_var")
        for key, column in (("display_source", "source"), ("display_time", "time"),
                            ("display_community", "community"), ("display_aux_source", "aux")):
            if block.get(key) is not None:
                (show.add if parse_bool(block.get(key)) else show.discard)(column)
    if args.all:
        names.append("*")
    if history and history not in names:
        names.append(history)
    if not names:
        raise ValueError("nothing to watch: name variables, use --all, or give var = lines in the uXMS block")
    host, port, warp = db_address(mission, args.host, args.port, args.time_warp)
    return Options(mission, names, sources, show, history, host, port, warp)


async def scope_main(args: argparse.Namespace, opts: Options, out=None) -> int:
    out = out or sys.stdout
    scope = Scope(opts.names, opts.sources)
    changed = asyncio.Event()
    answered = asyncio.Event()   # the DB answered our ALL request, so it has answered the registrations

    held: list[str] = []         # history lines that came before the header

    def show_history(line: str) -> None:
        print(line, file=out, flush=True)

    def on_mail(mail: list[MOOSMsg]) -> None:
        scope.note_db_start(mail)
        for msg in mail:
            if msg.id == SERVER_REQUEST_ID:
                if opts.history and not answered.is_set():
                    show_history(f"{'Time':<10} {'VarName':<20} {'Source':<15} VarValue")
                    for line in held:
                        show_history(line)
                answered.set()
                continue
            for seen in scope.take([msg]):
                if opts.history and seen.key == opts.history:
                    line = history_line(seen, scope.start, args.trunc)
                    show_history(line) if answered.is_set() else held.append(line)
                changed.set()

    def on_connect() -> None:
        if not scope.start:   # until DB_UPTIME says when the DB started: our start on the DB's clock
            scope.start = client.moos_time() + client.db_skew
        client.register("DB_UPTIME")
        for name in opts.names:
            if is_pattern(name):
                client.register_wildcard(name, "*")
            else:
                client.register(name)
        client.server_request("ALL")

    client = MOOSClient(args.alias, opts.host, opts.port, on_mail=on_mail, on_connect=on_connect,
                        time_warp=opts.time_warp)
    runner = asyncio.create_task(client.run())
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        try:
            await connect(client, runner, max(args.wait, 1.0))
        except ConnectionError as exc:
            print(f"uXMS: {exc}", file=sys.stderr)
            return 1
        if args.once or args.mode == "paused":
            try:
                await asyncio.wait_for(answered.wait(), args.wait)
            except (asyncio.TimeoutError, TimeoutError):
                pass
            print(format_table(scope, opts.show, args.trunc, args.novirgins), end="", file=out, flush=True)
            return 0
        await _refresh_loop(args, opts, scope, changed, stop, out)
        return 0
    finally:
        client.close()
        await asyncio.wait([runner], timeout=2.0)


async def _refresh_loop(args, opts: Options, scope: Scope, changed: asyncio.Event, stop: asyncio.Event, out) -> None:
    end = time.monotonic() + args.duration if args.duration > 0 else None
    clear = "\x1b[2J\x1b[H" if out.isatty() else ""
    first = True
    while not stop.is_set() and (end is None or time.monotonic() < end):
        if not opts.history and (first or args.mode == "streaming" or changed.is_set()):
            changed.clear()
            print(clear + format_table(scope, opts.show, args.trunc, args.novirgins), file=out, flush=True)
            first = False
        timeout = args.refresh if end is None else max(0.0, min(args.refresh, end - time.monotonic()))
        try:
            await asyncio.wait_for(stop.wait(), timeout)
        except (asyncio.TimeoutError, TimeoutError):
            pass


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_intermixed_args(argv)
    if args.example or args.interface:
        print_page(EXAMPLE if args.example else INTERFACE)
        return 0
    try:
        opts = options_from(args)
    except (ValueError, MissionFileError) as exc:
        print(f"uXMS: {exc}", file=sys.stderr)
        return 1
    return asyncio.run(scope_main(args, opts))


if __name__ == "__main__":
    sys.exit(main())
