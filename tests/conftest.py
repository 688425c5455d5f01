"""Fixtures shared by every test package: a real `moosdb` process on a free loopback port."""
from __future__ import annotations

import pytest

from helpers import free_port, start_moosdb


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
