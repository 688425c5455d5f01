"""Parameters real missions use that the helm once rejected: the constant behaviours' mismatch
variables and complete_thresh, pHelmIvP's pmgen and MaxAppTick, and term_report_interval, which the
C++ helm only warns about."""
from __future__ import annotations

import pytest

from behaviors.behavior import InfoBuffer
from behaviors.bhv_constant_depth import BHV_ConstantDepth
from behaviors.bhv_constant_heading import BHV_ConstantHeading
from behaviors.bhv_constant_speed import BHV_ConstantSpeed
from behaviors.domain import IvPDomain, parse_domain_line

from test_helm_audit import helm_app

DOMAIN = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41"),
                         parse_domain_line("depth:0:100:101")])


def running(cls, nav: dict, **params):
    info = InfoBuffer()
    bhv = cls(DOMAIN, info, "abe")
    for key, value in {"duration": "no-time-limit", **params}.items():
        bhv.apply(key, str(value))
    for var, value in nav.items():
        info.set(var, value, 0.0)
    return bhv


@pytest.mark.parametrize("nav_heading, desired, mismatch", [(350, 10, 20), (10, 350, 20), (90, 270, 180),
                                                             (45, 40, 5)])
def test_heading_mismatch_is_the_smaller_angle(nav_heading, desired, mismatch):
    bhv = running(BHV_ConstantHeading, {"NAV_HEADING": float(nav_heading)}, heading=desired,
                  heading_mismatch_var="HDG_ERR")
    assert bhv.tick(1.0) is not None
    assert {p.var: p.value for p in bhv.take_posts()}["HDG_ERR"] == mismatch


def test_complete_thresh_completes_once_on_heading():
    bhv = running(BHV_ConstantHeading, {"NAV_HEADING": 12.0}, heading=10, complete_thresh=3,
                  heading_mismatch_var="HDG_ERR", endflag="TURNED = true")
    assert bhv.tick(1.0) is None and bhv.state == "completed"                  # 2 degrees off: within 3
    posts = {p.var: p.value for p in bhv.take_posts()}
    assert (posts["HDG_ERR"], posts["TURNED"]) == (2.0, "true")
    far = running(BHV_ConstantHeading, {"NAV_HEADING": 20.0}, heading=10, complete_thresh=3)
    assert far.tick(1.0) is not None and far.state == "active"
    never = running(BHV_ConstantHeading, {"NAV_HEADING": 10.0}, heading=10)    # default 0: never completes
    assert never.tick(1.0) is not None


def test_depth_and_speed_mismatch():
    depth = running(BHV_ConstantDepth, {"NAV_DEPTH": 7.5}, depth=10, depth_mismatch_var="DEP_ERR")
    depth.tick(1.0)
    assert {p.var: p.value for p in depth.take_posts()}["DEP_ERR"] == 2.5
    speed = running(BHV_ConstantSpeed, {"NAV_SPEED": 1.2}, speed=2, speed_mismatch_var="SPD_ERR")
    speed.tick(1.0)
    assert {p.var: p.value for p in speed.take_posts()}["SPD_ERR"] == 0.8
    quiet = running(BHV_ConstantDepth, {}, depth=10, depth_mismatch_var="DEP_ERR")     # no NAV_DEPTH: no post
    quiet.tick(1.0)
    assert "DEP_ERR" not in {p.var for p in quiet.take_posts()}
    with pytest.raises(ValueError, match="without blanks"):
        running(BHV_ConstantDepth, {}, depth_mismatch_var="DEP ERR")


def test_pmgen_and_max_app_tick_are_pHelmIvP_keys(tmp_path, capsys):
    app, _ = helm_app(tmp_path, "  MaxAppTick = 10\n  pmgen = turn_rate=20, max_speed=3\n")
    assert app.helm.status == "PARK" and app.helm.config_warnings == []
    (tmp_path / "b").mkdir()
    bad, moos = helm_app(tmp_path / "b", "  pmgen = turn_rate\n")
    assert bad.helm.status == "MALCONFIG"
    assert f"{moos}:13: pmgen must be a key=value list" in capsys.readouterr().err


def test_term_report_interval_is_only_a_warning(tmp_path, capsys):
    app, moos = helm_app(tmp_path, "  term_report_interval = 0.8\n")
    assert app.helm.status == "PARK" and app.helm.config_warnings == []
    assert f"warning: {moos}:13: pHelmIvP ignores 'term_report_interval'" in capsys.readouterr().err
