"""Latency and loss of a bridged variable, shoreside -> vehicle, at 1, 10 and 100 Hz.

    python benchmarks/bridge_bench.py [--seconds S] [--rates 1,10,100]

Launches missions/fleet with one vehicle (MOOSDB, pShare and the broker of each
community, under pAntler, time warp 1) on free loopback ports, waits for the
handshake, then posts `X_ALL` on the shoreside at each rate; the qbridge delivers it
to the vehicle as `X`. The value carries the wall-clock send time, so the latency is
the whole path: client -> shoreside MOOSDB -> pShare -> UDP -> pShare -> vehicle
MOOSDB -> client. Loss counts values that never arrived.
"""
from __future__ import annotations

import argparse
import asyncio
import importlib.util
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from moosdb_py.client import MOOSClient

ROOT = Path(__file__).resolve().parents[1]
APPS = ["MOOSDB", "pShare", "uFldShoreBroker", "uFldNodeBroker"]


def load_launcher():
    spec = importlib.util.spec_from_file_location("fleet_launch", ROOT / "missions" / "fleet" / "launch.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def free_pair(kind: int) -> int:
    """A base port with base and base+1 free."""
    while True:
        with socket.socket(socket.AF_INET, kind) as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        try:
            with socket.socket(socket.AF_INET, kind) as a, socket.socket(socket.AF_INET, kind) as b:
                a.bind(("127.0.0.1", base))
                b.bind(("127.0.0.1", base + 1))
            return base
        except OSError:
            continue


async def measure(shore: MOOSClient, arrivals: dict, rate: float, seconds: float, tag: str) -> tuple[int, list[float]]:
    count = max(1, int(rate * seconds))
    period = 1.0 / rate
    start = time.monotonic()
    for i in range(count):
        await asyncio.sleep(max(0.0, start + i * period - time.monotonic()))
        shore.notify("X_ALL", f"{tag}:{i}:{time.time():.6f}")
    await asyncio.sleep(1.0)  # stragglers
    latencies = [arrivals[(tag, i)] for i in range(count) if (tag, i) in arrivals]
    return count, latencies


async def bench(shore_port: int, vehicle_port: int, rates: list[float], seconds: float) -> None:
    arrivals: dict[tuple[str, int], float] = {}

    def on_mail(mail):
        now = time.time()
        for msg in mail:
            if msg.key == "X":
                tag, i, sent = msg.string.split(":")
                arrivals[(tag, int(i))] = now - float(sent)

    shore = MOOSClient("bench_shore", "127.0.0.1", shore_port)
    vehicle = MOOSClient("bench_vehicle", "127.0.0.1", vehicle_port, on_mail=on_mail,
                         on_connect=lambda: vehicle.register("X"))
    tasks = [asyncio.create_task(c.run()) for c in (shore, vehicle)]
    for client in (shore, vehicle):
        if not await client.wait_connected(20.0):
            raise SystemExit(f"bridge_bench: {client.name} could not connect")
    handshake = time.monotonic()
    while not any(tag == "warmup" for tag, _ in arrivals):
        if time.monotonic() - handshake > 60:
            raise SystemExit("bridge_bench: the bridge did not come up within 60 s")
        shore.notify("X_ALL", f"warmup:0:{time.time():.6f}")
        await asyncio.sleep(0.2)
    print(f"bridge up {time.monotonic() - handshake:.1f} s after the clients connected")
    print(f"{'rate':>7} {'sent':>6} {'lost':>6} {'loss%':>6} {'p50 ms':>8} {'p95 ms':>8} {'max ms':>8}")
    for rate in rates:
        sent, lat = await measure(shore, arrivals, rate, seconds, f"r{rate:g}")
        lost = sent - len(lat)
        ms = sorted(x * 1000 for x in lat) or [float("nan")]
        p95 = ms[min(len(ms) - 1, int(0.95 * len(ms)))]
        print(f"{rate:>5g}Hz {sent:>6} {lost:>6} {100 * lost / sent:>6.1f} {statistics.median(ms):>8.2f} "
              f"{p95:>8.2f} {ms[-1]:>8.2f}")
    for client in (shore, vehicle):
        client.close()
    await asyncio.gather(*tasks)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="how long each rate runs (default 10)")
    parser.add_argument("--rates", default="1,10,100", help="comma list of rates in Hz")
    args = parser.parse_args(argv)
    rates = [float(r) for r in args.rates.split(",")]
    launcher = load_launcher()
    with tempfile.TemporaryDirectory(prefix="bridge_bench_") as tmp:
        communities = launcher.plan(1, 1.0, free_pair(socket.SOCK_STREAM), free_pair(socket.SOCK_DGRAM))
        files = launcher.generate(communities, Path(tmp))
        antlers = [subprocess.Popen([sys.executable, "-m", "moosdb_py.antler", "--quiet", f.name, *APPS],
                                    cwd=tmp, start_new_session=True) for f in files]
        try:
            asyncio.run(bench(communities[0].moos_port, communities[1].moos_port, rates, args.seconds))
        finally:
            for proc in antlers:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGTERM)
            for proc in antlers:
                proc.wait(timeout=15)
    return 0


if __name__ == "__main__":
    sys.exit(main())
