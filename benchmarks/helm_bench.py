"""Helm iteration time with 1, 5 and 20 active behaviours (goal: under 5 ms with 5).

Each behaviour is a BHV_Waypoint or BHV_StationKeep over the usual course:0:359:360 x speed:0:4:41
domain, all running at once; the figure is the mean wall time of Helm.iterate.
"""
from __future__ import annotations

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


def bench(n: int, iterations: int = 200) -> float:
    domain = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])
    lines = [SourceLine(t, Path("bench.bhv"), i) for i, t in enumerate(bhv_text(n).splitlines(), 1)]
    helm = Helm([parse_bhv(lines)], domain, "bench", active_start=True)
    helm.startup(0.0)
    t = 2.0
    for var, value in dict(NAV_X=5.0, NAV_Y=-30.0, NAV_HEADING=45.0, NAV_SPEED=1.5).items():
        helm.on_mail(var, value, 0.0)
    helm.iterate(t)
    start = time.perf_counter()
    for k in range(iterations):
        helm.on_mail("NAV_X", 5.0 + 0.01 * k, t)
        helm.iterate(t + 0.25 * k)
    return (time.perf_counter() - start) / iterations * 1e3


if __name__ == "__main__":
    for n in (1, 5, 20):
        print(f"helm iteration, {n:2d} active behaviours: {bench(n):6.2f} ms")
