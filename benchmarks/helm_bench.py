"""Helm iteration time with 1, 5 and 20 active behaviours (goal: under 5 ms with 5), with 10
spawned BHV_AvoidCollision behaviours (goal: under 5 ms), s1_alpha's own helm surveying, and a
head-on encounter at 2 m/s. `--alpha-iterations N` only flies s1_alpha's helm, for instruction counts
(`count_alpha`): `PYTHONHASHSEED=0 setarch -R valgrind --tool=callgrind --instr-atstart=no python
benchmarks/helm_bench.py --alpha-iterations 400` counts iterations 40-440 alone (a count of the whole run
varies by some 50 M instructions from run to run with the imports).

s1_alpha's helm is timed twice: iterations back to back (caches warm), and with the CPU caches
flushed between iterations (a sum over an array larger than the last-level cache), which is how
the helm runs inside a vessel, between the other apps and the machine's other processes; the
second figure is the one that matches the helm's share of vehicle_bench.py (3-4 times the first).

Each behaviour is a BHV_Waypoint or BHV_StationKeep over the usual course:0:359:360 x speed:0:4:41
domain, all active at once. The figure is the CPU time (process_time) of one Helm.iterate: on this
shared 2-core machine wall time mostly measures the other processes. The head-on run reports the
closest approach (goal: at least min_util_cpa_dist) and the time lost against the straight path.
"""
from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from behaviors.bhv_file import parse_bhv, read_bhv
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.helm import Helm
from moosdb_py.source import SourceLine

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "behaviors"))
from helm_sim import AVOID_MISSION, Boat, head_on, node_report as report  # noqa: E402  (the test support module)


def bhv_text(n: int) -> str:
    blocks = []
    for i in range(n):
        if i % 2:
            blocks.append(f"Behavior = BHV_StationKeep\n{{\n name = sk{i}\n station_pt = {10 * i},-20\n}}\n")
        else:
            blocks.append(f"Behavior = BHV_Waypoint\n{{\n name = wp{i}\n speed = 2\n lead = 8\n"
                          f" points = 0,{-100 - i}:200,-100:200,100\n repeat = forever\n}}\n")
    return "\n".join(blocks)


DOMAIN = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])


def make_helm(text: str) -> Helm:
    lines = [SourceLine(t, Path("bench.bhv"), i) for i, t in enumerate(text.splitlines(), 1)]
    helm = Helm([parse_bhv(lines)], DOMAIN, "bench", active_start=True)
    helm.startup(0.0)
    return helm


def time_iterations(helm: Helm, t: float, batches: int, per_batch: int, mail) -> tuple[float, float]:
    """(best, median) of the per-batch mean CPU time of one iteration, in ms."""
    means = []
    for _ in range(batches):
        start = time.process_time()
        for _ in range(per_batch):
            t += 0.25
            mail(t)
            helm.iterate(t)
        means.append((time.process_time() - start) / per_batch * 1e3)
    return min(means), statistics.median(means)


def bench(n: int, batches: int = 10, per_batch: int = 20) -> tuple[float, float]:
    helm = make_helm(bhv_text(n))
    for var, value in dict(NAV_X=5.0, NAV_Y=-30.0, NAV_HEADING=45.0, NAV_SPEED=1.5).items():
        helm.on_mail(var, value, 0.0)
    helm.iterate(2.0)
    assert sum(b.state == "active" for b in helm.behaviors) == n
    return time_iterations(helm, 2.0, batches, per_batch, lambda t: helm.on_mail("NAV_X", 5.0 + 0.01 * t, t))


def contacts_at(t: float, n: int) -> list[str]:
    """n contacts on a 60 m ring about ownship, each heading across it at 1.5 m/s."""
    return [report(f"c{i}", 60 * math.sin(2 * math.pi * i / n), 60 * math.cos(2 * math.pi * i / n),
                   (360 * i / n + 90) % 360, 1.5, t) for i in range(n)]


