""".alog writing in pLogger's layout and reading it back (ours and MOOS-IvP's)."""
from datetime import datetime

import pytest
from hypothesis import given, settings, strategies as st

from moosdb_py import alog
from moosdb_py.alog import (AlogFormatError, AlogWriter, alog_header, format_alog_line, format_double,
                            log_root_name, parse_alog_line, read_alog, source_field)
from moosdb_py.message import MOOSMsg

START = 1708009923.123456


def test_line_layout_matches_the_spec_example():
    assert format_alog_line(12.345671, "NAV_X", "uSimMarineV22", "105.23000   ") == \
        "12.34567        NAV_X                uSimMarineV22   105.23000    \n"
    long_source = "pHelmIvP:41:waypt_survey"
    assert format_alog_line(12.50012, "WPT_STAT", long_source, "vname=abe,index=1") == \
        "12.50012        WPT_STAT             pHelmIvP:41:waypt_survey vname=abe,index=1 \n"


def test_header():
    header = alog_header("./LOG_ABE/LOG_ABE.alog", START).splitlines()
    assert header[0] == header[-1] == "%" * 59
    assert header[1] == "%% LOG FILE:       ./LOG_ABE/LOG_ABE.alog"
    assert header[2].startswith("%% FILE OPENED ON  ") and header[2].endswith(str(datetime.now().year))
    assert header[3] == "%% LOGSTART           1708009923.123456"
    assert "%% DATATYPE MARKING ON" in alog_header("x", START, mark_data_type=True)


def test_root_name_with_and_without_timestamp():
    when = datetime(2026, 3, 4, 5, 6, 7)
    assert log_root_name("LOG_ABE", when) == "LOG_ABE_4_3_2026_____05_06_07"
    assert log_root_name("LOG_ABE", when, timestamp=False) == "LOG_ABE"


def test_writer_round_trip_with_aux_externals_and_binary(tmp_path):
    path = tmp_path / "run.alog"
    writer = AlogWriter(path, START, log_aux_src=True, mark_externals=True, community="abe", double_precision=3)
    writer.write(MOOSMsg.notification("NAV_X", 105.23, time=START + 1.5, source="uSim"))
    writer.write(MOOSMsg.notification("WPT_STAT", "a b  c ", time=START + 2, source="pHelmIvP", source_aux="41:wp"))
    ext = MOOSMsg.notification("NODE_REPORT", "NAME=ben", time=START + 3, source="pShare")
    ext.community = "ben"
    writer.write(ext)
    writer.write(MOOSMsg.notification("BLOB", b"\x00\x01\x02", time=START + 4, source="x"))
    writer.write(MOOSMsg.notification("BLOB", b"\xff" * 5, time=START + 5, source="x"))
    writer.close()
    text = path.read_text().splitlines()
    assert text[5] == "1.50000         NAV_X                uSim            105.230      "
    log = read_alog(path)
    assert log.log_start == START
    assert [(e.time, e.key, e.source, e.source_aux, e.community, e.value) for e in log.entries[:3]] == [
        (1.5, "NAV_X", "uSim", "", "", 105.23), (2.0, "WPT_STAT", "pHelmIvP", "41:wp", "", "a b  c "),
        (3.0, "NODE_REPORT", "pShare", "", "ben", "NAME=ben")]
    assert log.values("BLOB") == ["<MOOS_BINARY>File=run.blog,Offset=0,Bytes=3</MOOS_BINARY>",
                                  "<MOOS_BINARY>File=run.blog,Offset=3,Bytes=5</MOOS_BINARY>"]
    assert (tmp_path / "run.blog").read_bytes() == b"\x00\x01\x02" + b"\xff" * 5
    assert log.keys() == {"NAV_X", "WPT_STAT", "NODE_REPORT", "BLOB"} and log.last("BLOB").time == 5.0


def test_data_type_marking_keeps_numeric_strings_strings(tmp_path):
    path = tmp_path / "m.alog"
    writer = AlogWriter(path, START, mark_data_type=True)
    writer.write(MOOSMsg.notification("A", "12", time=START, source="s"))
    writer.write(MOOSMsg.notification("B", 12.0, time=START, source="s"))
    writer.close()
    assert [(e.value, e.is_double) for e in read_alog(path).entries] == [("12", False), (12.0, True)]


def test_reads_a_moos_ivp_style_file(tmp_path):
    path = tmp_path / "real.alog"
    path.write_text("%%%%\n%% LOG FILE:       ./x.alog\n%% FILE OPENED ON  Thu Feb 15 10:12:03 2024\n"
                    "%% LOGSTART           1708009923.12345\n%%%%\n"
                    "0.00100         DB_TIME              MOOSDB_alpha    1708009923.12445 \n"
                    "1.25000         DEPLOY               uPokeDB         true \n"
                    "1.26000         EMPTY                uPokeDB          \n")
    log = read_alog(path)
    assert log.log_start == 1708009923.12345
    assert [(e.key, e.value, e.line) for e in log.entries] == [
        ("DB_TIME", 1708009923.12445, 6), ("DEPLOY", "true", 7), ("EMPTY", "", 8)]


