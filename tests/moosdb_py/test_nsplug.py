"""nsplug preprocessor: golden outputs from the corpus, the spec's rules and quirks, and errors."""
import pytest
from hypothesis import given, settings, strategies as st

from moosdb_py.nsplug import main as nsplug_main
from moosdb_py.nsplug import parse_defines, preprocess
from moosdb_py.source import MissionFileError

from helpers import CORPUS, requires_shared

BASELINE = CORPUS / "minicourse_lab_henry_gilda_baseline"
VEHICLE = dict(WARP="10", SHORE_IP="localhost", SHORE_PSHARE="9200", IP_ADDR="localhost", VTYPE="kayak")


def expand(tmp_path, text, defines=None, name="meta.moos", **kw):
    path = tmp_path / name
    path.write_text(text)
    return [line.text for line in preprocess(path, defines, **kw)]


def body(lines):
    """The lines without the empty one nsplug adds at the end of every file."""
    return [line for line in lines if line.strip()]


@pytest.mark.parametrize("meta,target,defines", [
    ("meta_vehicle.moos", "targ_gilda.moos", dict(VEHICLE, VNAME="gilda", START_POS="0,0", VPORT="9001", PSHARE_PORT="9201")),
    ("meta_vehicle.moos", "targ_henry.moos", dict(VEHICLE, VNAME="henry", START_POS="80,0", VPORT="9002", PSHARE_PORT="9202")),
    ("meta_shoreside.moos", "targ_shoreside.moos", dict(WARP="10", VNAME="shoreside", PSHARE_PORT="9200", VPORT="9000", IP_ADDR="localhost")),
    ("meta_vehicle.bhv", "targ_gilda.bhv", dict(VNAME="gilda", START_POS="0,0", LOITER_POS="x=0,y=-75")),
    ("meta_vehicle.bhv", "targ_henry.bhv", dict(VNAME="henry", START_POS="80,0", LOITER_POS="x=125,y=-50")),
])
@requires_shared("missions-corpus")
def test_matches_real_nsplug_output_byte_for_byte(meta, target, defines, monkeypatch):
    # The targ files were made with WARP=10 (the README table says 1; the committed outputs say 10).
    monkeypatch.chdir(BASELINE)
    lines = preprocess(meta, defines)
    assert "".join(line.text + "\n" for line in lines) == (BASELINE / target).read_text(encoding="latin-1")


def test_spec_worked_example(tmp_path):
    text = """#define SPEED 2
ServerPort = $(PORT=9000)
#ifdef VNAME abe
  LatOrigin = 42.0
#elseifdef VNAME ben
  LatOrigin = 43.0
#else
  LatOrigin = 44.0
#endif
Community = %(VNAME)
cruise = $(SPEED) knots, $(UNDEFINED)
"""
    assert body(expand(tmp_path, text, {"VNAME": "ben"})) == [
        "ServerPort = 9000", "  LatOrigin = 43.0", "Community = BEN", "cruise = $(SPEED) knots, $(UNDEFINED)"]


@pytest.mark.parametrize("defines,plain,colon", [
    ({}, "dflt", "dflt"),                      # undefined: both forms give the default
    ({"N": "v"}, "v", "v"),                    # non-empty: both give the value
    ({"N": ""}, "", "dflt"),                   # defined empty: only := falls back
    ({"N": None}, "", "dflt"),                 # defined bare: the same
])
def test_default_forms(tmp_path, defines, plain, colon):
    assert body(expand(tmp_path, "a=[$(N=dflt)] b=[$(N:=dflt)]\n", defines)) == [f"a=[{plain}] b=[{colon}]"]


def test_defaults_may_hold_equals_signs(tmp_path):
    assert body(expand(tmp_path, "a = $(POS=x=1,y=2) $(P2:=h:=3)\n")) == ["a = x=1,y=2 h:=3"]


