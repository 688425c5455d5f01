"""Fixtures shared by every test package: a real `moosdb` process on a free loopback port; hypothesis
without its per-example deadline (speed is measured in benchmarks/, and CI machines are loaded)."""
from __future__ import annotations

import pytest
from hypothesis import settings

from helpers import free_port, start_moosdb

settings.register_profile("oilspill-moos", deadline=None)
settings.load_profile("oilspill-moos")


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