@pytest.mark.parametrize("text,message", [
    ("%% LOGSTART 1\nonly two\n", r"bad.alog:2: expected TIME VAR SOURCE VALUE"),
    ("%% LOGSTART 1\nabc VAR src 1 \n", r"bad.alog:2: time 'abc' is not a number"),
    ("%% LOGSTART soon\n", r"bad.alog:1: LOGSTART 'soon'"),
    ("1.0 VAR src 1\n", r"bad.alog:0: no %% LOGSTART"),
    ("%% LOGSTART 1\n%% DATATYPE MARKING ON\n1.0 VAR src D:abc \n", r"bad.alog:3: 'D:abc' is marked a double"),
])
def test_malformed_files(tmp_path, text, message):
    path = tmp_path / "bad.alog"
    path.write_text(text)
    with pytest.raises(AlogFormatError, match=message):
        read_alog(path)


WORDS = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,25}", fullmatch=True)
STRINGS = st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=40).filter(
    lambda s: not s.startswith(" ") and _not_a_number(s))


def _not_a_number(text):
    try:
        float(text)
    except ValueError:
        return True
    return False


@settings(max_examples=60, deadline=None)
@given(key=WORDS, source=WORDS, aux=st.one_of(st.just(""), WORDS),
       value=st.one_of(st.floats(-1e6, 1e6, allow_nan=False), STRINGS), offset=st.floats(0, 1e5))
def test_round_trip_property(key, source, aux, value, offset):
    msg = MOOSMsg.notification(key, value, time=START + offset, source=source, source_aux=aux)
    writer_line = format_alog_line(msg.time - START, key, f"{source}:{aux}" if aux else source,
                                   format_double(value) if isinstance(value, float) else value)
    entry = parse_alog_line(writer_line)
    assert (entry.key, entry.source, entry.source_aux) == (key, source, aux)
    assert entry.time == pytest.approx(offset, abs=1e-5)
    if isinstance(value, float):
        assert entry.value == pytest.approx(value, abs=1e-5)
    else:
        assert entry.value == value


def test_multi_line_values_read_back_whole(tmp_path):
    """pLogger writes DB_VARSUMMARY's newlines as they are: the value spans lines, the file still reads."""
    summary = ("DB_TIME              12:00:00.100         MOOSDB_#1             1.0 Hz D  1708009923.1\n"
               "DEPLOY               12:00:01.000         uPokeDB               0.0 Hz S  true\n")
    path = tmp_path / "multi.alog"
    writer = AlogWriter(path, START)
    for key, value in [("DB_VARSUMMARY", summary), ("NOTE", "a\n\nb 12 c\nd"), ("NAV_X", 3.0), ("LINES", "1\n2")]:
        writer.write(MOOSMsg.notification(key, value, time=START + 1, source="s"))
    writer.close()
    log = read_alog(path)
    assert [(e.key, e.value) for e in log.entries] == [
        ("DB_VARSUMMARY", summary), ("NOTE", "a\n\nb 12 c\nd"), ("NAV_X", 3.0), ("LINES", "1\n2")]
    assert [e.line for e in log.entries] == [6, 9, 13, 14]


@settings(max_examples=40, deadline=None)
@given(msgs=st.lists(st.tuples(st.sampled_from(["NAV_X", "WPT_STAT", "A_VERY_LONG_VARIABLE_NAME_INDEED"]),
                               st.sampled_from(["uSim", "pHelmIvP", "a_source_longer_than_15"]),
                               st.sampled_from(["", "41:waypt", "42:waypt"]), st.sampled_from(["", "alpha", "bravo"]),
                               st.one_of(st.floats(-1e6, 1e6, allow_nan=False), STRINGS)), max_size=30),
       aux=st.booleans(), externals=st.booleans(), marked=st.booleans(), kept=st.integers(1, 4))
def test_writer_lines_are_format_alog_line_of_each_message(tmp_path_factory, msgs, aux, externals, marked, kept):
    """The writer keeps each writer's VAR/source columns (a few at a time): every line is still the one
    format_alog_line, source_field and format_double give for that message alone."""
    writer = AlogWriter(tmp_path_factory.mktemp("w") / "w.alog", START, log_aux_src=aux, mark_externals=externals,
                        community="alpha", mark_data_type=marked)
    kept_before, alog.COLUMNS_KEPT = alog.COLUMNS_KEPT, kept
    try:
        for key, source, source_aux, community, value in msgs:
            msg = MOOSMsg.notification(key, value, time=START + 1.5, source=source, source_aux=source_aux)
            msg.community = community
            external = externals and community not in ("", "alpha")
            text = format_double(value) if isinstance(value, float) else value
            if marked:
                text = ("D:" if isinstance(value, float) else "S:") + text
            assert writer.line(msg) == format_alog_line(1.5, key, source_field(msg, aux, external), text)
            assert len(writer._columns) <= kept
    finally:
        alog.COLUMNS_KEPT = kept_before
        writer.close()


@settings(max_examples=200, deadline=None)
@given(value=st.floats(allow_nan=True, allow_infinity=True), precision=st.integers(0, 15),
       key=WORDS, source=WORDS)
def test_printf_templates_give_the_format_spec_layout(value, precision, key, source):
    """The templates pLogger formats with lay numbers out as the f-string specs they replace, for any double."""
    assert format_double(value, precision) == f"{value:<12.{precision}f}"
    assert format_alog_line(value, key, source, "v") == f"{value:<15.5f} {key:<20} {source:<15} v \n"
