"""Fixtures shared by every test package: a real `moosdb` process on a free loopback port."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # makes `helpers` importable in importlib mode

from helpers import wait_until  # noqa: E402


def free_port() -> int:
    """An ephemeral loopback port that is free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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


@pytest.fixture(name="free_port")
def free_port_fixture():
    """Call it for a fresh free port: `port = free_port()`."""
    return free_port


@pytest.fixture
def moosdb_server():
    """A real moosdb process on a free loopback port; has .host and .port."""
    db = start_moosdb()
    yield db
    db.stop()
