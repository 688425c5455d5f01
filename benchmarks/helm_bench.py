"""Helm iteration time with 1, 5 and 20 active behaviours (goal: under 5 ms with 5).

Each behaviour is a BHV_Waypoint or BHV_StationKeep over the usual course:0:359:360 x speed:0:4:41
domain, all active at once. The figure is the CPU time (process_time) of one Helm.iterate: on this
shared 2-core machine wall time mostly measures the other processes.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

from behaviors.bhv_file import parse_bhv
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.helm import Helm
from moosdb_py.source import SourceLine


def bhv_text(n: int) -> str:
    blocks = []
    for i in range(n):
        if i % 2:
            blocks.append(f"Behavior = BHV_StationKeep\n{{\n name = sk{i}\n station_pt = {10 * i},-20\n}}\n")
        else:
            blocks.append(f"Behavior = BHV_Waypoint\n{{\n name = wp{i}\n speed = 2\n lead = 8\n"
                          f" points = 0,{-100 - i}:200,-100:200,100\n repeat = forever\n}}\n")
    return "\n".join(blocks)


def bench(n: int, batches: int = 10, per_batch: int = 20) -> tuple[float, float]:
    """(best, median) of the per-batch mean CPU time of one iteration, in ms."""
    domain = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])
    lines = [SourceLine(t, Path("bench.bhv"), i) for i, t in enumerate(bhv_text(n).splitlines(), 1)]
    helm = Helm([parse_bhv(lines)], domain, "bench", active_start=True)
    helm.startup(0.0)
    for var, value in dict(NAV_X=5.0, NAV_Y=-30.0, NAV_HEADING=45.0, NAV_SPEED=1.5).items():
        helm.on_mail(var, value, 0.0)
    t = 2.0
    helm.iterate(t)
    assert sum(b.state == "active" for b in helm.behaviors) == n
    means = []
    for _ in range(batches):
        start = time.process_time()
        for _ in range(per_batch):
            t += 0.25
            helm.on_mail("NAV_X", 5.0 + 0.01 * t, t)
            helm.iterate(t)
        means.append((time.process_time() - start) / per_batch * 1e3)
    return min(means), statistics.median(means)


if __name__ == "__main__":
    for n in (1, 5, 20):
        best, median = bench(n)
        print(f"helm iteration, {n:2d} active behaviours: {best:6.2f} ms CPU (median of batches {median:6.2f} ms)")
