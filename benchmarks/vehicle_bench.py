"""Cost of the simulated vehicle's per-iteration work, and how many vehicles one core could carry.

    python benchmarks/vehicle_bench.py [--iterations N]

Times the pure parts each app runs every AppTick: uSimMarine's model step plus its
lat/lon conversion, pMarinePID's control law, pNodeReporter's report string, and the
vectorised LocalGrid on 100 000 points. From the per-iteration costs and s1_alpha's
AppTicks (sim 4, PID 10, reporter 2; nav posted every second sim iteration) it prints
the CPU a vehicle needs per warped second, excluding MOOS messaging.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from oilspill_moos.geodesy import LocalGrid
from oilspill_moos.marine.marine_pid import PIDEngine, PIDParams
from oilspill_moos.marine.node_reporter import NodeReportBuilder, ReporterParams
from oilspill_moos.marine.sim_marine import MarineModel, SimParams

ALPHA_SIM = {"start_pos": "0,-20,180,0", "prefix": "NAV", "turn_rate": "95",
             "thrust_map": "0:0, 20:1, 40:2, 60:3, 80:4, 100:5", "turn_spd_loss": "0.4"}
ALPHA_PID = {"depth_control": "false", "yaw_pid_kp": "0.9", "yaw_pid_kd": "0.3", "yaw_pid_ki": "0.3",
             "yaw_pid_integral_limit": "0.07", "speed_factor": "20"}


def per_call(fn, n: int) -> float:
    """Mean seconds per call of fn(i) over n calls."""
    start = time.perf_counter()
    for i in range(n):
        fn(i)
    return (time.perf_counter() - start) / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=20000)
    n = parser.parse_args().iterations

    grid = LocalGrid(43.8253, -70.3304)
    model = MarineModel(SimParams.from_config(ALPHA_SIM))
    model.set_thrust(60)

    def sim_step(i):
        model.set_rudder(30.0 if (i // 40) % 2 else -30.0, i * 0.25)
        model.step(0.25)

    def sim_latlon(i):
        grid.to_latlon(model.state.x, model.state.y)

    engine = PIDEngine(PIDParams.from_config(ALPHA_PID))
    builder = NodeReportBuilder("alpha", ReporterParams.from_config({"platform_type": "kayak",
                                                                     "platform_length": "4"}))
    for key, value in (("NAV_X", 12.5), ("NAV_Y", -40.2), ("NAV_SPEED", 2.0), ("NAV_HEADING", 181.3),
                       ("NAV_LAT", 43.82494), ("NAV_LONG", -70.3302), ("IVPHELM_STATE", "DRIVE")):
        builder.on_mail(key, value, 0.0)

    costs = {
        "uSimMarine model step": per_call(sim_step, n),
        "uSimMarine lat/lon (scalar)": per_call(sim_latlon, n // 4),
        "pMarinePID control law": per_call(lambda i: engine.control(90.0, 2.0, i % 360, 1.8, i * 0.1), n),
        "pNodeReporter report string": per_call(lambda i: builder.node_report(float(i)), n),
    }
    for name, seconds in costs.items():
        print(f"{name:32s} {seconds * 1e6:8.2f} us")

    xs = np.random.default_rng(1).uniform(-5000, 5000, (2, 100_000))
    start = time.perf_counter()
    lat, lon = grid.to_latlon(xs[0], xs[1])
    grid.to_local(lat, lon)
    print(f"{'LocalGrid round trip, 100k pts':32s} {(time.perf_counter() - start) * 1e3:8.2f} ms")

    per_second = (4 * costs["uSimMarine model step"] + 2 * costs["uSimMarine lat/lon (scalar)"]
                  + 10 * costs["pMarinePID control law"] + 2 * costs["pNodeReporter report string"])
    print(f"{'vehicle model CPU per warped s':32s} {per_second * 1e6:8.2f} us "
          f"(one core: ~{1 / per_second:,.0f} vehicle-seconds per second, messaging excluded)")


if __name__ == "__main__":
    main()