def test_upper_case_form_upper_cases_defaults_too(tmp_path):
    assert body(expand(tmp_path, "File = LOG_%(VNAME)_%(X:=low)\n", {"VNAME": "abe"})) == ["File = LOG_ABE_LOW"]


def test_values_may_hold_macros_and_defines_override(tmp_path):
    text = "#define A $(B)x\n#define B 1\n#define B 2\nv = $(A)\n"
    assert body(expand(tmp_path, text)) == ["v = 2x"]


def test_bare_defines_expand_empty_and_count_for_ifdef(tmp_path):
    text = "#define FLAG\n#ifdef FLAG\nyes = [$(FLAG)]\n#endif\n#ifdef EMPTY\nno = 1\n#endif\n"
    assert body(expand(tmp_path, text, {"EMPTY": ""})) == ["yes = []"]


@pytest.mark.parametrize("condition,defines,expected", [
    ("XMODE SIM", {"XMODE": "SIM"}, True),
    ("XMODE SIM", {"XMODE": "M300"}, False),
    ("XMODE SIM", {}, False),
    ("XMODE OTHER", {"XMODE": "SIM", "OTHER": "SIM"}, True),     # compare with another macro's value
    ("A 1 || B 2", {"B": "2"}, True),
    ("A 1 || B 2", {"B": "3"}, False),
    ("A 1 && B 2", {"A": "1", "B": "2"}, True),
    ("A 1 && B 2", {"A": "1", "B": "3"}, False),
    ("A && B 2", {"A": "", "B": "2"}, True),                     # bare clause in && only needs "defined"
    ("A x && B 2", {"B": "2"}, True),                            # QUIRK: undefined A vs undefined x
    ("A 1 || B 2 && C 3", {"A": "1", "B": "2", "C": "3"}, False),  # mixing is false
])
def test_ifdef_clauses(tmp_path, condition, defines, expected):
    text = f"#ifdef {condition}\nyes\n#else\nno\n#endif\n"
    assert body(expand(tmp_path, text, defines)) == (["yes"] if expected else ["no"])


def test_mixing_or_and_is_an_error_when_strict(tmp_path):
    with pytest.raises(MissionFileError, match=r"meta.moos:1: .*mixes"):
        expand(tmp_path, "#ifdef A 1 || B 2 && C 3\n#endif\n", strict=True)


def test_ifndef_and_nesting(tmp_path):
    text = """#ifndef A B
none
#ifdef C
  c
#else
  not-c
#endif
#else
#ifdef C
some-c
#endif
#endif
"""
    assert body(expand(tmp_path, text, {"C": "1"})) == ["none", "  c"]
    assert body(expand(tmp_path, text, {"B": "1"})) == []
    assert body(expand(tmp_path, text, {"B": "1", "C": "1"})) == ["some-c"]


@requires_shared("missions-corpus")
def test_tagged_include_drops_its_directives(monkeypatch):
    """spec 3.6: both branches of plugs.moos <origin_warp> reach the output, pavlab first."""
    monkeypatch.chdir(CORPUS / "ufld_alpha")
    text = [line.text for line in preprocess("meta_vehicle.moos", {"WARP": "1", "VNAME": "abe"})]
    origins = [t.split("=")[1].strip() for t in text if t.startswith("LatOrigin")]
    assert origins == ["42.358436", "43.825300"]
    assert not any(t.lstrip().startswith("#") for t in text)


def test_include_lines_name_their_own_file(tmp_path):
    (tmp_path / "inc").mkdir()
    (tmp_path / "inc" / "part.moos").write_text("<tag><a>\nfrom_a = $(X)\n<tag><b>\nfrom_b = 1\n")
    (tmp_path / "main.moos").write_text("top = 1\n#include part.moos <a>\n#include \"part.moos\"\n")
    lines = preprocess(tmp_path / "main.moos", {"X": "7"}, include_paths=[tmp_path / "inc"])
    texts = [(line.text, line.file.name, line.line) for line in lines if line.text]
    assert texts == [("top = 1", "main.moos", 1), ("from_a = 7", "part.moos", 2),
                     ("from_a = 7", "part.moos", 2), ("from_b = 1", "part.moos", 4)]


