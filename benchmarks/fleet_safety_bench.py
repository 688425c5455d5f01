"""Fleet safety on missions/oilspill: 10 vessels start clustered 50 m apart and cross each other on
their way to their starting positions round a spill; uFldCollisionDetect judges every pair.

For each seed (the side of the cluster the spill lies on, which vessel sits where in the cluster,
uFldNodeComms's drop dice) and each drop percentage (0 and 20 % of the relayed NODE_REPORTs), the
mission runs from deployment until every vessel has been on the containment loop for LOOP_S mission
seconds. Printed per run and in total: collisions, near misses and encounters (COLLISION_TOTAL,
NEAR_MISS_TOTAL, ENCOUNTER_TOTAL), the minimum separation (the least UCD_CLOSEST_RANGE), how many
pairs of transit routes cross, the transit time, and how well the machine kept up with the time
warp (NAV_X posts per mission second against uSimMarineV22's 5).

Run: nice -n 10 .venv/bin/python benchmarks/fleet_safety_bench.py [--warp 4] [--seeds 5] [--drops 0,20]
     [--no-avoid]   (the same without collision avoidance, for comparison)
     [--patrol arcs|loop]   (pPathAssign's patrol mode; arcs, the mission's default, unless given)
"""
from __future__ import annotations

import argparse
import asyncio
import itertools
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import shapely

from moosdb_py.alog import read_alog
from oilspill_moos.forecaster.push import BoundaryPusher
from oilspill_moos.oilspill_mission import Observer, OilspillMission, wait_for
from oilspill_moos.messages import format_points
from oilspill_moos.response.path_assign import OIL_PATH

VESSELS = 10
SPACING = 50.0        # m between neighbours in the cluster (two rows of five)
SPILL_SIDE = 110.0    # m; with the stand-off a 150 m square loop: 60 m between starting positions
STANDOFF = 20.0
SPILL_DISTANCE = 250.0  # m from the cluster's centre to the spill's
LOOP_S = 30.0         # mission seconds on the loop after the last arrival
SIM_NAV_RATE = 5.0    # NAV_X per mission second from uSimMarineV22 at AppTick 10 (every second iteration)


def cluster(rng: np.random.Generator) -> list[tuple[float, float]]:
    """Two rows of five, SPACING apart, about the origin, in a random order of vessels."""
    grid = [((i - 2) * SPACING, (j - 0.5) * SPACING) for j in range(2) for i in range(5)]
    return [grid[k] for k in rng.permutation(len(grid))]


def spill(rng: np.random.Generator) -> str:
    """A square spill SPILL_DISTANCE from the cluster, on a random side."""
    bearing = rng.uniform(0.0, 2.0 * math.pi)
    cx, cy = SPILL_DISTANCE * math.sin(bearing), SPILL_DISTANCE * math.cos(bearing)
    h = SPILL_SIDE / 2
    return f"pts={{{format_points([(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)])}}}\n"


def crossings(starts: dict[str, tuple[float, float]], routes: dict[str, list[tuple[float, float]]]) -> int:
    """Pairs of vessels whose transit routes (from where they started) cross."""
    lines = {name: shapely.LineString([starts[name], *route]) for name, route in routes.items() if name in starts}
    return sum(a.crosses(b) for a, b in itertools.combinations(lines.values(), 2))


async def fly(mission: OilspillMission, boundary: str, timeout: float) -> dict:
    observer = Observer("127.0.0.1", mission.shoreside.moos_port, mission.warp)
    task = asyncio.create_task(observer.client.run())
    try:
        await observer.client.wait_connected(timeout)
        await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout, "every vessel reporting", mission)
        await observer.deploy(mission.fleet, timeout, mission)
        pusher = BoundaryPusher("127.0.0.1", mission.boundary_port, connect_timeout=timeout)
        pushed = observer.moos_now
        await pusher.push(boundary.encode())
        await pusher.close()
        await wait_for(lambda: observer.phase_count.get(OIL_PATH, 0) >= 1, timeout, "every vessel at its start", mission)
        arrived = observer.moos_now
        await wait_for(lambda: observer.moos_now - arrived >= LOOP_S, timeout, "the loops", mission)
        return {"transit_s": arrived - pushed, "routes": dict(observer.routes), "dropped": list(observer.dropped)}
    finally:
        observer.client.close()
        task.cancel()


