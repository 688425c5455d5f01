"""Shared fixtures for the helm tests: the mission corpus, the repo's missions and a standard course/speed domain."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # makes `helm_sim` importable in importlib mode

from behaviors.domain import IvPDomain, parse_domain_line
from helpers import CORPUS, shared_missing
from mission_run import MISSIONS


@pytest.fixture
def corpus() -> Path:
    """../shared/missions-corpus (the real MOOS-IvP files); the test skips without it."""
    if reason := shared_missing("missions-corpus"):
        pytest.skip(reason)
    return CORPUS


@pytest.fixture
def missions() -> Path:
    """The repo's own missions/ (s1_alpha, station_keep, ...): always present."""
    return MISSIONS


@pytest.fixture
def domain() -> IvPDomain:
    return IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])


@pytest.fixture
def make_bhv():
    """Parse .bhv text given inline (file name t.bhv)."""
    from moosdb_py.source import SourceLine
    from behaviors.bhv_file import parse_bhv

    def make(text: str):
        return parse_bhv([SourceLine(t, Path("t.bhv"), i) for i, t in enumerate(text.splitlines(), 1)])
    return make