def bench_avoidance(n: int = 10, batches: int = 10, per_batch: int = 20) -> tuple[float, float]:
    helm = make_helm(AVOID_MISSION)
    for var, value in dict(NAV_X=0.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=2.0).items():
        helm.on_mail(var, value, 0.0)
    for i, text in enumerate(contacts_at(0.0, n)):
        helm.on_mail("NODE_REPORT", text, 0.0)
        helm.on_mail("CONTACT_INFO", f"name=c{i} # contact=c{i}", 0.0)
    helm.iterate(2.0)
    assert sum(b.state == "active" and b.name.startswith("avd_") for b in helm.behaviors) == n

    def mail(t: float) -> None:
        for text in contacts_at(t, n):
            helm.on_mail("NODE_REPORT", text, t)
    return time_iterations(helm, 2.0, batches, per_batch, mail)


def fly_alpha(iterations: int, each=None) -> None:
    """`iterations` iterations of missions/s1_alpha's helm surveying from home (a Boat follows its
    decisions); `each(i, iterate)` runs each iteration (iterate() does it), by default plainly."""
    helm = Helm([read_bhv(ROOT / "missions" / "s1_alpha" / "alpha.bhv")], DOMAIN, "alpha", active_start=True)
    helm.startup(0.0)
    helm.on_mail("DEPLOY", "true", 0.0)
    boat, t = Boat(0, -20, 180), 0.0
    for i in range(iterations):
        for var, value in boat.nav().items():
            helm.on_mail(var, value, t)
        posts = each(i, lambda: helm.iterate(t)) if each is not None else helm.iterate(t)
        boat.step({v: val for v, val, _ in posts if v.startswith("DESIRED_")}, 0.25)
        t += 0.25


def bench_alpha(flush: bool, runs: int = 3, iterations: int = 400) -> float:
    """Median CPU ms of one iteration of missions/s1_alpha's helm while it surveys, caches flushed
    between iterations or not."""
    flusher = np.ones(8_000_000) if flush else None     # 64 MB: more than the last-level cache
    times = []

    def timed(i: int, iterate):
        start = time.process_time()
        posts = iterate()
        if i >= 40:
            times.append(time.process_time() - start)
        if flusher is not None:
            flusher.sum()
        return posts
    for _ in range(runs):
        fly_alpha(iterations, timed)
    return statistics.median(times) * 1e3


def head_on_figures(avoid: bool) -> tuple[float, float]:
    """(closest approach, transit time) of the head-on encounter, with or without the avoidance."""
    text = AVOID_MISSION if avoid else AVOID_MISSION[AVOID_MISSION.index("Behavior = BHV_Waypoint"):]
    closest, arrived, _ = head_on(make_helm(text))
    return closest, arrived


def count_alpha(iterations: int) -> None:
    """For instruction counts: under `setarch -R valgrind --tool=callgrind --instr-atstart=no` (with
    PYTHONHASHSEED=0), 40 iterations of s1_alpha's helm uncounted, then `iterations` counted (callgrind_control
    turns the counting on), with the helm's clocks fixed so that its summary does not depend on the speed."""
    import os
    import subprocess
    import types

    import behaviors.helm as helm_module
    helm_module.perf_counter = lambda: 0.0
    helm_module._time = types.SimpleNamespace(time=lambda: 0.0)

    def each(i: int, iterate):
        if i == 40:
            subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True, capture_output=True)
        return iterate()
    fly_alpha(40 + iterations, each)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--alpha-iterations":
        count_alpha(int(sys.argv[2]))
        sys.exit()
    for n in (1, 5, 20):
        best, median = bench(n)
        print(f"helm iteration, {n:2d} active behaviours: {best:6.2f} ms CPU (median of batches {median:6.2f} ms)")
    best, median = bench_avoidance()
    print(f"helm iteration, 10 spawned BHV_AvoidCollision + 1 waypoint: {best:6.2f} ms CPU "
          f"(median of batches {median:6.2f} ms; goal < 5 ms)")
    print(f"s1_alpha's helm surveying: {bench_alpha(False):6.3f} ms CPU per iteration back to back, "
          f"{bench_alpha(True):6.3f} ms with the caches flushed between iterations (as in a vessel)")
    (cpa, t_avoid), (cpa_none, t_straight) = head_on_figures(True), head_on_figures(False)
    print(f"head-on at 2 m/s: closest approach {cpa:.1f} m with avoidance (min_util_cpa_dist 10 m; "
          f"{cpa_none:.1f} m without), {t_avoid - t_straight:.1f} s lost against the straight path "
          f"({t_straight:.1f} s)")
