"""pAntler: launch a mission's MOOSDB and apps from its ANTLER block, and stop them all together.

Python and C++ apps mix: a name an installed package declares (the `moosdb_py.apps` entry points for
MOOSApp classes, `moosdb_py.programs` for other MOOS programs such as uXMS) runs the Python app with
this interpreter, any other name is looked up in
ExecutablePath / on PATH. Every child gets its own session, so a terminal Ctrl-C reaches only
pAntler, which then stops each child's whole process group (SIGTERM, then SIGKILL); on Linux the
children also get SIGTERM if pAntler itself is killed. Nothing starts when the mission cannot be
read.
"""
from __future__ import annotations

import argparse
import asyncio
import ctypes
import importlib
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from .formats import print_page, version_page
from .mission import AntlerRun, Mission, parse_mission
from .nsplug import parse_defines, preprocess
from .source import MissionFileError, SourceLine

APP_GROUP = "moosdb_py.apps"
PROGRAM_GROUP = "moosdb_py.programs"
DB_NAMES = ("MOOSDB", "moosdb")
DB_TARGET = "moosdb_py.moosdb:main"
DB_CONSOLE_SCRIPT = "moosdb"
STOP_GRACE = 3.0          # seconds a child gets between SIGTERM and SIGKILL
DB_READY_TIMEOUT = 10.0
LAST_LINES = 8
OUTPUT_CHUNK = 65536
# Runs `module:attr` with argv = [name, args...]; a class target is a MOOSApp, whose `main` is the entry.
_BOOT = ("import importlib, sys\n"
         "mod, _, attr = sys.argv[1].partition(':')\n"
         "obj = importlib.import_module(mod)\n"
         "for part in attr.split('.'): obj = getattr(obj, part)\n"
         "sys.argv = sys.argv[2:]\n"
         "sys.exit((obj.main if isinstance(obj, type) else obj)())\n")

EXAMPLE = """\
ProcessConfig = ANTLER
{
  MSBetweenLaunches = 1000        // ms to wait after each launch (default 1000)
  ExecutablePath    = SYSTEMPATH  // or a folder searched before PATH (default SYSTEMPATH)

  // Run = <exe> [@ NewConsole=false, InhibitMOOSParams=false, Path=<dir>, ExtraProcessParams=<Key>] [~ <MOOSName>]
  Run = MOOSDB        @ NewConsole = false
  Run = pLogger       @ NewConsole = false
  Run = uXMS          @ NewConsole = false, ExtraProcessParams = XmsArgs ~ uXMS_NAV
  XmsArgs = NAV_X,NAV_Y
}
"""
INTERFACE = """\
pAntler is a launcher, not a MOOS client: it subscribes to nothing and publishes nothing.
Each child is started as `<exe> <mission.moos> <MOOSName> [extra params]` (MOOSDB: `<mission.moos>`).
"""


@dataclass
class LaunchSpec:
    """How one `Run =` line is started: a Python target (`module:attr`) or an executable."""

    run: AntlerRun
    args: list[str]                        # after the program: mission, MOOS name, extra params
    target: str | None = None              # Python `module:attr`
    executable: str | None = None          # external program
    is_db: bool = False

    @property
    def name(self) -> str:
        return self.run.moos_name

    @property
    def hostable(self) -> bool:
        """A MOOSApp class that --one-process can run inside pAntler's own interpreter."""
        return self.target is not None and not self.is_db and _load(self.target, check_class=True) is not None

    def argv(self) -> list[str]:
        """The app's console script next to this interpreter (so `ps` shows its name), else a boot line."""
        if self.target is None:
            return [self.executable, *self.args]
        script = _console_script(DB_CONSOLE_SCRIPT if self.is_db else Path(self.run.exe).name)
        if script is not None:
            return [sys.executable, script, *self.args]
        return [sys.executable, "-c", _BOOT, self.target, self.name, *self.args]