def test_defines_inside_an_include_are_visible_after_it(tmp_path):
    (tmp_path / "defs.moos").write_text("#define SPEED 3\n")
    assert body(expand(tmp_path, "#include defs.moos\nspeed = $(SPEED)\n")) == ["speed = 3"]


def test_include_file_name_is_expanded(tmp_path):
    (tmp_path / "plug_abe.moos").write_text("x = 1\n")
    assert body(expand(tmp_path, "#include plug_$(V).moos\n", {"V": "abe"})) == ["x = 1"]


def test_strict_mode_rejects_unexpanded_macros_except_in_comments(tmp_path):
    assert body(expand(tmp_path, "// note $(X)\n", strict=True)) == ["// note $(X)"]
    with pytest.raises(MissionFileError, match=r"meta.moos:2: unexpanded macro"):
        expand(tmp_path, "ok = 1\nport = $(PORT)\n", strict=True)


def test_helm_macros_pass_through_untouched(tmp_path):
    text = "wptflag = PREV=$(PX),$(PY) v=$(VNAME)\nflag = $[X] $(VNAME)\n"
    assert body(expand(tmp_path, text, {"VNAME": "abe"}, name="meta.bhv")) == [
        "wptflag = PREV=$(PX),$(PY) v=$(VNAME)", "flag = $[X] abe"]


@pytest.mark.parametrize("text,message", [
    ("a = 1\n#include nothere.moos\n", r"meta.moos:2: #include file 'nothere.moos' not found"),
    ("#include\n", r"meta.moos:1: #include expects a file name"),
    ("#inclde plugs.moos\n", r"meta.moos:1: unknown nsplug directive '#inclde' \(did you mean #include\?\)"),
    ("x\n#else\n", r"meta.moos:2: #else without #ifdef"),
    ("#endif\n", r"meta.moos:1: #endif without #ifdef"),
    ("a\n#ifdef A\nb\n", r"meta.moos:2: #ifdef/#ifndef without matching #endif"),
    ("#ifdef\n#endif\n", r"meta.moos:1: #ifdef needs a macro name"),
    ("#include meta.moos\n", r"meta.moos:1: include loop: meta.moos -> meta.moos"),
])
def test_errors_name_file_and_line(tmp_path, text, message):
    with pytest.raises(MissionFileError, match=message):
        expand(tmp_path, text)


def test_top_level_tag_like_nsplug_tag_switch(tmp_path):
    path = tmp_path / "plugs.moos"
    path.write_text("top = 0\n<tag><a>\nfrom_a = $(X)\n#ifdef X\n<tag><b>\nfrom_b = 1\n")
    assert [line.text for line in preprocess(path, {"X": "7"}, tag="a")] == ["from_a = 7"]


def test_a_tag_the_file_lacks_inserts_nothing(tmp_path):
    (tmp_path / "plugs.moos").write_text("<tag><a>\nx = 1\n")
    assert body(expand(tmp_path, "#include plugs.moos <b>\ny = 2\n")) == ["y = 2"]


def test_hash_comments_in_bhv_pass_through(tmp_path):
    assert body(expand(tmp_path, "# a comment\n#----\n", name="x.bhv")) == ["# a comment", "#----"]


def test_parse_defines():
    assert parse_defines(["A=1", "B", "C=", "D=x=y"]) == {"A": "1", "B": None, "C": "", "D": "x=y"}
    with pytest.raises(ValueError, match="=oops"):
        parse_defines(["=oops"])


