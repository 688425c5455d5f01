"""moos-lint: check `.moos` and `.bhv` mission files before a mission misbehaves.

Each file is run through nsplug (with the `-D VAR=value` defines; unresolved macros stay as nsplug
leaves them) and read as the apps read it. Severity follows those apps: what they reject (pAntler
starts nothing, pHelmIvP sits in MALCONFIG, a behaviour refuses a parameter) is an error, printed as
`file:line: message`; what they only warn about (an app pAntler cannot launch, a parameter the helm
ignores, a line the mission reader skips) is a warning, printed to stderr as `file:line: warning:
message`. Every problem of a file is reported, not only the first. A last line on stderr counts the
files (`N files OK`); the exit status is 1 when any file has an error, else 0.
"""
from __future__ import annotations

import argparse
import difflib
import sys
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from moosdb_py.antler import APP_GROUP, DB_NAMES, plan
from moosdb_py.formats import print_page, version_page
from moosdb_py.mission import Mission, parse_mission
from moosdb_py.nsplug import parse_defines, preprocess
from moosdb_py.source import MissionFileError, SourceLine

from .behavior import InfoBuffer
from .bhv_file import BehaviorSpec, parse_bhv
from .domain import IvPDomain, parse_domain_line
from .helm_app import ignored_parameter_warnings, parameter_warnings
from .registry import PluginError, behavior_class

LINT_DOMAIN = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:10:101"),
                              parse_domain_line("depth:0:1000:1001:optional")])
GLOBALS = {"server_port": "ServerPort", "time_warp": "MOOSTimeWarp", "lat_origin": "LatOrigin",
           "long_origin": "LongOrigin"}

EXAMPLE = """\
$ cd missions/s1_alpha
$ moos-lint alpha.moos alpha.bhv
2 files OK
$ moos-lint broken.moos broken.bhv
broken.bhv:6: BHV_Waypoint 'waypt_survey': vertex 3 'oops' is not x,y
broken.bhv:9: BHV_Waypoint 'waypt_survey': speed must be a number >= 0, got 'fast'
broken.moos:21: warning: Run line has no '@': pAntler takes all of 'pHelmIvPNewConsole=false' as the program name (write Run = <app> @ NewConsole = false)
broken.moos:40: warning: pHelmIvP ignores 'term_report_interval' (the C++ helm only warns about it)
2 files: 2 errors, 2 warnings
$ moos-lint -D VNAME=abe -D START_POS=0,0 meta_vehicle.moos meta_vehicle.bhv   # templates, with nsplug values
"""
INTERFACE = """\
moos-lint is not a MOOS app: it connects to no MOOSDB, subscribes to nothing and publishes nothing.

Reads:   the .moos and .bhv files named (and their #include files), nsplug'd with the -D values
Writes:  stdout  file:line: message            (an error: the app reading the line rejects it)
         stderr  file:line: warning: message   (the app only warns; the mission runs)
                 N files OK[, W warnings]      (last; or N files: E errors, W warnings)
Exit:    0 no errors, 1 errors, 2 bad command line
"""


@dataclass
class Findings:
    """The errors and warnings of one file, one message per line of the file (the first found)."""

    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    seen: set[str] = field(default_factory=set)

    def _add(self, to: list[str], problem: MissionFileError | str) -> None:
        text = str(problem)
        where = text.split(": ", 1)[0]
        if where not in self.seen:
            self.seen.add(where)
            to.append(text)

    def error(self, problem: MissionFileError | str) -> None:
        self._add(self.errors, problem)

    def warning(self, problem: MissionFileError | str) -> None:
        self._add(self.warnings, problem)


def _unresolved(text: str) -> bool:
    return "$(" in text or "%(" in text


def check_behavior_params(spec: BehaviorSpec, found: Findings) -> None:
    """Apply each line of a behaviour as the helm would, collecting every rejected one."""
    try:
        cls = behavior_class(spec.type)      # built-in or a plug-in's (the behaviors.bhv entry points)
    except PluginError as exc:
        found.error(MissionFileError(spec.file, spec.line, str(exc)))
        return
    if cls is None:
        found.warning(MissionFileError(spec.file, spec.line, f"{spec.type} '{spec.name}': a behaviour type this "
                                       "helm does not implement (its pHelmIvP refuses the file); general "
                                       "syntax checked only"))
        return
    bhv = cls(LINT_DOMAIN, InfoBuffer())
    for p in spec.params:
        if _unresolved(p.value):
            continue
        try:
            bhv.apply(p.key, p.value)
        except ValueError as exc:
            found.error(p.error(f"{spec.type} '{spec.name}': {exc}"))


def as_the_helm_reads(lines: list[SourceLine], path: Path) -> list[SourceLine]:
    """nsplug's output ends with one empty line more than the file has; the helm reads no such line,
    so without it an unclosed block is reported at the helm's line."""
    if lines and lines[-1].file == path and lines[-1].text == "":
        return lines[:-1]
    return lines


