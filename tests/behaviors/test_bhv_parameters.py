"""The declared behaviour parameters: one declaration drives apply(), defaults, moos-lint and the docs."""
from __future__ import annotations

from pathlib import Path

import pytest

from behaviors.behavior import InfoBuffer, IvPBehavior
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.parameters import parameter_table, unique_specs
from behaviors.registry import behavior_types

BUILTIN = {name: cls for name, cls in behavior_types().items() if cls.__module__.startswith("behaviors.")}
DOCS = Path(__file__).resolve().parents[2] / "docs"
DOMAIN = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41"),
                         parse_domain_line("depth:0:100:101")])


def type_tables() -> dict[str, str]:
    tables = {"general": parameter_table(IvPBehavior.parameters)}
    tables.update({cls.type_name: parameter_table(cls.parameters, skip=IvPBehavior.parameters)
                   for cls in BUILTIN.values()})
    return tables


@pytest.mark.parametrize("name", list(type_tables()))
def test_docs_show_the_declared_table(name):
    """docs/*.md hold each type's generated table verbatim; regenerate with
    `python -c "from tests.behaviors.test_bhv_parameters import type_tables; print(type_tables()['<type>'])"`."""
    text = "".join(p.read_text() for p in sorted(DOCS.glob("*.md")))
    assert type_tables()[name] in text, f"docs table for {name} is out of step with its declaration"


@pytest.mark.parametrize("cls", list(BUILTIN.values()), ids=lambda c: c.type_name)
def test_declared_defaults_are_the_real_ones(cls):
    bhv = cls(DOMAIN, InfoBuffer())
    for spec in unique_specs(cls.parameters):
        if spec.attr and spec.default is not None:
            assert getattr(bhv, spec.attr) == spec.parse(spec.default, spec.name), spec.name


@pytest.mark.parametrize("cls", list(BUILTIN.values()), ids=lambda c: c.type_name)
def test_every_declared_name_is_accepted_and_nothing_else(cls):
    for spec in unique_specs(cls.parameters):
        for name in spec.names:
            assert cls.spec_for(name) is spec
    assert cls.spec_for("_pwt") is IvPBehavior.spec_for("pwt")          # a leading _ on general keys
    assert cls.spec_for("no_such_parameter") is None
    with pytest.raises(ValueError, match=f"unknown parameter 'no_such_parameter' for {cls.type_name}"):
        cls(DOMAIN, InfoBuffer()).apply("no_such_parameter", "1")


def test_loiter_takes_only_the_waypoint_parameters_it_shares():
    loiter = BUILTIN["bhv_loiter"]
    assert loiter.spec_for("speed") is BUILTIN["bhv_waypoint"].spec_for("speed")
    assert loiter.spec_for("repeat") is None and loiter.spec_for("points") is None
    assert loiter.spec_for("polygon") is not BUILTIN["bhv_waypoint"].spec_for("polygon")


def test_a_key_dependent_parser_sees_the_alias_used():
    loiter = BUILTIN["bhv_loiter"](DOMAIN, InfoBuffer())
    loiter.apply("polygon", "0,0:0,10:10,10:10,0")
    loiter.apply("xcenter_assign", "100")
    assert loiter.base_polygon.mean(axis=0).tolist() == [100, 5]
