"""CPU a vehicle community costs per simulated second, and the largest fleet that keeps its AppTicks.

    python benchmarks/vehicle_bench.py [--fleets 1,10,30] [--warp 10] [--warps 10,20] [--window 10] [--one] [--per-process K]
    python benchmarks/vehicle_bench.py --oilspill 8 --warps 30,40 [--demo-ticks] [--per-process K]   # the demo's vessels and shoreside

Each vessel is a copy of missions/s1_alpha (MOOSDB, pLogger, uSimMarineV22, pMarinePIDV22,
pHelmIvP, pNodeReporter) with its own port and community, run by `pAntler --one-process
--host-db` (one process per vessel, apps and DB talking in-process; `--sockets`: the MOOSDB as
pAntler's child and the apps on loopback TCP) and deployed at once. Over a window of wall time while the
vessels drive their survey, it sums the CPU seconds (utime + stime from /proc, so a loaded
machine does not inflate the figure) of every pAntler and its children, divided by the
simulated seconds (window x warp) and by the vessel count. An app fell behind when its
`<NAME>_STATUS` shows it missed more than 2% of the AppTicks due in the window (MOOSApp counts in
`TicksMissed` the AppTick periods that passed with no iteration). `--one` measures one vessel at warp 10 only (the quick before/after).
`--per-process K` hosts K vessels in each pAntler (`pAntler --with`), whose apps then share wake-ups.
"""
from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import re
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

from moosdb_py.app import fell_behind, status_ticks
from moosdb_py.client import MOOSClient
from moosdb_py.ports import free_port   # never the same port twice: vessels are prepared before their DBs bind

MISSION = Path(__file__).resolve().parents[1] / "missions" / "s1_alpha"
BIN = Path(sys.executable).parent
TICKS = os.sysconf("SC_CLK_TCK")
SETTLE = 3.0          # wall seconds after deploying before the window opens


def prepare(folder: Path, index: int, port: int, warp: float) -> Path:
    """A copy of s1_alpha in its own folder, with its own ServerPort, Community, MOOSTimeWarp and log name."""
    folder.mkdir()
    for path in MISSION.iterdir():
        if path.suffix in (".moos", ".bhv"):
            shutil.copy(path, folder / path.name)
    target = folder / "alpha.moos"
    text = target.read_text()
    for name, value in (("ServerPort", port), ("MOOSTimeWarp", warp), ("Community", f"alpha{index}"),
                        ("File", f"LOG_ALPHA{index}")):   # pLogger's: vessels hosted together share a folder
        text, count = re.subn(rf"(?m)^\s*{name}\s*=.*$", f"{name} = {value}", text)
        assert count == 1, f"{target}: expected one {name} line"
    target.write_text(text)
    return target


def tree_cpu(root: int) -> float:
    """CPU seconds (user + system) of `root` and every live descendant."""
    children: dict[int, list[int]] = {}
    stats: dict[int, float] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(entry))
        stats[int(entry)] = (int(fields[11]) + int(fields[12])) / TICKS
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        total += stats.get(pid, 0.0)
        todo.extend(children.get(pid, []))
    return total


def tick_counts(watchers: list[MOOSClient], names: list[str] | None = None) -> dict[str, tuple[int, int]]:
    """The latest (Iterations, TicksMissed) per app of every community (`<community>/<APP>`; communities
    named alpha0, alpha1, ... unless `names` says)."""
    latest: dict[str, tuple[int, int]] = {}
    for index, watcher in enumerate(watchers):
        community = names[index] if names else f"alpha{index}"
        for msg in watcher.fetch():
            ticks = status_ticks(msg.string or "")
            if ticks and msg.community in ("", community):    # not another community's, shared by pShare
                latest[f"{community}/{msg.key[:-len('_STATUS')]}"] = ticks[1:]
    return latest


def behind(before: dict[str, tuple[int, int]], after: dict[str, tuple[int, int]]) -> list[str]:
    """Apps that missed more than BEHIND_SHARE of the AppTicks due between two statuses, and first the share
    of all the apps' AppTicks missed (how far a loaded run is from keeping up, when many apps fell behind)."""
    late = [f"{app} ({missed} of {due})" for app, missed, due in fell_behind(before, after)]
    if late:
        missed = sum(m - before.get(app, (0, 0))[1] for app, (_, m) in after.items())
        due = missed + sum(i - before.get(app, (0, 0))[0] for app, (i, _) in after.items())
        late.insert(0, f"{100 * missed / max(due, 1):.1f} % of all AppTicks missed")
    return late