def judge(mission: OilspillMission) -> dict:
    """What uFldCollisionDetect counted, from the shoreside alog; and the sim's posting rate."""
    shore = read_alog(mission.alog("shoreside"))
    last = {key: shore.values(key)[-1] if shore.values(key) else 0.0
            for key in ("COLLISION_TOTAL", "NEAR_MISS_TOTAL", "ENCOUNTER_TOTAL")}
    closest = [v for v in shore.values("UCD_CLOSEST_RANGE") if isinstance(v, float)]
    rates = []
    for name in mission.fleet:
        alog = read_alog(mission.alog(name))
        times = [e.time for e in alog.entries if e.key == "NAV_X"]
        if len(times) > 1:
            rates.append((len(times) - 1) / (times[-1] - times[0]))
    return {"collisions": int(last["COLLISION_TOTAL"]), "near_misses": int(last["NEAR_MISS_TOTAL"]),
            "encounters": int(last["ENCOUNTER_TOTAL"]), "min_sep": min(closest, default=math.inf),
            "keep_up": min(rates, default=0.0) / SIM_NAV_RATE}


def run(seed: int, drop: float, warp: float, avoid: bool, timeout: float, folder: Path, patrol: str) -> dict:
    rng = np.random.default_rng(seed)
    starts = cluster(rng)
    boundary = spill(rng)
    extra = {"COMMS_DROP": f"{drop:g}", "COMMS_SEED": str(seed), "AVOID": "true" if avoid else "false",
             "PATROL": patrol}
    mission = OilspillMission(folder, vehicles=VESSELS, warp=warp, starts=starts, standoff=STANDOFF,
                              node_timeout=60.0, extra=extra)
    began = time.monotonic()
    with mission:
        flown = asyncio.run(fly(mission, boundary, timeout))
    result = {**flown, **judge(mission), "wall_s": time.monotonic() - began}
    result["crossings"] = crossings(dict(zip(mission.fleet, starts)), flown["routes"])
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--warp", type=float, default=4.0, help="MOOSTimeWarp (default 4)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--drops", default="0,20", help="uFldNodeComms drop percentages (default 0,20)")
    parser.add_argument("--no-avoid", action="store_true", help="fly without collision avoidance")
    parser.add_argument("--timeout", type=float, default=300.0, help="wall seconds per step (default 300)")
    parser.add_argument("--patrol", choices=("arcs", "loop"), default="arcs", help="pPathAssign patrol mode (default arcs)")
    parser.add_argument("--keep", type=Path, default=None, help="keep the runs' folders here")
    args = parser.parse_args(argv)
    drops = [float(d) for d in args.drops.split(",")]
    avoid = not args.no_avoid
    print(f"{VESSELS} vessels clustered {SPACING:g} m apart, spill {SPILL_DISTANCE:g} m away, "
          f"time warp {args.warp:g}, patrol {args.patrol}, avoidance {'on' if avoid else 'off'}")
    print(f"{'drop %':>6} {'seed':>4} {'collisions':>10} {'near miss':>9} {'encounters':>10} {'min sep m':>9} "
          f"{'crossings':>9} {'transit s':>9} {'keep-up':>7} {'wall s':>6}")
    base = args.keep or Path(tempfile.mkdtemp(prefix="fleet_safety_"))
    for drop in drops:
        rows = []
        for seed in range(1, args.seeds + 1):
            r = run(seed, drop, args.warp, avoid, args.timeout, base / f"drop{drop:g}_seed{seed}", args.patrol)
            rows.append(r)
            print(f"{drop:>6g} {seed:>4} {r['collisions']:>10} {r['near_misses']:>9} {r['encounters']:>10} "
                  f"{r['min_sep']:>9.1f} {r['crossings']:>9} {r['transit_s']:>9.0f} {r['keep_up']:>7.2f} "
                  f"{r['wall_s']:>6.0f}" + (f"  dropped by pPathAssign: {r['dropped']}" if r["dropped"] else ""),
                  flush=True)
        print(f"{drop:>6g} {'all':>4} {sum(r['collisions'] for r in rows):>10} "
              f"{sum(r['near_misses'] for r in rows):>9} {sum(r['encounters'] for r in rows):>10} "
              f"{min(r['min_sep'] for r in rows):>9.1f} {sum(r['crossings'] for r in rows):>9}", flush=True)


if __name__ == "__main__":
    main()
