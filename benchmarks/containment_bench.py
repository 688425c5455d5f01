"""Containment figures: planner run time, and boundary push -> every vehicle on its loop.

    python benchmarks/containment_bench.py [--sizes 3,10,30] [--warp W] [--planner-only]
    python benchmarks/containment_bench.py --response [--vehicles 8] [--warp 30] [--cycles 3]

For each fleet size the whole stack runs (missions/oilspill, one pAntler per
community in --one-process mode) with the vehicles on a start line south of a
shipped spill outline. The time from the boundary push to pPathAssign's OIL-PATH
(every vehicle arrived) is set against the lower bound: the longest straight-line
distance from a vehicle to its assigned point divided by the transit speed, plus
nothing for station-keeping and coordination. Times are mission (MOOS) seconds.

--response runs the default demo's real-scale response instead (oilspill_moos/response_demo.py: a
truth spill, the forecaster every cycle, each vessel on its own arc) and prints, per cycle, the time
from the push until every arc is manned against the physical bound (longest route / top speed x 1.3)
and the share of the true perimeter covered, with the wall time and the NODE_REPORT rate that shows
whether the communities kept up with the warp.
"""
from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from oilspill_moos.demo import shipped_boundaries
from oilspill_moos.oilspill_mission import (
    ORIGIN,
    STANDOFF,
    VEHICLE_SPACING,
    Observer,
    OilspillMission,
    vehicle_names,
    wait_for,
)
from oilspill_moos.forecaster.push import BoundaryPusher
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.messages import parse_boundary_line
from oilspill_moos.response.path_assign import OIL_PATH, STARTING_POSITION
from oilspill_moos.response.planner import containment_region, plan_arcs, plan_containment

TRANSIT_SPEED = 2.5  # the mission's default TRANSIT_SPEED, m/s


def start_line(n: int) -> dict[str, tuple[float, float]]:
    """Where OilspillMission puts the vehicles by default (a line south of the origin)."""
    return {name: ((i - (n - 1) / 2) * VEHICLE_SPACING, 0.0) for i, name in enumerate(vehicle_names(n))}


def planner_figures(sizes: list[int]) -> None:
    outline = parse_boundary_line(shipped_boundaries()[0].decode(), LocalGrid(*ORIGIN)).polygon
    region = containment_region(outline, STANDOFF)
    print(f"planner: stand-off loop {region.exterior.length:.0f} m, {len(region.exterior.coords) - 1} vertices")
    for n in sizes:
        positions = start_line(n)
        for planner in (plan_containment, plan_arcs):
            runs = []
            for _ in range(5):
                t0 = time.perf_counter()
                plan = planner(region, positions)
                runs.append(time.perf_counter() - t0)
            print(f"  N={n:3d}: {planner.__name__:16s} {1000 * statistics.median(runs):7.1f} ms (median of 5), "
                  f"longest transit {plan.bottleneck:6.1f} m")


async def stack_figure(n: int, warp: float, timeout: float) -> None:
    line = shipped_boundaries()[0]
    with tempfile.TemporaryDirectory(prefix=f"containment_{n}_") as folder:
        mission = OilspillMission(Path(folder), vehicles=n, warp=warp, standoff=STANDOFF)
        launched = time.monotonic()
        with mission:
            observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
            task = asyncio.create_task(observer.client.run())
            try:
                await observer.client.wait_connected(timeout)
                await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout, "fleet online", mission)
                online = time.monotonic() - launched
                await observer.deploy(mission.fleet, timeout, mission)
                pusher = BoundaryPusher("127.0.0.1", mission.boundary_port, connect_timeout=timeout)
                await pusher.push(line)
                pushed = observer.moos_now
                await wait_for(lambda: observer.phase_count.get(STARTING_POSITION, 0) > 0, timeout, "plan", mission)
                planned = observer.moos_now
                await wait_for(lambda: observer.phase_count.get(OIL_PATH, 0) > 0, timeout, "all on loop", mission)
                on_loop = observer.moos_now
                await pusher.close()
            finally:
                observer.client.close()
                task.cancel()
        starts = {name: loop[0] for name, loop in observer.loops.items()}
        positions = start_line(n)
        longest = max(np.hypot(starts[v][0] - positions[v][0], starts[v][1] - positions[v][1]) for v in starts)
        bound = longest / TRANSIT_SPEED
        print(f"  N={n:3d}: push -> all on loop {on_loop - pushed:7.1f} s (coordinates {planned - pushed:5.1f} s), "
              f"lower bound {bound:6.1f} s, ratio {(on_loop - pushed) / bound:4.2f}; "
              f"time warp {warp:g}, fleet online after {online:5.1f} s wall")


def response_figures(vehicles: int, warp: float, cycles: int, timeout: float) -> int:
    from oilspill_moos.response_demo import run_response, summary_lines

    with tempfile.TemporaryDirectory(prefix="response_bench_") as folder:
        record = asyncio.run(run_response(Path(folder), vehicles, warp, cycles, 2.0, timeout))
    print(f"response at real scale ({record['scenario']}, {vehicles} vessels, warp {warp:g}):")
    for c in record["cycles"]:
        print(f"  cycle {c['cycle']}: push -> every arc manned {c['push_to_manned_s']:7.1f} s, bound "
              f"{c['bound_s']:7.1f} s (longest route {c['longest_route_m'] / 1000:.1f} km), ratio "
              f"{c['push_to_manned_s'] / c['bound_s']:.2f}; perimeter coverage {100 * (c['coverage_mean'] or 0):.0f} %")
    for line in summary_lines(record)[-1:]:
        print("  " + line)
    print(f"  wall time {record['wall_s']:.0f} s")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="3,10,30", help="fleet sizes (default 3,10,30)")
    parser.add_argument("--warp", type=float, default=None,
                        help="MOOSTimeWarp for the stack runs (default: 10 up to 3 vehicles, 5 up to 10, else 2, "
                             "so that 2 cores keep up)")
    parser.add_argument("--timeout", type=float, default=600.0, help="wall seconds allowed per step")
    parser.add_argument("--planner-only", action="store_true", help="skip the full-stack runs")
    parser.add_argument("--response", action="store_true", help="the real-scale response run instead")
    parser.add_argument("--vehicles", type=int, default=8, help="--response: fleet size (default 8)")
    parser.add_argument("--cycles", type=int, default=3, help="--response: forecast cycles (default 3)")
    args = parser.parse_args(argv)
    if args.response:
        return response_figures(args.vehicles, args.warp or 30.0, args.cycles, args.timeout)
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    planner_figures(sizes)
    if not args.planner_only:
        print(f"full stack (transit speed {TRANSIT_SPEED} m/s, stand-off {STANDOFF:g} m):")
        for n in sizes:
            warp = args.warp or (10.0 if n <= 3 else 5.0 if n <= 10 else 2.0)
            try:
                asyncio.run(stack_figure(n, warp, args.timeout))
            except (TimeoutError, RuntimeError) as exc:
                print(f"  N={n:3d}: failed: {exc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
