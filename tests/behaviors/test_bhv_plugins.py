"""Behaviours as plug-ins: a package that is not this project adds a behaviour type through the
`behaviors.bhv` entry-point group, and a .bhv file names it with no edit of the helm."""
from __future__ import annotations

import sys
import textwrap

import pytest

from behaviors import registry
from behaviors.helm import Helm
from behaviors.registry import behavior_class, known_type_names
from moosdb_py.source import MissionFileError

from helm_sim import Boat, run

PLUGIN = '''
"""A third-party behaviour: hold the heading that points at a beacon."""
import numpy as np

from behaviors.behavior import IvPBehavior
from behaviors.geometry import bearing
from behaviors.ivp_function import IvPFunction
from behaviors.parameters import NON_NEGATIVE, attr
from behaviors.zaic import PeakComponent, zaic_peak


class BHV_Beacon(IvPBehavior):
    type_name = "BHV_Beacon"
    default_name = "beacon"
    info_vars = ("NAV_X", "NAV_Y")
    domain_vars = ("course",)
    params = (attr("beacon_x", "beacon_x", NON_NEGATIVE, "0", "beacon east"),
              attr("beacon_y", "beacon_y", NON_NEGATIVE, "0", "beacon north"))

    def on_run_state(self):
        nav = self.nav()
        if nav is None:
            return None
        to_beacon = float(bearing(nav[0], nav[1], self.beacon_x, self.beacon_y))
        self.post("BEACON_BEARING", round(to_beacon, 1))
        var = self.domain.var("course")
        return IvPFunction(("course",), zaic_peak(var, [PeakComponent(to_beacon, 0, 90)], value_wrap=True), self.pwt)


class NotABehavior:
    pass
'''


@pytest.fixture
def plugin_package(tmp_path, monkeypatch):
    """A package installed the way pip leaves one: its module and a dist-info with entry_points.txt."""
    (tmp_path / "beacon_bhv.py").write_text(PLUGIN)
    info = tmp_path / "beacon_bhv-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: beacon-bhv\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(textwrap.dedent("""\
        [behaviors.bhv]
        BHV_Beacon = beacon_bhv:BHV_Beacon
        BHV_Broken = beacon_bhv:NotABehavior
        BHV_Missing = beacon_bhv_absent:Nothing
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("beacon_bhv", None)
    for name in ("bhv_beacon", "bhv_broken", "bhv_missing"):
        registry._loaded.pop(name, None)        # the helm keeps loaded classes; this package goes away


def test_without_the_package_the_type_is_unknown(make_bhv, domain):
    assert behavior_class("BHV_Beacon") is None and "BHV_Waypoint" in known_type_names()
    with pytest.raises(MissionFileError, match=r"t.bhv:1: unknown behavior type 'BHV_Beacon' \(this helm has "):
        Helm([make_bhv("Behavior = BHV_Beacon\n{\n beacon_x = 10\n}\n")], domain, "abe")


def test_a_plugin_behaviour_is_named_configured_and_run(plugin_package, make_bhv, domain):
    assert "BHV_Beacon" in known_type_names()
    bhv = make_bhv("Behavior = bhv_beacon\n{\n beacon_x = 100\n beacon_y = 100\n pwt = 50\n}\n"
                   "Behavior = BHV_ConstantSpeed\n{\n speed = 1\n duration = no-time-limit\n}\n")
    assert bhv.behaviors[0].name == "beacon"              # the plug-in's default name
    helm = Helm([bhv], domain, "abe", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(0, 0, 0), 3, log=log)
    assert [val for _, v, val in log if v == "BEACON_BEARING"][0] == 45        # from 0,0 before moving
    assert [val for _, v, val in log if v == "DESIRED_HEADING"][-1] == 45
    with pytest.raises(MissionFileError, match=r"t.bhv:3: bhv_beacon 'beacon': beacon_x must be a number >= 0"):
        Helm([make_bhv("Behavior = bhv_beacon\n{\n beacon_x = east\n}\n")], domain, "abe")


@pytest.mark.parametrize("name, message", [
    ("BHV_Broken", r"behaviour plug-in 'BHV_Broken' \(beacon_bhv:NotABehavior\) is not an IvPBehavior subclass"),
    ("BHV_Missing", r"behaviour plug-in 'BHV_Missing' \(beacon_bhv_absent:Nothing\) does not load: No module"),
])
def test_a_bad_plugin_is_a_clear_error_naming_it(plugin_package, make_bhv, domain, name, message):
    with pytest.raises(MissionFileError, match=f"t.bhv:1: {message}"):
        Helm([make_bhv(f"Behavior = {name}\n{{\n}}\n")], domain, "abe")
    types = registry.behavior_types()                # the others still load
    assert name.lower() not in types and types["bhv_beacon"].type_name == "BHV_Beacon"
