"""The helm's posts, decisions included, on fixed runs, against digests recorded from the helm as it was
before its iteration was cut down for cost: an exact-equivalence check for any such cut (a fused numpy step
that moves the last bit of a utility can flip a tie and change a decision; a dropped or reordered post
changes the digest too). The summary's timing and clock fields are left out (they vary from run to run).

When a change of behaviour is meant, record the new digests (`fixed_posts_digest` below) and say why in
the commit."""
from __future__ import annotations

import hashlib
import re
from pathlib import Path

from behaviors.bhv_file import parse_bhv, read_bhv
from behaviors.helm import Helm
from moosdb_py.source import SourceLine

from helm_sim import AVOID_MISSION, Boat, head_on, run

_CLOCKS = re.compile(r"(utc_time|(max_)?(create|solve|loop)_time)=[^,]*,?")


def fixed_posts_digest(log: list) -> str:
    """sha256 of every (time, variable, value) posted, floats by repr, the summary without its clocks."""
    digest = hashlib.sha256()
    for t, var, value in log:
        if var == "IVPHELM_SUMMARY":
            value = _CLOCKS.sub("", value)
        digest.update(repr((t, var, value)).encode())
    return digest.hexdigest()


def test_s1_alpha_surveys_and_returns_with_the_recorded_posts(missions, domain):
    helm = Helm([read_bhv(missions / "s1_alpha" / "alpha.bhv")], domain, "alpha", active_start=True)
    helm.startup(0.0)
    helm.on_mail("DEPLOY", "true", 0.0)
    log: list = []
    run(helm, Boat(0, -20, 180), 600, log=log)        # the survey, the return and the station at home
    assert fixed_posts_digest(log) == "5e6587b3051174f73ae689fb58e830b6e46bb560d078f3c01a16630b5f2b9693"


def test_a_head_on_encounter_with_a_spawned_avoidance_gives_the_recorded_posts(domain):
    lines = [SourceLine(t, Path("avoid.bhv"), i) for i, t in enumerate(AVOID_MISSION.splitlines(), 1)]
    helm = Helm([parse_bhv(lines)], domain, "ownship", active_start=True)
    helm.startup(0.0)
    _, _, log = head_on(helm)
    assert fixed_posts_digest(log) == "02dd4e304b73bee1ca91f456999abae6389d682a4a6c23fcaf83d96771936868"


def test_station_keeping_under_a_current_gives_the_recorded_posts(missions, domain):
    helm = Helm([read_bhv(missions / "station_keep" / "station_keep.bhv")], domain, "sk", active_start=True)
    helm.startup(0.0)
    helm.on_mail("DEPLOY", "true", 0.0)
    log: list = []
    run(helm, Boat(0, -20, 180, current=(0.2, -0.1)), 300, log=log)
    assert fixed_posts_digest(log) == "797a7114b494fe31260d988108ee2ec6e2865f86769de0988e43c20b9dff5878"


def test_a_loiter_of_the_lab_polygon_gives_the_recorded_posts(corpus, domain):
    helm = Helm([read_bhv(corpus / "minicourse_lab_henry_gilda_baseline" / "targ_henry.bhv")], domain, "henry",
                active_start=True)
    helm.startup(0.0)
    log: list = []
    run(helm, Boat(80, 0, 180), 400, dt=0.5, log=log)
    assert fixed_posts_digest(log) == "0c318ef2c43f35eee027af33207b7c75f64bff4218e740287970a0caa5d2a95a"