async def run_fleet(vessels: int, warp: float, window: float, modes: tuple[str, ...],
                    per_process: int = 1) -> tuple[float, list[str]]:
    """(CPU ms per vessel per simulated second, apps that fell behind their AppTick); `per_process` vessels
    in each pAntler (the first's mission, `--with` the others')."""
    with tempfile.TemporaryDirectory(prefix="vehicle_bench_") as tmp:
        antlers, watchers, tasks = [], [], []
        try:
            group: list[Path] = []
            for index in range(vessels):
                port = free_port()
                group.append(prepare(Path(tmp) / f"v{index}", index, port, warp))
                if len(group) == per_process or index == vessels - 1:
                    others = [arg for mission in group[1:] for arg in ("--with", str(mission))]
                    antlers.append(await asyncio.create_subprocess_exec(
                        str(BIN / "pAntler"), group[0].name, *others, *modes, "--quiet", cwd=group[0].parent,
                        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
                        start_new_session=True))
                    group = []
                watcher = MOOSClient("uBenchWatch", port=port, time_warp=warp)
                watcher.register_wildcard("*_STATUS")
                watcher.register("IVPHELM_STATE", 0.5 * warp)   # that the helm is up, not its every iteration
                watchers.append(watcher)
                tasks.append(asyncio.create_task(watcher.run()))
            deadline = time.monotonic() + 60 + 5 * vessels
            for watcher in watchers:
                assert await watcher.wait_connected(max(1.0, deadline - time.monotonic())), "no MOOSDB came up"
            while not all(any(m.key == "IVPHELM_STATE" for m in w.inbox) for w in watchers):
                assert time.monotonic() < deadline, "a helm did not come up"
                await asyncio.sleep(0.1)
            for watcher in watchers:
                watcher.notify("MOOS_MANUAL_OVERRIDE", "false")
                watcher.notify("DEPLOY", "true")
            await asyncio.sleep(SETTLE)
            before = tick_counts(watchers)
            cpu0, t0 = sum(tree_cpu(a.pid) for a in antlers), time.monotonic()
            await asyncio.sleep(window)
            cpu1, t1 = sum(tree_cpu(a.pid) for a in antlers), time.monotonic()
            await asyncio.sleep(2.5)      # one more status from every app
            late = behind(before, tick_counts(watchers))
            return 1000 * (cpu1 - cpu0) / ((t1 - t0) * warp) / vessels, late
        finally:
            for watcher in watchers:
                watcher.close()
            for antler in antlers:
                with contextlib.suppress(ProcessLookupError):
                    antler.send_signal(signal.SIGINT)
            for antler in antlers:
                try:
                    await asyncio.wait_for(antler.wait(), 15)
                except TimeoutError:
                    os.killpg(antler.pid, signal.SIGKILL)
                    await antler.wait()
            if tasks:
                await asyncio.wait(tasks, timeout=5)