NAMES = st.from_regex(r"[A-Z][A-Z0-9_]{0,8}", fullmatch=True)
VALUES = st.text(st.characters(whitelist_categories=("L", "N"), whitelist_characters=" ,.:=-_", max_codepoint=127),
                 max_size=12)


@settings(max_examples=60, deadline=None)
@given(macros=st.dictionaries(NAMES, VALUES, min_size=1, max_size=4), prefix=VALUES)
def test_substitution_property(tmp_path_factory, macros, prefix):
    tmp_path = tmp_path_factory.mktemp("subst")
    text = prefix + " " + " ".join(f"$({n})|%({n})" for n in macros) + "\n"
    expected = prefix + " " + " ".join(f"{v}|{v.upper()}" for v in macros.values())
    assert expand(tmp_path, text, macros)[0] == expected


@settings(max_examples=40, deadline=None)
@given(defined=st.lists(st.booleans(), min_size=1, max_size=4))
def test_exactly_one_branch_property(tmp_path_factory, defined):
    """#ifdef / #elseifdef... / #else emits exactly the first branch whose macro is set, else the #else."""
    tmp_path = tmp_path_factory.mktemp("branch")
    lines = []
    for i in range(len(defined)):
        lines += [f"#{'ifdef' if i == 0 else 'elseifdef'} M{i}", f"branch{i}"]
    text = "\n".join(lines + ["#else", "fallback", "#endif"]) + "\n"
    defines = {f"M{i}": "1" for i, on in enumerate(defined) if on}
    first = next((f"branch{i}" for i, on in enumerate(defined) if on), "fallback")
    assert body(expand(tmp_path, text, defines)) == [first]


PLAIN_LINES = st.lists(st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=30).filter(
    lambda t: "$(" not in t and "%(" not in t and "<tag>" not in t and not t.lstrip().startswith("#")), max_size=8)


@settings(max_examples=50, deadline=None)
@given(before=PLAIN_LINES, included=PLAIN_LINES, after=PLAIN_LINES)
def test_plain_text_passes_through_and_includes_are_transparent(tmp_path_factory, before, included, after):
    tmp_path = tmp_path_factory.mktemp("plain")
    (tmp_path / "part.moos").write_text("".join(line + "\n" for line in included))
    lines = expand(tmp_path, "".join(line + "\n" for line in [*before, "#include part.moos", *after]))
    assert lines == [*before, *included, "", *after, ""]   # nsplug's empty line at the end of each file


def test_command_line_like_nsplug(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "inc").mkdir()
    (tmp_path / "inc" / "plug.moos").write_text("MOOSTimeWarp = $(WARP)\n")
    (tmp_path / "meta.moos").write_text("Community = $(VNAME)\n#include plug.moos\nx = $(NOPE) $(VNAME)\n")
    (tmp_path / "macros.txt").write_text("# launch defaults\nWARP=10\n// more\nVNAME=zed\n")
    assert nsplug_main(["meta.moos", "targ.moos", "--path=inc", "--macros=macros.txt", "VNAME=abe"]) == 0
    assert (tmp_path / "targ.moos").read_text() == "Community = abe\nMOOSTimeWarp = 10\n\nx = $(NOPE) $(VNAME)\n\n"
    assert nsplug_main(["meta.moos", "targ.moos", "--path=inc", "VNAME=abe"]) == 1   # exists, no -f
    assert "not overwritten (use -f)" in capsys.readouterr().err
    assert nsplug_main(["meta.moos", "-t", "-l", "-p", "inc", "VNAME=abe", "WARP=2"]) == 0
    assert capsys.readouterr().out == "Community = abe\nMOOSTimeWarp = 2\n\nx = $(NOPE) abe\n\n"
    assert nsplug_main(["meta.moos", "targ.moos", "-f", "-s", "--path=inc", "VNAME=abe", "WARP=2"]) == 1
    assert f"nsplug: meta.moos:3: unexpanded macro in: x = $(NOPE) abe" in capsys.readouterr().err
