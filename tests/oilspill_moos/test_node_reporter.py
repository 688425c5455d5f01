"""pNodeReporter report strings: field order, number format, MODE, INDEX, policies, platform reports."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moosdb_py.formats import FormatError, split_quoted
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.marine.node_reporter import (
    NodeReportBuilder,
    PlatReportInput,
    ReporterParams,
    format_number,
    summary_modes,
)

KAYAK = {"platform_type": "kayak", "platform_color": "yellow", "platform_length": "4"}


def fed(builder, now, **nav):
    for key, value in nav.items():
        builder.on_mail(key, value, now)
    return builder


def test_spec_example_byte_for_byte():
    b = NodeReportBuilder("abe", ReporterParams.from_config(KAYAK))
    fed(b, 1708012345.0, NAV_X=12.514, NAV_Y=-40.2, NAV_SPEED=1.98, NAV_HEADING=181.3, NAV_DEPTH=0.0,
        NAV_LAT=43.82494, NAV_LONG=-70.3302, NAV_YAW=-3.16)
    fed(b, 1708012345.0, IVPHELM_STATE="DRIVE", IVPHELM_ALLSTOP="clear",
        IVPHELM_SUMMARY="iter=66,ofnum=1,warnings=0,modes=MODE@ACTIVE:SURVEYING")
    b.index = 417
    assert b.node_report(1708012345.23) == (
        "NAME=abe,X=12.51,Y=-40.2,SPD=1.98,HDG=181.3,DEP=0,LAT=43.82494,LON=-70.3302,TYPE=kayak,"
        "COLOR=yellow,MODE=MODE@ACTIVE:SURVEYING,ALLSTOP=clear,INDEX=417,YAW=-1.5934856,"
        "TIME=1708012345.23,LENGTH=4")


def test_first_reports_index_and_nohelm():
    b = NodeReportBuilder("alpha", ReporterParams.from_config({}))
    assert b.node_report(10.0) is None  # no nav yet
    fed(b, 10.0, NAV_X=0.0, NAV_Y=-20.0)
    first = b.node_report(10.0)
    assert first == "NAME=alpha,X=0,Y=-20,SPD=0,HDG=0,DEP=0,TYPE=unknown,MODE=NOHELM-EVER,ALLSTOP=unknown,TIME=10"
    assert "INDEX=1," in b.node_report(10.5)
    b.on_mail("IVPHELM_STATE", "PARK", 11.0)
    assert "MODE=PARK," in b.node_report(12.0)
    assert "MODE=NOHELM-7," in b.node_report(18.5)


def test_drive_without_modes_reports_drive():
    b = fed(NodeReportBuilder("a", ReporterParams.from_config({})), 1.0, NAV_X=1.0, NAV_Y=2.0,
            IVPHELM_STATE="DRIVE", IVPHELM_SUMMARY="iter=3,ofnum=0")
    assert ",MODE=DRIVE," in b.node_report(1.0)


def test_terse_and_global_policies():
    grid = LocalGrid(43.8253, -70.3304)
    lat, lon = grid.to_latlon(100.0, -50.0)
    terse = fed(NodeReportBuilder("a", ReporterParams.from_config({"terse_reports": "true"}), grid), 1.0,
                NAV_X=100.0, NAV_Y=-50.0, NAV_LAT=lat, NAV_LONG=lon, NAV_YAW=0.1)
    report = terse.node_report(1.0)
    assert "DEP=" not in report and "LAT=" not in report and "YAW=" not in report and "X=100" in report
    glob = fed(NodeReportBuilder("a", ReporterParams.from_config({"coord_policy_global": "true",
                                                                 "terse_reports": "true"}), grid), 1.0,
               NAV_LAT=lat, NAV_LONG=lon)
    report = glob.node_report(1.0)
    assert "X=" not in report and f"LAT={format_number(lat, 8)}" in report


@pytest.mark.parametrize("policy, expect_x", [("literal", None), ("fill-empty", "100"), ("global", "100")])
def test_crossfill_from_latlon(policy, expect_x):
    grid = LocalGrid(43.8253, -70.3304)
    lat, lon = grid.to_latlon(100.0, -50.0)
    b = fed(NodeReportBuilder("a", ReporterParams.from_config({"crossfill_policy": policy}), grid), 1.0,
            NAV_LAT=lat, NAV_LONG=lon)
    report = b.node_report(1.0)
    if expect_x is None:
        assert ",X=" not in report
    else:
        assert f",X={expect_x},Y=-50," in report


def test_use_latest_prefers_the_newest_source():
    grid = LocalGrid(43.8253, -70.3304)
    lat, lon = grid.to_latlon(10.0, 10.0)
    b = NodeReportBuilder("a", ReporterParams.from_config({"crossfill_policy": "use-latest"}), grid)
    fed(b, 1.0, NAV_X=0.0, NAV_Y=0.0)
    fed(b, 2.0, NAV_LAT=lat, NAV_LONG=lon)
    assert ",X=10,Y=10," in b.node_report(2.0)
    fed(b, 3.0, NAV_X=-5.0, NAV_Y=-5.0)
    pos = b.position()
    assert (pos["x"], pos["y"]) == (-5.0, -5.0) and grid.to_local(pos["lat"], pos["lon"]) == pytest.approx((-5, -5))


def test_optional_fields_in_order():
    params = ReporterParams.from_config({**KAYAK, "group": "blue", "platform_beam": "1.5",
                                         "platform_vsource": "gps"})
    b = fed(NodeReportBuilder("a", params), 1.0, NAV_X=1.0, NAV_Y=1.0, NAV_TRANSP=0.5,
            AUX_MODE="SURVEY", LOAD_WARNING="slow", THRUST_MODE_REVERSE="true", NODE_COLOR_CHANGE="red")
    keys = [f.split("=")[0] for f in b.node_report(1.0).split(",")]
    assert keys == ["NAME", "X", "Y", "SPD", "HDG", "DEP", "TYPE", "COLOR", "GROUP", "VSOURCE", "MODE",
                    "MODE_AUX", "ALLSTOP", "LOAD_WARNING", "THRUST_MODE_REVERSE", "TIME", "TRANSPARENCY",
                    "LENGTH", "BEAM"]


def test_pause_and_blackout():
    b = fed(NodeReportBuilder("a", ReporterParams.from_config({"blackout_interval": "5"})), 0.0,
            NAV_X=0.0, NAV_Y=0.0)
    assert b.node_report(0.0) is not None
    assert b.node_report(4.9) is None
    assert b.node_report(5.0) is not None
    b.on_mail("PNR_PAUSE", "true", 6.0)
    assert b.node_report(20.0) is None


def test_platform_report_gap_and_alias():
    params = ReporterParams.from_config({"plat_report_input": ["BATTERY,gap=10,alias=BATT", "WIFI"]})
    b = NodeReportBuilder("abe", params)
    assert b.platform_report(0.0) is None
    b.on_mail("BATTERY", 12.5, 0.0)
    assert b.platform_report(1.0) == "platform=abe,utc_time=1,BATT=12.5"
    b.on_mail("BATTERY", 12.4, 2.0)
    assert b.platform_report(3.0) is None  # gap not passed
    b.on_mail("WIFI", "up", 3.0)
    assert b.platform_report(4.0) == "platform=abe,utc_time=4,BATT=12.4,WIFI=up"
    assert b.platform_report(11.5) == "platform=abe,utc_time=11.5,BATT=12.4,WIFI=up"
    assert b.platform_report(12.0) is None


@pytest.mark.parametrize("cfg, plat, word", [({"crossfill_policy": "newest"}, [], "crossfill_policy"),
                                              ({"platform_length": "long"}, [], "platform_length"),
                                              ({}, ["gap=3"], "plat_report_input"),
                                              ({}, ["V,gap=x"], "plat_report_input gap")])
def test_bad_config_names_the_parameter(cfg, plat, word):
    with pytest.raises(ValueError, match=word):
        ReporterParams.from_config({**cfg, "plat_report_input": plat})


def test_summary_modes_and_plat_input_parse():
    assert summary_modes("iter=1,modes=MODE@ACTIVE:LOITERING,var=speed:1") == "MODE@ACTIVE:LOITERING"
    assert summary_modes("iter=1") is None
    assert PlatReportInput.parse("X, alias=Y") == PlatReportInput("X", 0.0, "Y")


@given(st.lists(st.sampled_from(["modes", "MODES", "Modes ", "mode", "=", " = ", ",", '"', "iter=3", "@", "x",
                                  "{", "}"])).map("".join))
def test_summary_modes_reads_the_field_whether_or_not_the_word_is_looked_for_first(summary):
    """The look for the word `modes` before splitting changes no answer: the modes field of the split."""
    try:
        fields = [f.partition("=") for f in split_quoted(summary)]
    except FormatError:
        fields = []
    expected = next((value.strip() for key, sep, value in fields if sep and key.lower() == "modes"), None)
    assert summary_modes(summary) == expected


@settings(max_examples=80, deadline=None)
@given(st.floats(-1e6, 1e6, allow_nan=False), st.sampled_from([2, 7, 8]))
def test_format_number_round_trips_within_precision(value, decimals):
    text = format_number(value, decimals)
    assert abs(float(text) - value) <= 0.5 * 10 ** -decimals + 1e-9
    assert not (("." in text) and text.endswith("0")) and not text.endswith(".") and text != "-0"


@pytest.mark.parametrize("word, paused", [("true", True), ("ON", True), ("1", True), ("false", False),
                                          ("off", False), ("0", False), ("maybe", None)])
def test_pause_and_reverse_mail_are_moos_booleans(word, paused):
    """PNR_PAUSE and THRUST_MODE_REVERSE read booleans by the one rule (moosdb_py.formats); a word that is
    no boolean leaves the setting alone, as the C++ app's setBooleanOnString does."""
    for before in (False, True):
        b = NodeReportBuilder("a", ReporterParams.from_config({"paused": str(before).lower()}))
        b.thrust_mode_reverse = before
        fed(b, 1.0, PNR_PAUSE=word, THRUST_MODE_REVERSE=word)
        expected = before if paused is None else paused
        assert (b.paused, b.thrust_mode_reverse) == (expected, expected)