async def run_oilspill(vessels: int, warp: float, window: float, extra: dict[str, str],
                       per_process: int = 1) -> tuple[float, float, list[str]]:
    """(CPU ms per oil-spill vessel, CPU ms of the shoreside) per simulated second, and the apps that fell
    behind their AppTick: missions/oilspill's communities (oilspill_mission.OilspillMission, each pAntler
    --one-process --host-db, `per_process` vessels to a pAntler), deployed."""
    from oilspill_moos.oilspill_mission import Observer, OilspillMission, wait_for

    with tempfile.TemporaryDirectory(prefix="vehicle_bench_oilspill_") as tmp:
        mission = OilspillMission(Path(tmp), vehicles=vessels, warp=warp, extra=extra, vessels_per_process=per_process)
        with mission:
            observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
            task = asyncio.create_task(observer.client.run())
            watchers = [MOOSClient("uBenchWatch", port=c.moos_port, time_warp=warp) for c in mission.communities]
            for watcher in watchers:
                watcher.register_wildcard("*_STATUS")
            tasks = [task, *(asyncio.create_task(w.run()) for w in watchers)]
            try:
                timeout = 60 + 5 * vessels
                assert await observer.client.wait_connected(timeout), "the shoreside MOOSDB did not come up"
                await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout,
                               "every vessel's NODE_REPORT", mission)
                await observer.deploy(mission.fleet, timeout, mission)
                await asyncio.sleep(SETTLE)
                names = [c.name for c in mission.communities]
                before = tick_counts(watchers, names)
                pids = {group[0].process.pid: group[0].name == "shoreside" for group in mission.processes()}
                cpu0, t0 = {p: tree_cpu(p) for p in pids}, time.monotonic()
                await asyncio.sleep(window)
                cpu1, t1 = {p: tree_cpu(p) for p in pids}, time.monotonic()
                await asyncio.sleep(2.5)      # one more status from every app
                late = behind(before, tick_counts(watchers, names))
            finally:
                observer.client.close()
                for watcher in watchers:
                    watcher.close()
                await asyncio.wait(tasks, timeout=5)
    simulated = (t1 - t0) * warp
    fleet = sum(cpu1[p] - cpu0[p] for p, shore in pids.items() if not shore)   # each process once
    shore = sum(cpu1[p] - cpu0[p] for p, shore in pids.items() if shore)
    return 1000 * fleet / simulated / vessels, 1000 * shore / simulated, late


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", default="1,10,30", help="vessel counts to measure at --warp")
    parser.add_argument("--warp", type=float, default=10.0, help="warp at which --fleets are measured (default 10)")
    parser.add_argument("--warps", default="10,20", help="warps at which to find the largest fleet that keeps up")
    parser.add_argument("--window", type=float, default=10.0, help="wall seconds measured")
    parser.add_argument("--one", action="store_true", help="one vessel at warp 10 only")
    parser.add_argument("--oilspill", type=int, metavar="N",
                        help="instead: N vessels of missions/oilspill (the demo's, with contact manager, brokers, "
                             "pShare...) and their shoreside, deployed, at each of --warps")
    parser.add_argument("--demo-ticks", action="store_true",
                        help="with --oilspill: the simulator/PID and helm at 4 and 2 Hz, as in the real-scale demo")
    parser.add_argument("--per-process", type=int, default=1, metavar="K",
                        help="K vessels hosted in each pAntler (pAntler --with): their apps wake together")
    parser.add_argument("--sockets", action="store_true",
                        help="the MOOSDB as a child process, apps over loopback TCP (pAntler --one-process alone)")
    args = parser.parse_args()
    if args.oilspill:
        ticks = {"SIM_TICK": "4", "HELM_TICK": "2"} if args.demo_ticks else {}
        for warp in (float(w) for w in args.warps.split(",")):
            vessel_ms, shore_ms, late = asyncio.run(run_oilspill(args.oilspill, warp, args.window, ticks,
                                                                 args.per_process))
            print(f"{args.oilspill:3d} oil-spill vessel(s) at warp {warp:g}: {vessel_ms:7.2f} ms CPU per vessel per "
                  f"simulated second; shoreside {shore_ms:7.2f} ms per simulated second; behind their AppTick: "
                  f"{', '.join(late) or 'none'}", flush=True)
        return
    if args.per_process < 1 or (args.sockets and args.per_process > 1):
        parser.error("--per-process needs K >= 1, and the hosted DB (not --sockets)")
    modes = ("--one-process",) if args.sockets else ("--one-process", "--host-db")
    fleets = [1] if args.one else [int(n) for n in args.fleets.split(",")]
    warp = 10.0 if args.one else args.warp
    kept_up: dict[float, dict[int, bool]] = {warp: {}}
    for vessels in fleets:
        ms, behind = asyncio.run(run_fleet(vessels, warp, args.window, modes, args.per_process))
        kept_up[warp][vessels] = not behind
        print(f"{vessels:3d} vessel(s) at warp {warp:g}: {ms:7.2f} ms CPU per vessel per simulated second; "
              f"behind their AppTick: {', '.join(behind) or 'none'}", flush=True)
    if args.one:
        return
    for warp in (float(w) for w in args.warps.split(",") if w):    # --warps "": no search
        results = kept_up.setdefault(warp, {})
        low, high = 0, None   # largest fleet known to keep up / smallest known not to
        for vessels, ok in sorted(results.items()):
            if ok:
                low = max(low, vessels)
            elif high is None or vessels < high:
                high = vessels
        vessels = max(1, low * 2) if high is None else (low + high) // 2
        while vessels > low and (high is None or vessels < high) and vessels <= 64:
            _, behind = asyncio.run(run_fleet(vessels, warp, args.window, modes, args.per_process))
            print(f"  warp {warp:g}, {vessels} vessel(s): {'behind: ' + ', '.join(behind) if behind else 'kept up'}",
                  flush=True)
            if behind:
                high = vessels
            else:
                low = vessels
            vessels = low * 2 if high is None else (low + high) // 2
        print(f"largest fleet that keeps up at warp {warp:g}: {low} vessel(s)", flush=True)


if __name__ == "__main__":
    main()
