"""Cost of the shoreside judges and the vehicle contact manager per round, and what the judge sees.

For N vessels (10, 30, 100) running straight lines across a square, prints the time one round
takes in uFldCollisionDetect (all pairs), uFldNodeComms (relaying every report, 20 % drops) and
one vessel's pContactMgrV20 (ranges, CPA and an avoidance alert for every contact), and the
encounters, near misses and collisions the judge counted in 300 s without any avoidance.
Run: .venv/bin/python benchmarks/collision_bench.py
"""
from __future__ import annotations

import time

import numpy as np

from oilspill_moos.field.collision_detect import CollisionMonitor, CollisionParams
from oilspill_moos.field.node_comms import NodeCommsParams, NodeCommsRelay
from oilspill_moos.marine.contact_mgr import ContactManager, ContactMgrParams

ALERT = 'id=avd, var=CONTACT_INFO, val="name=avd_$[VNAME] # contact=$[VNAME]", alert_range=40, cpa_range=60'
SECONDS, SPEED = 300, 2.0


def tracks(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Start points in a square sized for ~1 vessel per 50 x 50 m, random headings."""
    rng = np.random.default_rng(seed)
    side = 50.0 * np.sqrt(n)
    return rng.uniform(0, side, (n, 2)), rng.uniform(0, 360, n)


def reports(start: np.ndarray, heading: np.ndarray, t: float) -> list[str]:
    rad = np.radians(heading)
    xy = start + SPEED * t * np.column_stack([np.sin(rad), np.cos(rad)])
    return [f"NAME=v{i},X={x:.2f},Y={y:.2f},SPD={SPEED},HDG={h:.1f},TIME={t}"
            for i, ((x, y), h) in enumerate(zip(xy, heading))]


def run(n: int, seed: int = 1) -> dict:
    start, heading = tracks(n, seed)
    judge = CollisionMonitor(CollisionParams())
    relay = NodeCommsRelay(NodeCommsParams(comms_range=200.0, drop_percentage=20.0), np.random.default_rng(seed))
    manager = ContactManager("v0", ContactMgrParams(alerts=[ALERT]))
    cost = {"judge": 0.0, "relay": 0.0, "manager": 0.0}
    spawned = 0
    for t in range(SECONDS):
        batch = reports(start, heading, float(t))
        own = batch[0].split(",")
        for key, field in (("NAV_X", 1), ("NAV_Y", 2)):
            manager.on_mail(key, float(own[field].split("=")[1]), t)
        manager.on_mail("NAV_HEADING", float(heading[0]), t)
        manager.on_mail("NAV_SPEED", SPEED, t)
        for what, feed, step in (("judge", lambda r: judge.on_mail("NODE_REPORT", r), judge.iterate),
                                 ("relay", lambda r: relay.on_mail("NODE_REPORT", r, t), relay.iterate),
                                 ("manager", lambda r: manager.on_mail("NODE_REPORT", r, t), manager.iterate)):
            began = time.perf_counter()
            for text in batch:
                feed(text)
            posts = step(t)
            cost[what] += time.perf_counter() - began
            if what == "manager":
                spawned += sum(1 for key, _ in posts if key == "CONTACT_INFO")
    return {"n": n, **{k: 1e3 * v / SECONDS for k, v in cost.items()}, "totals": judge.totals,
            "closest": judge.closest_ever, "relayed": relay.stats.reports_sent, "dropped": relay.stats.reports_dropped,
            "spawned": spawned}


def main() -> None:
    print(f"{SECONDS} s of straight-line vessels at {SPEED} m/s, no avoidance; ms per round (1 report per vessel)")
    print(f"{'N':>4} {'judge ms':>9} {'relay ms':>9} {'cmgr ms':>8}  {'encounters':>10} {'near miss':>9} "
          f"{'collisions':>10} {'closest m':>9} {'relayed':>8} {'dropped %':>9} {'alerts':>6}")
    for n in (10, 30, 100):
        r = run(n)
        dropped = 100.0 * r["dropped"] / max(1, r["relayed"] + r["dropped"])
        print(f"{r['n']:>4} {r['judge']:>9.3f} {r['relay']:>9.3f} {r['manager']:>8.3f}  "
              f"{r['totals']['encounter']:>10} {r['totals']['near_miss']:>9} {r['totals']['collision']:>10} "
              f"{r['closest']:>9.2f} {r['relayed']:>8} {dropped:>9.1f} {r['spawned']:>6}")


if __name__ == "__main__":
    main()
