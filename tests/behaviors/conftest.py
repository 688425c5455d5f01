"""Shared fixtures for the helm tests: the mission corpus and a standard course/speed domain."""
from pathlib import Path

import pytest

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
