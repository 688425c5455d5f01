"""pMarineViewer under load: 30 vehicles reporting at 4 Hz; WebSocket message rate and page frame time.

    python benchmarks/viewer_bench.py [--vehicles 30] [--hz 4] [--seconds 15]

Starts a real `moosdb` and `pMarineViewer` on free loopback ports, posts NODE_REPORTs for N
vehicles driving circles (one MOOS client, like a shoreside receiving them all), and watches
the page two ways: a plain WebSocket client counts messages, updates and bytes per second,
and a headless Chromium (if installed) loads the page and reports how long each canvas frame
took to draw and how many frames per second it managed. Prints the figures.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import websockets

from moosdb_py.client import MOOSClient
from moosdb_py.ports import free_port

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from browser import Browser, find_chromium  # noqa: E402  (the tests' Chromium driver)

BIN = Path(sys.executable).parent


async def wait_serving(url: str, process: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while True:
        if process.poll() is not None:
            raise RuntimeError(f"pMarineViewer exited with {process.returncode}")
        try:
            async with websockets.connect(url):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)


async def publish(client: MOOSClient, vehicles: int, hz: float, seconds: float) -> int:
    """NODE_REPORTs for `vehicles` boats circling at 2 m/s, each at `hz`; returns how many were posted."""
    posted, start = 0, time.monotonic()
    while (now := time.monotonic() - start) < seconds:
        for i in range(vehicles):
            a = now * 2.0 / 50.0 + i
            x, y = 200 * (i % 6) + 50 * math.cos(a), 200 * (i // 6) + 50 * math.sin(a)
            hdg = (math.degrees(-a) + 360) % 360
            client.notify("NODE_REPORT", f"NAME=v{i:02d},X={x:.2f},Y={y:.2f},SPD=2,HDG={hdg:.1f},"
                                         f"MODE=MODE@ACTIVE:OIL-PATH,LENGTH=4")
            posted += 1
        await asyncio.sleep(max(0.0, posted / vehicles / hz - (time.monotonic() - start)))
    return posted


async def count_messages(url: str, seconds: float) -> dict:
    messages = updates = size = 0
    async with websockets.connect(url, max_size=None) as page:
        await page.recv()  # the snapshot
        start = time.monotonic()
        while (left := seconds - (time.monotonic() - start)) > 0:
            try:
                raw = await asyncio.wait_for(page.recv(), left)
            except TimeoutError:
                break
            messages, size = messages + 1, size + len(raw)
            updates += len(json.loads(raw)["updates"])
    return {"messages_per_s": messages / seconds, "updates_per_s": updates / seconds, "kB_per_s": size / seconds / 1e3}


async def page_figures(url: str, vehicles: int, seconds: float) -> dict:
    async with Browser(1280, 800) as browser:
        await browser.goto(url)
        deadline = time.monotonic() + 20
        while await browser.evaluate("document.querySelectorAll('#vehicles tbody tr').length") < vehicles:
            if time.monotonic() > deadline:
                raise RuntimeError("the page never showed every vehicle")
            await asyncio.sleep(0.1)
        await browser.evaluate("(viewerStats.frameMs = [], viewerStats.batchMs = [], viewerStats.frames = 0,"
                               " viewerStats.messages = 0)")
        await asyncio.sleep(seconds)
        stats = await browser.evaluate("viewerStats")
    frame = sorted(stats["frameMs"])
    return {"frames_per_s": stats["frames"] / seconds, "page_messages_per_s": stats["messages"] / seconds,
            "frame_ms_mean": statistics.fmean(frame), "frame_ms_p95": frame[int(0.95 * (len(frame) - 1))],
            "frame_ms_max": frame[-1], "batch_ms_mean": statistics.fmean(stats["batchMs"])}


async def run(vehicles: int, hz: float, seconds: float) -> dict:
    db_port, http_port = free_port(), free_port()
    folder = Path(tempfile.mkdtemp(prefix="viewer-bench-"))
    db = subprocess.Popen([str(BIN / "moosdb"), "--port", str(db_port)], cwd=folder,
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    viewer = subprocess.Popen([str(BIN / "pMarineViewer"), f"--moos_port={db_port}", f"--http_port={http_port}"],
                              cwd=folder, stdout=subprocess.DEVNULL)
    client = MOOSClient("uBenchFleet", port=db_port)
    comms = asyncio.create_task(client.run())
    url = f"ws://127.0.0.1:{http_port}/ws"
    try:
        await client.wait_connected(20)
        await wait_serving(url, viewer)
        publisher = asyncio.create_task(publish(client, vehicles, hz, seconds + 25))
        await asyncio.sleep(1.0)
        figures = await count_messages(url, seconds)
        if find_chromium():
            figures.update(await page_figures(f"http://127.0.0.1:{http_port}/", vehicles, seconds))
        publisher.cancel()
    finally:
        client.close()
        comms.cancel()
        for process in (viewer, db):
            process.terminate()
            process.wait(10)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=30)
    parser.add_argument("--hz", type=float, default=4.0)
    parser.add_argument("--seconds", type=float, default=15.0)
    args = parser.parse_args()
    figures = asyncio.run(run(args.vehicles, args.hz, args.seconds))
    print(f"pMarineViewer, {args.vehicles} vehicles x {args.hz:g} Hz NODE_REPORT "
          f"({args.vehicles * args.hz:g} reports/s) over {args.seconds:g} s")
    print(f"  WebSocket: {figures['messages_per_s']:.1f} messages/s carrying {figures['updates_per_s']:.0f} "
          f"updates/s ({figures['kB_per_s']:.0f} kB/s)")
    if "frame_ms_mean" in figures:
        print(f"  page (headless Chromium): {figures['frames_per_s']:.1f} frames/s, frame time mean "
              f"{figures['frame_ms_mean']:.2f} ms, p95 {figures['frame_ms_p95']:.2f} ms, max {figures['frame_ms_max']:.2f} ms;\n"
              f"  applying a batch (state + vehicle table) {figures['batch_ms_mean']:.2f} ms mean")
    else:
        print("  page: no chromium on PATH, frame time not measured")


if __name__ == "__main__":
    main()