def _console_script(name: str) -> str | None:
    if not metadata.entry_points(group="console_scripts", name=name):
        return None
    script = Path(sys.executable).parent / name
    return str(script) if script.is_file() else None


def _load(target: str, check_class: bool = False):
    module, _, attr = target.partition(":")
    try:
        obj = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError):
        return None
    return obj if not check_class or isinstance(obj, type) else None


def python_target(name: str) -> str | None:
    """`module:attr` of the app or program an entry point names `name` (MOOSApp classes first)."""
    for group in (APP_GROUP, PROGRAM_GROUP):
        found = list(metadata.entry_points(group=group, name=name))
        if found:
            return found[0].value
    return None


def plan(mission: Mission, mission_file: Path, only: list[str] | None = None) -> tuple[list[LaunchSpec], list[str]]:
    """The launch list in Run order (filtered by MOOS name), and a problem line for each run that cannot start."""
    if mission.antler is None:
        raise MissionFileError(mission.path, 0, "no ProcessConfig = ANTLER block")
    specs, problems = [], []
    for run in mission.antler.runs:
        if only and run.moos_name not in only:
            continue
        spec = _resolve(run, mission.antler.executable_path, str(mission_file))
        if spec is None:
            problems.append(f"{run.source}: cannot launch {run.exe}: not a project app and not found on PATH")
        else:
            specs.append(spec)
    return specs, problems


def _resolve(run: AntlerRun, executable_path: str | None, mission_file: str) -> LaunchSpec | None:
    base = Path(run.exe).name
    is_db = base in DB_NAMES
    if is_db:
        args = [] if run.inhibit_moos_params else [mission_file]
    else:
        args = [] if run.inhibit_moos_params else [mission_file, run.moos_name]
    args += run.extra_params
    folder = run.path if run.path and run.path.upper() not in ("SYSTEM", "SYSTEMPATH") else executable_path
    if folder and (Path(folder) / run.exe).is_file() and os.access(Path(folder) / run.exe, os.X_OK):
        return LaunchSpec(run, args, executable=str(Path(folder) / run.exe), is_db=is_db)
    if "/" not in run.exe:
        target = DB_TARGET if is_db else python_target(run.exe)
        if target is not None:
            return LaunchSpec(run, args, target=target, is_db=is_db)
    found = shutil.which(run.exe)
    return None if found is None else LaunchSpec(run, args, executable=found, is_db=is_db)


def expanded_mission(path: Path, defines: dict, overrides: dict[str, str], folder: Path) -> tuple[Mission, Path]:
    """Read the mission; when nsplug or overrides changed its text, write the expansion for the children.

    The children read a plain file, as after MOOS-IvP's `nsplug meta.moos targ.moos`; overrides
    (`--MOOSTimeWarp=10`) go first because the first global line wins. The returned Mission keeps
    the original file:line of every entry, for messages.
    """
    lines = preprocess(path, defines)
    original = path.read_text(encoding="latin-1") + "\n"
    command_line = [SourceLine(f"{k} = {v}", Path("<command line>"), n) for n, (k, v) in enumerate(overrides.items(), 1)]
    lines = command_line + lines
    mission = parse_mission(path, lines)
    mission.check()
    text = "".join(line.text + "\n" for line in lines)
    if text == original:
        return mission, path.resolve()
    target = folder / path.name
    target.write_text(text, encoding="latin-1")
    return mission, target


def _die_with_parent() -> None:
    """In the child before exec: new session, and SIGTERM when pAntler dies (Linux prctl)."""
    os.setsid()
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


@dataclass
class Child:
    spec: LaunchSpec
    process: asyncio.subprocess.Process
    last: deque = field(default_factory=lambda: deque(maxlen=LAST_LINES))


