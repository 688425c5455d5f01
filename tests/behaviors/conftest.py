"""Shared fixtures for the helm tests: the mission corpus and a standard course/speed domain."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # makes `helm_sim` importable in importlib mode

from behaviors.domain import IvPDomain, parse_domain_line

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "missions-corpus"


@pytest.fixture
def corpus() -> Path:
    if not CORPUS.is_dir():
        pytest.skip("shared mission corpus not present")
    return CORPUS


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
