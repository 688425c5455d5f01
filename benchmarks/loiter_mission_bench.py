"""Issue 15's four-vehicle MOOS-IvP loiter mission (the corpus m2_berta for four vehicles, with the
deprecated uSimMarine / pMarinePID of the issue's mission; see tests/corpus_loiter.py) flown by this
stack: metres each vessel covers in the first 900 simulated seconds after DEPLOY, with the
BHV_AvoidCollision block live and with it removed, against the C++ vessels' 1,025-1,037 m
(avoidance removed, issue 15). `--v22` adds the corpus's own uSimMarineV22 / pMarinePIDV22 for
comparison. "min sep m" is the closest two vessels came (vehicles 1 and 2 of the shore broker swap
loiter regions every 180 s, head-on). "keep-up" is the slowest vessel's NAV_X posts per simulated second against the 10 its
simulator posts at AppTick 10 (the deprecated one posts every iteration, V22 every second one).

Run: nice -n 10 .venv/bin/python benchmarks/loiter_mission_bench.py [--warp 10] [--seconds 900] [--v22]
Needs ../shared/missions-corpus.
"""
from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from corpus_loiter import CPP_DISTANCE_M, M2_BERTA, VEHICLES, LoiterMission, closest_approach, distances, fly  # noqa: E402
from moosdb_py.alog import read_alog  # noqa: E402


def keep_up(mission: LoiterMission, nav_per_s: float) -> float:
    rates = []
    for v in mission.fleet.values():
        times = [e.time for e in read_alog(mission.alog(v.name)).entries if e.key == "NAV_X"]
        rates.append((len(times) - 1) / (times[-1] - times[0]))
    return min(rates) / nav_per_s


def run(folder: Path, warp: float, seconds: float, deprecated: bool, avoid: bool) -> dict:
    began = time.monotonic()
    mission = LoiterMission(folder, warp=warp, deprecated=deprecated, avoid=avoid)
    with mission:
        flown = asyncio.run(fly(mission, seconds + 5.0))
    return {"distances": distances(mission, seconds), "keep_up": keep_up(mission, 10.0 if deprecated else 5.0),
            "closest": closest_approach(mission, seconds),
            "wall": time.monotonic() - began, "clients": flown["clients"]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--warp", type=float, default=10.0)
    parser.add_argument("--seconds", type=float, default=900.0)
    parser.add_argument("--v22", action="store_true", help="also fly the corpus's uSimMarineV22 / pMarinePIDV22")
    parser.add_argument("--keep", type=Path, default=None, help="keep the runs' folders here")
    args = parser.parse_args(argv)
    if not M2_BERTA.is_dir():
        sys.exit(f"needs {M2_BERTA} (../shared/missions-corpus)")
    base = args.keep or Path(tempfile.mkdtemp(prefix="loiter_mission_"))
    cases = [("uSimMarine", True, False), ("uSimMarine", True, True)]
    if args.v22:
        cases += [("uSimMarineV22", False, False), ("uSimMarineV22", False, True)]
    print(f"m2_berta, 4 vessels, {args.seconds:g} simulated s after DEPLOY, time warp {args.warp:g}; "
          f"C++ (avoidance removed): {CPP_DISTANCE_M[0]:,.0f}-{CPP_DISTANCE_M[1]:,.0f} m")
    print(f"{'simulator':<14} {'avoidance':<9} " + " ".join(f"{n:>7}" for n in VEHICLES)
          + f" {'mean':>7} {'vs C++':>7} {'min sep m':>9} {'keep-up':>7} {'wall s':>6}")
    mid = sum(CPP_DISTANCE_M) / 2
    for sim, deprecated, avoid in cases:
        r = run(base / f"{sim}_{'avoid' if avoid else 'noavoid'}", args.warp, args.seconds, deprecated, avoid)
        d = r["distances"]
        mean = sum(d.values()) / len(d)
        print(f"{sim:<14} {'on' if avoid else 'removed':<9} " + " ".join(f"{d[n]:>7.0f}" for n in VEHICLES)
              + f" {mean:>7.0f} {100 * (mean / mid - 1):>+6.1f}% {r['closest']:>9.1f} {r['keep_up']:>7.2f}"
              + f" {r['wall']:>6.0f}", flush=True)


if __name__ == "__main__":
    main()