class Antler:
    """Starts the plan in order, echoes children's output, reports deaths, stops everything on request."""

    def __init__(self, mission: Mission, specs: list[LaunchSpec], *, quiet: bool = False, one_process: bool = False,
                 host_db: bool = False, out=None, stopping: asyncio.Event | None = None):
        self.mission = mission
        self.specs = specs
        self.quiet = quiet
        self.one_process = one_process
        self.host_db = host_db
        self.db = None                                 # --host-db: the MOOSDB serving in this process
        self._db_task: asyncio.Task | None = None
        self.out = out or sys.stdout
        self.children: list[Child] = []
        self.hosted: list = []
        self.stopping = stopping or asyncio.Event()   # shared by missions hosted together (--with): they stop together
        self.failures: list[str] = []   # MOOS names that could not start or died on their own
        self._tasks: list[asyncio.Task] = []          # output watchers
        self._hosted_tasks: list[asyncio.Task] = []   # --one-process apps

    def say(self, text: str) -> None:
        self._print(f"pAntler: {text}")

    def _print(self, text: str) -> None:
        try:
            print(text, file=self.out, flush=True)
        except OSError:        # our own output is gone (a closed pipe): keep running and draining the children
            self.quiet = True

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self.stopping.set)
        try:
            pause = self.mission.antler.ms_between_launches / 1000.0
            for spec in self.specs:
                if self.stopping.is_set():
                    break
                if not await self._launch(spec):
                    self.failures.append(spec.name)
                if spec.is_db:
                    await self._wait_for_db()
                await self._pause(pause)
            await self._supervise()
        finally:
            await self.stop()
        return 1 if self.failures else 0

    async def _pause(self, seconds: float) -> None:
        try:
            await asyncio.wait_for(self.stopping.wait(), seconds)
        except asyncio.TimeoutError:
            pass

    async def _launch(self, spec: LaunchSpec) -> bool:
        if self.host_db and spec.is_db and spec.target is not None:
            return self._host_db(spec)
        if self.one_process and spec.hostable:
            return self._host(spec)
        try:
            process = await asyncio.create_subprocess_exec(
                *spec.argv(), stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT, preexec_fn=_die_with_parent,
                env={**os.environ, "PYTHONUNBUFFERED": "1"})
        except OSError as exc:
            self.say(f"{spec.run.source}: cannot start {spec.run.exe}: {exc.strerror}")
            return False
        child = Child(spec, process)
        self.children.append(child)
        self._tasks.append(asyncio.create_task(self._watch(child)))
        self.say(f"launched {spec.name} (pid {process.pid})")
        return True

    def _host_db(self, spec: LaunchSpec) -> bool:
        """--host-db: the MOOSDB serves TCP from this event loop, and the hosted apps reach it without a socket."""
        from .moosdb import db_from_args
        try:
            self.db = db_from_args([str(a) for a in spec.args])
        except (SystemExit, ValueError, MissionFileError, OSError) as exc:
            self.say(f"{spec.name}: cannot start: {exc}")
            return False
        self._db_task = asyncio.create_task(self.db.run())
        self._db_task.add_done_callback(lambda t, name=spec.name: self._hosted_done(name, t))
        self.say(f"hosting {spec.name} in-process on port {self.db.port}")
        return True

    def _host(self, spec: LaunchSpec) -> bool:
        """--one-process: the MOOSApp runs in this interpreter, still its own client with its own tick."""
        app_class = _load(spec.target, check_class=True)
        try:
            app = app_class(str(spec.args[0]) if spec.args else None, spec.name)
        except (ValueError, MissionFileError, OSError) as exc:
            self.say(f"{spec.name}: cannot start: {exc}")
            return False
        if self.db is not None and app.client.port == self.db.port and app.client.host in ("127.0.0.1", "localhost"):
            app.client.local_db = self.db
        self.hosted.append(app)
        task = asyncio.create_task(app.run_async())
        task.add_done_callback(lambda t, name=spec.name: self._hosted_done(name, t))
        self._hosted_tasks.append(task)
        self.say(f"hosting {spec.name} in-process")
        return True

    def _hosted_done(self, name: str, task: asyncio.Task) -> None:
        if task.cancelled() or self.stopping.is_set():
            return
        if task.exception() is not None or task is self._db_task:
            self.failures.append(name)
            self.say(f"{name} (in-process) failed: {task.exception() or 'stopped'}")

    def _echo(self, child: Child, line: bytes) -> None:
        text = line.decode("utf-8", errors="replace").rstrip("\r")
        child.last.append(text)
        if not self.quiet:
            self._print(f"[{child.spec.name}] {text}")

    async def _watch(self, child: Child) -> None:
        """Echo the child's output by lines; chunked reads, so even a huge line never stalls the pipe."""
        pending = b""
        while chunk := await child.process.stdout.read(OUTPUT_CHUNK):
            *lines, pending = (pending + chunk).split(b"\n")
            if len(pending) >= OUTPUT_CHUNK:
                lines, pending = [*lines, pending], b""
            for line in lines:
                self._echo(child, line)
        if pending:
            self._echo(child, pending)
        code = await child.process.wait()
        if not self.stopping.is_set():
            if code != 0:
                self.failures.append(child.spec.name)
            tail = "".join(f"\n    {t}" for t in child.last) or " (no output)"
            self.say(f"{child.spec.name} (pid {child.process.pid}) exited with code {code}; last output:{tail}")

    async def _wait_for_db(self) -> None:
        host, port = self.mission.server_host, self.mission.server_port
        deadline = time.monotonic() + DB_READY_TIMEOUT
        while time.monotonic() < deadline and not self.stopping.is_set():
            try:
                socket.create_connection((host, port), timeout=0.2).close()
                return
            except OSError:
                await asyncio.sleep(0.05)
        self.say(f"MOOSDB not accepting on {host}:{port} after {DB_READY_TIMEOUT:g} s; launching the rest anyway")

    async def _supervise(self) -> None:
        """Until a stop request, or until no child is left and nothing is hosted; woken by those events
        rather than polling (a wake-up costs a loaded machine ~0.1 ms of CPU)."""
        stop = asyncio.create_task(self.stopping.wait())
        try:
            while not self.stopping.is_set():
                exits = [asyncio.ensure_future(c.process.wait()) for c in self.children if c.process.returncode is None]
                hosted = [t for t in (*self._hosted_tasks, self._db_task) if t is not None and not t.done()]
                if not exits and not hosted:
                    self.say("every process has exited")
                    return
                await asyncio.wait([stop, *exits, *hosted], return_when=asyncio.FIRST_COMPLETED)
                for waiting in exits:
                    waiting.cancel()
        finally:
            stop.cancel()

    async def stop(self) -> None:
        """Apps first (hosted and child processes), the MOOSDB last, so the apps' final posts still land."""
        self.stopping.set()
        for app in reversed(self.hosted):
            app.stop()
        await self._terminate([c for c in reversed(self.children) if not c.spec.is_db])
        if self._hosted_tasks:
            await asyncio.wait(self._hosted_tasks, timeout=STOP_GRACE)
        await self._terminate([c for c in self.children if c.spec.is_db])
        if self._db_task is not None:
            self._db_task.cancel()
            await asyncio.wait([self._db_task], timeout=STOP_GRACE)
        for child in self.children:   # grandchildren left in a group whose leader already exited
            _signal_group(child.process.pid, signal.SIGKILL)
        if self._tasks:
            await asyncio.wait(self._tasks, timeout=STOP_GRACE)
        for task in self._tasks:
            task.cancel()

    async def _terminate(self, children: list[Child]) -> None:
        live = [c for c in children if c.process.returncode is None]
        for child in live:
            _signal_group(child.process.pid, signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE
        for child in live:
            try:
                await asyncio.wait_for(child.process.wait(), max(0.05, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                self.say(f"{child.spec.name} ignored SIGTERM; killing it")
                _signal_group(child.process.pid, signal.SIGKILL)
                await child.process.wait()


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pAntler", description=__doc__.split("\n\n")[0],
        epilog="Any other --Name=value option overrides that global of the mission (e.g. --MOOSTimeWarp=10).")
    p.add_argument("mission", nargs="?", help="mission file (.moos, or an nsplug template with --nsplug)")
    p.add_argument("only", nargs="*", help="launch only these MOOS names (the ~ alias if given)")
    p.add_argument("--nsplug", "-D", action="append", default=[], metavar="VAR=value",
                   help="nsplug macro for a templated mission (repeatable; a bare VAR defines it empty)")
    p.add_argument("--one-process", action="store_true",
                   help="run the community's Python apps inside this process, each its own MOOS client and tick")
    p.add_argument("--host-db", action="store_true",
                   help="with --one-process: the MOOSDB too, and the hosted apps reach it in-process (no loopback sockets)")
    p.add_argument("--with", dest="also", action="append", default=[], metavar="MISSION",
                   help="another mission (another vessel's community) hosted in this process too, its apps waking "
                        "with this one's (implies --host-db; repeatable; the same macros, overrides and MOOS names "
                        "apply; the missions share the working folder, so their pLogger File names must differ)")
    p.add_argument("--quiet", "--terse", action="store_true", help="do not echo the children's output")
    p.add_argument("--example", action="store_true", help="print an example ANTLER block")
    p.add_argument("--interface", action="store_true", help="print what pAntler subscribes to and publishes")
    p.add_argument("--version", action="version", version=version_page("pAntler"), help="print the release")
    return p


def split_overrides(argv: list[str]) -> tuple[list[str], dict[str, str]]:
    """MOOS's `--Name=value` global overrides, apart from pAntler's own options (anywhere on the line)."""
    own = {"nsplug", "one-process", "host-db", "with", "quiet", "terse", "example", "interface", "help", "version"}
    rest, overrides = [], {}
    for arg in argv:
        match = re.fullmatch(r"--([\w-]+)=(.*)", arg)
        if match is not None and match.group(1) not in own:
            overrides[match.group(1)] = match.group(2)
        else:
            rest.append(arg)
    return rest, overrides


def main(argv: list[str] | None = None) -> int:
    rest, overrides = split_overrides(sys.argv[1:] if argv is None else list(argv))
    args = _parser().parse_intermixed_args(rest)
    if args.example or args.interface:
        print_page(EXAMPLE if args.example else INTERFACE)
        return 0
    if not args.mission:
        _parser().error("a mission file is required")
    host_db = args.host_db or bool(args.also)
    with tempfile.TemporaryDirectory(prefix="pAntler_") as folder:
        plans = []
        for index, path in enumerate([args.mission, *args.also]):
            try:
                (Path(folder) / str(index)).mkdir()
                mission, child_file = expanded_mission(Path(path), parse_defines(args.nsplug), overrides,
                                                       Path(folder) / str(index))
                specs, problems = plan(mission, child_file, args.only)
            except (MissionFileError, ValueError) as exc:
                print(f"pAntler: {exc}; nothing started", file=sys.stderr)
                return 1
            for problem in [*mission.warnings, *problems]:
                print(f"pAntler: {problem}", file=sys.stderr)
            if not specs:
                print(f"pAntler: {path}: nothing to launch", file=sys.stderr)
                return 1
            plans.append((mission, specs))
        return asyncio.run(run_together(plans, quiet=args.quiet, one_process=args.one_process or host_db,
                                        host_db=host_db))


async def run_together(plans: list[tuple[Mission, list[LaunchSpec]]], **options) -> int:
    """Each mission's plan run by its own Antler in this event loop (so its hosted apps share one AppTicker
    and wake together); a stop request, or one mission ending, stops them all."""
    stopping = asyncio.Event()
    codes = await asyncio.gather(*(Antler(m, specs, stopping=stopping, **options).run() for m, specs in plans))
    return max(codes)


if __name__ == "__main__":
    sys.exit(main())