def lint_bhv(path: Path, defines: dict, found: Findings) -> None:
    errors: list[MissionFileError] = []
    bhv = parse_bhv(as_the_helm_reads(preprocess(path, defines), path), path, errors=errors)
    for problem in errors:
        found.error(problem)
    for spec in bhv.behaviors:
        check_behavior_params(spec, found)


def check_antler(mission: Mission, found: Findings) -> None:
    """Run lines pAntler could not launch, as pAntler warns about them (it launches the rest)."""
    block = mission.process_config("ANTLER")
    for entry in block.entries if block is not None else []:
        value = entry.moos_value
        if entry.key.lower() == "run" and "@" not in value and ("~" in value or "=" in value):
            found.warning(entry.source.error(f"Run line has no '@': pAntler takes all of '{value}' as the program "
                                             "name (write Run = <app> @ NewConsole = false [~ MOOSName])"))
    _, problems = plan(mission, mission.path)
    ours = [*DB_NAMES, *(e.name for e in metadata.entry_points(group=APP_GROUP))]
    for problem in problems:
        run = next(r for r in mission.antler.runs if problem.startswith(f"{r.source}: "))
        close = difflib.get_close_matches(run.exe, ours, n=1, cutoff=0.8)
        found.warning(problem + (f" (did you mean {close[0]}?)" if close else ""))


def read_past_bad_entries(path: Path, defines: dict, found: Findings) -> Mission:
    """The mission as MOOS reads it; a rejected `key = value` line (a bad Run line, ...) is reported
    and read again without it, so the lines after it are checked too. A structural error (a block
    never closed, a header without `{`) ends the file: what follows is in no known block."""
    lines = preprocess(path, defines)
    while True:
        try:
            return parse_mission(path, lines)
        except MissionFileError as exc:
            found.error(exc)
            at = next((i for i, s in enumerate(lines) if (s.file, s.line) == (exc.file, exc.line)), None)
            text = lines[at].text.strip() if at is not None else ""
            if at is None or "=" not in text or text.replace(" ", "").lower().startswith("processconfig="):
                raise
            lines = [*lines[:at], SourceLine("", exc.file, exc.line), *lines[at + 1:]]


def lint_moos(path: Path, defines: dict, found: Findings) -> None:
    mission = read_past_bad_entries(path, defines, found)
    for warning in mission.warnings:
        found.warning(warning)
    for attr, name in GLOBALS.items():
        try:
            getattr(mission, attr)
        except MissionFileError as exc:
            if not _unresolved(mission.get_global(name) or ""):
                found.error(exc)
    if mission.antler is not None:
        check_antler(mission, found)
    helm = mission.process_config("pHelmIvP")
    if helm is None:
        return
    for problem in parameter_warnings(helm):     # the helm would sit in MALCONFIG
        found.error(problem)
    for ignored in ignored_parameter_warnings(helm):
        found.warning(ignored)
    for entry in (e for e in helm.entries if e.key.lower() == "domain" and not _unresolved(e.value)):
        try:
            parse_domain_line(entry.value)
        except ValueError as exc:
            found.error(entry.source.error(str(exc)))


def lint(path: Path, defines: dict) -> Findings:
    """Every problem of one file, as `file:line: message` strings sorted into errors and warnings."""
    found = Findings()
    try:
        if path.suffix.lower() == ".bhv":
            lint_bhv(path, defines, found)
        else:
            lint_moos(path, defines, found)
    except MissionFileError as exc:
        found.error(exc)          # already there when read_past_bad_entries gave up on it
    found.errors.sort(key=_line_order)
    found.warnings.sort(key=_line_order)
    return found


def _line_order(text: str) -> tuple[str, int]:
    file, _, rest = text.partition(":")
    line = rest.partition(":")[0]
    return file, int(line) if line.isdigit() else 0


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="moos-lint", description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", type=Path, metavar="FILE", help=".moos or .bhv files")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="VAR=value",
                        help="an nsplug macro value (repeatable)")
    parser.add_argument("-e", "--example", action="store_true", help="print an example session")
    parser.add_argument("-i", "--interface", action="store_true", help="print what it reads and writes")
    parser.add_argument("-v", "--version", action="store_true", help="print the version")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.example or args.interface or args.version:
        print_page(EXAMPLE if args.example else INTERFACE if args.interface else version_page("moos-lint"))
        return 0
    if not args.files:
        parser.error("at least one FILE is required")
    try:
        defines = parse_defines(args.defines)
    except ValueError as exc:
        parser.error(str(exc))
    errors = warnings = 0
    for path in args.files:
        found = lint(path, defines)
        for line in found.errors:
            print(line)
        for warning in found.warnings:
            where, _, message = warning.partition(": ")
            print(f"{where}: warning: {message}", file=sys.stderr)
        errors += len(found.errors)
        warnings += len(found.warnings)
    files = _count(len(args.files), "file")
    if errors:
        print(f"{files}: {_count(errors, 'error')}, {_count(warnings, 'warning')}", file=sys.stderr)
        return 1
    print(f"{files} OK" + (f", {_count(warnings, 'warning')}" if warnings else ""), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
