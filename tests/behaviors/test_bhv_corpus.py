"""Every .bhv of the mission corpus parses as the helm reads it, with the README's facts."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from behaviors.bhv_file import parse_bhv, read_bhv
from behaviors.flags import FLAG_KINDS
from behaviors.helm import build_behavior
from behaviors.behavior import InfoBuffer
from moosdb_py.source import MissionFileError, SourceLine


def bhv_lines(text: str, name: str = "t.bhv") -> list[SourceLine]:
    return [SourceLine(t, Path(name), i) for i, t in enumerate(text.splitlines(), 1)]


def test_every_corpus_bhv_parses(corpus):
    files = sorted(corpus.glob("*/*.bhv"))
    assert len(files) >= 8
    for f in files:
        assert read_bhv(f).behaviors, f


def test_s1_alpha_facts(corpus, domain):
    bhv = read_bhv(corpus / "s1_alpha" / "alpha.bhv")
    assert [(i.var, i.value) for i in bhv.initializes] == [("DEPLOY", "false"), ("RETURN", "false")]
    assert bhv.modes == []
    assert [(b.type, b.name) for b in bhv.behaviors] == [
        ("BHV_Waypoint", "waypt_survey"), ("BHV_Waypoint", "waypt_return"), ("BHV_ConstantSpeed", "const_speed")]
    survey = bhv.behavior("waypt_survey")
    assert survey.get_all("condition") == ["RETURN = false", "DEPLOY = true"]
    assert survey.get("updates") == "WPT_UPDATE" and survey.get("speed") == "3"
    assert survey.get_all("endflag") == ["RETURN = true", "SUMMARY=speed=$[SPEED],time=$[DUR_RUN_TIME]"]
    wpt = build_behavior(survey, domain, InfoBuffer(), "alpha")
    assert wpt.points.tolist() == [[60, -40], [60, -160], [150, -160], [180, -100], [150, -40]]
    assert (wpt.perpetual, wpt.lead, wpt.lead_damper, wpt.lead_to_start, wpt.capture_line) == (True, 8, 1, True, True)
    assert (wpt.capture_radius, wpt.slip_radius, wpt.speed, wpt.speed_alt, wpt.use_alt_speed) == (5, 15, 3, 1.2, True)
    assert wpt.wptflag_on_start and len(wpt.flags["wptflag"]) == 4 and len(wpt.flags["activeflag"]) == 3
    ret = build_behavior(bhv.behavior("waypt_return"), domain, InfoBuffer(), "alpha")
    assert ret.points.tolist() == [[0, -20]] and (ret.capture_radius, ret.slip_radius) == (2, 8)
    assert [f.var for f in ret.flags["endflag"]] == ["RETURN", "DEPLOY", "MISSION"]
    spd = build_behavior(bhv.behavior("const_speed"), domain, InfoBuffer(), "alpha")
    assert (spd.pwt, spd.duration.limit, spd.duration.reset_var) == (200, 10, "CONST_SPD_RESET")


def test_minicourse_waypoints(corpus, domain):
    bhv = read_bhv(corpus / "minicourse_s2_alpha" / "alpha.bhv")
    assert len(bhv.initializes) == 3
    pts = {b.name: build_behavior(b, domain, InfoBuffer(), "alpha").points.tolist() for b in bhv.behaviors}
    assert len(pts["waypt_survey"]) == 5
    assert pts["west_waypt_survey"] == [[-35, -65], [-35, -125], [20, -125], [20, -65]]
    assert pts["waypt_return"] == [[0, -20]]


def test_station_keep_uuv_modes_and_station(corpus, domain):
    bhv = read_bhv(corpus / "station-keep-uuv" / "davis.bhv")
    assert [(m.value, m.prefix, m.else_value) for m in bhv.modes] == [
        ("ACTIVE", "", "INACTIVE"), ("STATION-KEEPING", "ACTIVE", ""), ("LOITERING", "ACTIVE", ""),
        ("RETURNING", "ACTIVE", "")]
    assert [str(c) for c in bhv.modes[2].conditions] == ["MODE=ACTIVE", "STATION_KEEP=false", "LOITER=true"]
    sk = build_behavior(bhv.behavior("station-keep"), domain, InfoBuffer(), "davis")
    assert sk.static_pt == (20, -20)
    assert (sk.inner, sk.outer, sk.outer_speed, sk.transit_speed, sk.swing_time, sk.hibernation_radius,
            sk.center_activate) == (5, 10, 1.0, 1.3, 7, 25, False)
    assert bhv.behavior("loiter").get("priority") == "100"
    assert bhv.behavior("station_depth").get("duration") == "no-time-limit"


def test_m2_berta_skips_commented_header_block(corpus):
    bhv = read_bhv(corpus / "m2_berta" / "meta_vehicle.bhv")
    assert [b.name for b in bhv.behaviors] == ["loiter", "avdcol_", "waypt_return", "station-keep"]
    assert bhv.behavior("avdcol_").templating == "spawn"
    assert bhv.behavior("station-keep").get("center_activate") == "true"
    assert [m.value for m in bhv.modes] == ["ACTIVE", "STATION-KEEPING", "RETURNING", "LOITERING"]


def test_targ_files_use_start_pos(corpus, domain):
    bhv = read_bhv(corpus / "minicourse_lab_henry_gilda_baseline" / "targ_henry.bhv")
    ret = build_behavior(bhv.behavior("waypt_return"), domain, InfoBuffer(), "henry")
    assert ret.points.tolist() == [[80, 0]]


@pytest.mark.parametrize("text, line, fragment", [
    ("Behavior = BHV_Waypoint\n{\n name = a\n", 3, "unexpected end of file"),
    ("name = x\n", 1, "outside any block"),
    ("set MODE = A {\n DEPLOY == true\n}\n", 2, "not allowed"),
    ("Behavior = BHV_Waypoint\n{\n condition = (A=1) and B=2\n}\n", 3, "condition"),
    ("Behavior = BHV_Waypoint\n{\n endflag = RETURN\n}\n", 3, "VAR = value"),
    ("Behavior = BHV_Waypoint\n name = x\n", 2, "expected '{'"),
    ("Behavior = BHV_Waypoint\n{\n}\nBehavior = BHV_Waypoint\n{\n}\n", 4, "duplicate"),
    ("initialize DEPLOY\n", 1, "bad initialize"),
    ("}\n", 1, "unexpected '}'"),
])
def test_errors_name_file_and_line(text, line, fragment):
    with pytest.raises(MissionFileError) as err:
        parse_bhv(bhv_lines(text))
    assert err.value.line == line and fragment in err.value.message
    assert str(err.value).startswith(f"t.bhv:{line}:")


def test_line_model_details(domain):
    text = ("initialize MSG = \"a,b\", N = 3\ninitialize_ LATE = x\n"
            "Behavior = BHV_Waypoint {\n  points = 1,2 : \\\n 3,4 // two points\n} \n"
            "set MODE = A {\nDEPLOY = true\n}\nELSEWORD\n")
    bhv = parse_bhv(bhv_lines(text))
    assert [(i.var, i.value, i.deferred) for i in bhv.initializes] == [
        ("MSG", "a,b", False), ("N", 3.0, False), ("LATE", "x", True)]
    assert bhv.behaviors[0].get("points") == "1,2 :  3,4"
    assert bhv.modes[0].else_value == "ELSEWORD"
    assert np.array_equal(build_behavior(bhv.behaviors[0], domain, InfoBuffer(), "").points, [[1, 2], [3, 4]])



def nsplugged(path, **defines):
    from moosdb_py.nsplug import preprocess
    return parse_bhv(preprocess(path, defines), path)


def test_ufld_alpha_after_nsplug(corpus, domain):
    bhv = nsplugged(corpus / "ufld_alpha" / "meta_vehicle.bhv", VNAME="abe", START_POS="0,0")
    survey = build_behavior(bhv.behavior("waypt_survey"), domain, InfoBuffer(), "abe")
    assert len(survey.points) == 5 and survey.repeat == 1 and survey.perpetual
    assert survey.updates_var == "WPT_UPDATE"   # `UPDATES = ...` in upper case
    ret = build_behavior(bhv.behavior("waypt_return"), domain, InfoBuffer(), "abe")
    assert ret.points.tolist() == [[0, 0]]


def test_m2_berta_after_nsplug(corpus, domain):
    bhv = nsplugged(corpus / "m2_berta" / "meta_vehicle.bhv", VNAME="abe", START_POS="x=0,y=0,heading=0",
                    STOCK_SPD="1.4", LOITER_POS="0,-50")
    assert bhv.behavior("loiter").get("polygon").startswith("radial:: 0,-50, radius=20")
    assert bhv.behavior("loiter").get("speed") == "1.4"
    sk = build_behavior(bhv.behavior("station-keep"), domain, InfoBuffer(), "abe")
    assert sk.center_activate and (sk.inner, sk.outer) == (5, 10)
    assert [i.var for i in bhv.initializes] == ["DEPLOY", "RETURN", "STATION_KEEP", "LOITER", "AVOID"]


@pytest.mark.parametrize("vname, start", [("henry", "80,0"), ("gilda", "0,0")])
def test_lab_meta_matches_golden_targ(corpus, vname, start):
    folder = corpus / "minicourse_lab_henry_gilda_baseline"
    loiter = "x=125,y=-50" if vname == "henry" else "x=0,y=-75"
    meta = nsplugged(folder / "meta_vehicle.bhv", VNAME=vname, START_POS=start, LOITER_POS=loiter)
    targ = read_bhv(folder / f"targ_{vname}.bhv")

    def facts(b):
        return ([(i.var, i.value) for i in b.initializes], [(m.var, m.value, m.else_value) for m in b.modes],
                [(s.type, [(p.key, " ".join(p.value.split())) for p in s.params]) for s in b.behaviors])
    assert facts(meta) == facts(targ)


def test_unexpanded_nsplug_macros_wait_for_expansion():
    text = "Behavior = BHV_Loiter\n{\n pwt = $(PWT)\n condition = GO_$(VNAME) = true\n name = l_%(VNAME)\n}\n"
    assert parse_bhv(bhv_lines(text)).behaviors[0].get("pwt") == "$(PWT)"
    with pytest.raises(MissionFileError, match="t.bhv:3: pwt: must be a number >= 0"):
        parse_bhv(bhv_lines(text.replace("$(PWT)", "heavy")))


GENERAL_KEYS = {"condition", "pwt", "priority", "priwt", "name", "descriptor", "duration", "perpetual",
                "cycleflag", "wptflag", "spawnx_flag", *FLAG_KINDS}
_word = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=8).filter(
    lambda w: not w[0].isdigit())
_value = st.text(alphabet="abcXYZ0123456789.,:-_ =$[]", min_size=1, max_size=20).map(str.strip).filter(
    lambda v: v and not v.startswith(("{", "}", "//", "#")) and not v.endswith(("{", "\\")) and "//" not in v)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(_word.filter(lambda w: w not in GENERAL_KEYS), _value), max_size=8),
       st.sampled_from(["\t", "  ", ""]))
def test_behavior_block_keeps_every_line_in_order(params, indent):
    body = "\n".join(f"{indent}{k} = {v}" for k, v in params)
    spec = parse_bhv(bhv_lines(f"Behavior = BHV_Anything\n{{\n{body}\n}}\n")).behaviors[0]
    assert [(p.key, p.value) for p in spec.params] == [(k, v) for k, v in params]
    assert [p.line for p in spec.params] == list(range(3, 3 + len(params)))


_bhv_lines = st.lists(st.sampled_from([
    "Behavior = BHV_Waypoint", "Behavior=BHV_X {", "{", "}", "} ELSE", "set MODE = A", "set MODE = B {",
    "initialize A = 1, B = \"x,y\"", "initialize_ C = 2", "name = w", "condition = (A=1) and (B=2)",
    "condition = A = ", "endflag = X = 1 [if] Y < 2", "runflag = NOEQ", "DEPLOY = true", "MODE = A",
    "", "// note", "# note", "pwt = 50", "points = 1,2:3,4 \\", "x = y }", "A=1 and B=2", "!(A = 1)",
]), max_size=14)


@settings(max_examples=80, deadline=None)
@given(_bhv_lines)
def test_any_line_sequence_parses_or_names_its_line(lines):
    try:
        parse_bhv(bhv_lines("\n".join(lines)))
    except MissionFileError as exc:
        assert 0 <= exc.line <= len(lines) and str(exc).startswith(f"t.bhv:{exc.line}: ")
