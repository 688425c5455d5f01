"""moos-lint: check `.moos` and `.bhv` mission files before a mission misbehaves.

Each file is run through nsplug (with the `-D VAR=value` defines; unresolved macros stay as nsplug
leaves them) and parsed; every problem is printed as `file:line: message`. The exit status is 0
only when every file parses. What a .moos reader ignores (stray lines, a second block of one name)
goes to stderr as `file:line: warning: ...`: the mission runs, but likely not as meant.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from moosdb_py.mission import read_mission
from moosdb_py.nsplug import parse_defines, preprocess
from moosdb_py.source import MissionFileError

from .behavior import InfoBuffer
from .bhv_file import BehaviorSpec, parse_bhv
from .domain import IvPDomain, parse_domain_line
from .helm import BEHAVIOR_TYPES
from .helm_app import parameter_warnings

LINT_DOMAIN = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:10:101"),
                              parse_domain_line("depth:0:1000:1001:optional")])
GLOBALS = {"server_port": "ServerPort", "time_warp": "MOOSTimeWarp", "lat_origin": "LatOrigin",
           "long_origin": "LongOrigin"}


def _unresolved(text: str) -> bool:
    return "$(" in text or "%(" in text


def check_behavior_params(spec: BehaviorSpec) -> list[MissionFileError]:
    """Apply each line of a known behaviour type, collecting every rejected one."""
    cls = BEHAVIOR_TYPES.get(spec.type.lower())
    if cls is None:
        return []  # a type this helm does not implement: only its general syntax was checked
    bhv = cls(LINT_DOMAIN, InfoBuffer())
    problems = []
    for p in spec.params:
        if _unresolved(p.value):
            continue
        try:
            bhv.apply(p.key, p.value)
        except ValueError as exc:
            problems.append(p.error(f"{spec.type} '{spec.name}': {exc}"))
    return problems


def lint_bhv(path: Path, defines: dict) -> list[MissionFileError]:
    bhv = parse_bhv(preprocess(path, defines), path)
    return [e for spec in bhv.behaviors for e in check_behavior_params(spec)]


def lint_moos(path: Path, defines: dict, warnings: list[str] | None = None) -> list[MissionFileError]:
    mission = read_mission(path, defines)
    if warnings is not None:
        warnings += mission.warnings
    problems = []
    for attr, name in GLOBALS.items():
        try:
            getattr(mission, attr)
        except MissionFileError as exc:
            if not _unresolved(mission.get_global(name) or ""):
                problems.append(exc)
    helm = mission.process_config("pHelmIvP")
    if helm is not None:
        problems += parameter_warnings(helm)     # the helm would sit in MALCONFIG
    for value in helm.get_all("domain") if helm else []:
        if not _unresolved(value):
            try:
                parse_domain_line(value)
            except ValueError as exc:
                entry = next(e for e in helm.entries if e.key.lower() == "domain" and e.value == value)
                problems.append(entry.source.error(str(exc)))
    return problems


def lint(path: Path, defines: dict, warnings: list[str] | None = None) -> list[str]:
    """Problems of one file as `file:line: message` strings; a .moos file's warnings go to `warnings`."""
    try:
        if path.suffix.lower() == ".bhv":
            return [str(e) for e in lint_bhv(path, defines)]
        return [str(e) for e in lint_moos(path, defines, warnings)]
    except MissionFileError as exc:
        return [str(exc)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="moos-lint", description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+", type=Path, metavar="FILE", help=".moos or .bhv files")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="VAR=value",
                        help="an nsplug macro value (repeatable)")
    args = parser.parse_args(argv)
    try:
        defines = parse_defines(args.defines)
    except ValueError as exc:
        parser.error(str(exc))
    failed = False
    for path in args.files:
        warnings: list[str] = []
        problems = lint(path, defines, warnings)
        for line in problems:
            print(line)
        for warning in warnings:
            where, _, message = warning.partition(": ")
            print(f"{where}: warning: {message}", file=sys.stderr)
        failed = failed or bool(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
