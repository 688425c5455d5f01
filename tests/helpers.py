"""Shared test helpers: waiting on conditions (never bare sleeps) and reading the conformance captures."""
from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared"
CONFORMANCE = SHARED / "conformance"


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


def conformance_files() -> list[Path]:
    return sorted(CONFORMANCE.glob("*.json"))


def load_capture(path: Path) -> dict:
    return json.loads(path.read_text())
