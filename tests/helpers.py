"""Shared test helpers: waiting on conditions (never bare sleeps), the conformance captures, and the
`requires_shared` marker for tests that read what stays outside the repo."""
from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from collections.abc import Callable
from pathlib import Path

import pytest

from moosdb_py.ports import free_port  # the product's (the demo uses it too); conftest re-exports it

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared"
# What ../shared holds that the repo may not (not ours to redistribute); tests reading it skip without it.
SHARED_PARTS = {"missions-corpus": "the MOOS-IvP mission corpus",
                "data/dwh": "the NOAA/ERMA Deepwater Horizon composites"}
CORPUS = SHARED / "missions-corpus"
DWH = SHARED / "data" / "dwh"
# The C++ MOOS byte captures ship with the repo (tests/data/README.md says where they came from).
CONFORMANCE = Path(__file__).resolve().parent / "data" / "conformance"


def _check(predicate: Callable[[], object], deadline: float, timeout: float):
    result = predicate()
    if not result and time.monotonic() > deadline:
        raise AssertionError(f"condition not met within {timeout} s: {getattr(predicate, '__name__', predicate)}")
    return result


def wait_until(predicate: Callable[[], object], timeout: float = 5.0, interval: float = 0.01):
    """Poll `predicate` until it returns something truthy; return that, or fail after `timeout` s."""
    deadline = time.monotonic() + timeout
    while not (result := _check(predicate, deadline, timeout)):
        time.sleep(interval)
    return result


async def async_wait_until(predicate: Callable[[], object], timeout: float = 5.0, interval: float = 0.005):
    """`wait_until` for code running inside an event loop."""
    deadline = time.monotonic() + timeout
    while not (result := _check(predicate, deadline, timeout)):
        await asyncio.sleep(interval)
    return result


def shared_missing(part: str) -> str | None:
    """The skip reason when ../shared/<part> is absent (a clone with nothing beside it), else None."""
    if (SHARED / part).exists():
        return None
    return f"needs ../shared/{part}: {SHARED_PARTS[part]}, kept outside the repo (not ours to redistribute)"


def requires_shared(part: str) -> pytest.MarkDecorator:
    """Mark a test (or a module, as `pytestmark`) that reads ../shared/<part>: it skips with one reason."""
    reason = shared_missing(part)
    return pytest.mark.skipif(reason is not None, reason=reason or "")


def conformance_files() -> list[Path]:
    return sorted(CONFORMANCE.glob("*.json"))


def load_capture(path: Path) -> dict:
    return json.loads(path.read_text())


@dataclass
class DBProcess:
    host: str
    port: int
    process: subprocess.Popen

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def _accepting(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False


def one_app_mission(path: Path, port: int, community: str, app: str, block: str, warp: float = 10) -> Path:
    """A .moos file for one app against a test DB: its address, community, time warp and `app`'s block
    (`block` is the lines inside the braces)."""
    path.write_text(f"ServerHost = localhost\nServerPort = {port}\nCommunity = {community}\nMOOSTimeWarp = {warp:g}\n\n"
                    f"ProcessConfig = {app}\n{{\n{block}}}\n")
    return path


def start_moosdb(*args: str, port: int | None = None) -> DBProcess:
    """Start `python -m moosdb_py.moosdb` and wait until it accepts connections."""
    port = port or free_port()
    proc = subprocess.Popen([sys.executable, "-m", "moosdb_py.moosdb", "--port", str(port), *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    db = DBProcess("127.0.0.1", port, proc)
    try:
        wait_until(lambda: proc.poll() is not None or _accepting(db.host, port), timeout=10)
    except AssertionError:
        db.stop()
        raise
    if proc.poll() is not None:
        raise RuntimeError(f"moosdb exited: {proc.stderr.read().decode(errors='replace')}")
    return db
