"""The feedback apps driven by hand (no MOOSDB): pOilSampler's rate, phases and stray answers,
uFldOilFusion's rejections and feedback file, uFldOilSensor's replies, clock command and config."""
import json

import pytest

from moosdb_py.message import MOOSMsg
from oilspill_moos.response.oil_fusion import OilFusion
from oilspill_moos.response.oil_sampler import OilSampler
from oilspill_moos.response.oil_sensor import OilSensor

MISSION = """\
ServerPort = 9000
Community  = {community}
MOOSTimeWarp = 1
LatOrigin  = 28.736667
LongOrigin = -88.387222

ProcessConfig = {app}
{{
{body}
}}
"""


def make(cls, tmp_path, community="abe", **params):
    path = tmp_path / "m.moos"
    path.write_text(MISSION.format(community=community, app=cls.default_name,
                                   body="\n".join(f"  {k} = {v}" for k, v in params.items())))
    app = cls(path)
    app.posts = []
    app.notify = lambda key, value, time=None, source_aux="": app.posts.append((key, value))
    app.clock = 1000.0
    app.moos_time = lambda: app.clock
    app.on_startup()
    return app


def mail(*pairs):
    return [MOOSMsg.notification(k, v, time=0.0, source="test") for k, v in pairs]


def test_sampler_asks_at_its_rate_only_in_its_phases_and_forwards_its_answers(tmp_path):
    sampler = make(OilSampler, tmp_path, sample_interval=5)
    sampler.on_new_mail(mail(("NAV_X", 10.0), ("NAV_Y", -4.0)))
    sampler.iterate()
    assert sampler.posts == []                                   # station-keeping: no sampling
    sampler.on_new_mail(mail(("OILSPILL_PHASE", "OIL-PATH")))
    for t in (1000.0, 1002.0, 1005.0):
        sampler.clock = t
        sampler.iterate()
    assert sampler.posts == [("OIL_SENSOR_REQUEST", "vname=abe,id=1,x=10.00,y=-4.00"),
                             ("OIL_SENSOR_REQUEST", "vname=abe,id=2,x=10.00,y=-4.00")]
    sampler.posts.clear()
    answer = "vname=abe,id=2,utc=1275019200,x=10,y=-4,oil=1,range=15"
    sampler.on_new_mail(mail(("OIL_SENSOR_REPORT", answer), ("OIL_SENSOR_REPORT", answer),
                             ("OIL_SENSOR_REPORT", "vname=abe,id=9,utc=1,x=0,y=0,oil=0")))
    assert sampler.posts[0] == ("OIL_OBSERVATION", "vname=abe,id=2,utc=1275019200.00,x=10,y=-4,oil=1,range=15")
    assert [k for k, _ in sampler.posts[1:]] == ["OIL_SAMPLER_WARNING", "OIL_SAMPLER_WARNING"]
    assert sampler.posts[1][1].startswith("test@?: answer to a request this vehicle did not make")
    assert sampler.status_fields()["unanswered"] == 1           # request 1 never answered: counted, no wait


def test_fusion_app_rejects_with_reasons_and_writes_the_feedback_file(tmp_path):
    feedback = tmp_path / "fb.jsonl"
    fusion = make(OilFusion, tmp_path, community="shoreside", fleet="abe:ben", operating_radius=1000,
                  map_scale=0.02, feedback_file=feedback)
    fusion.on_new_mail(mail(("OILSPILL_BOUNDARY", "pts={0,0:100,0:100,100:0,100},label=oilspill_1")))
    good = "vname=abe,id=1,utc=1275019200,x=50,y=120,oil=0,range=15"
    fusion.on_new_mail(mail(("OIL_OBSERVATION", good), ("OIL_OBSERVATION", good),
                            ("OIL_OBSERVATION", "vname=zed,id=1,utc=1275019200,x=50,y=50,oil=1,range=15"),
                            ("OIL_OBSERVATION", "vname=ben,id=1,utc=1275019200,x=5000,y=50,oil=1,range=15"),
                            ("OIL_OBSERVATION", "vname=abe,id=2,utc=1275019100,x=50,y=110,oil=1,range=15"),
                            ("OIL_OBSERVATION", "vname=abe,id=3,utc=1275019300,x=50,y=105,oil=1,range=15")))
    warnings = [v for k, v in fusion.posts if k == "OIL_FUSION_WARNING"]
    assert len(warnings) == 3 and "unknown vehicle 'zed'" in warnings[0] and "operating area" in warnings[1] \
        and "older than" in warnings[2]
    rows = [json.loads(line) for line in feedback.read_text().splitlines()]
    assert [(r["utc"], r["oil"], r["cycle"]) for r in rows] == [(1275019200, False, "oilspill_1"),
                                                              (1275019300, True, "oilspill_1")]
    assert rows[0]["range_m"] == pytest.approx(750) and abs(rows[0]["lat"] - 28.736667) < 0.1
    fusion.clock += 10
    fusion.iterate()
    skill = dict(kv.split("=") for kv in next(v for k, v in fusion.posts if k == "OIL_FUSION_SKILL").split(","))
    assert skill["cycle"] == "oilspill_1" and skill["observations"] == "2" and skill["flips"] == "1"
    assert skill["rejected"] == "3" and skill["duplicates"] == "1"


def test_sensor_config_errors_name_the_parameter(tmp_path):
    with pytest.raises(ValueError, match="scenario"):
        make(OilSensor, tmp_path, community="shoreside", scenario="no-such-spill")
    with pytest.raises(ValueError, match="false_positive"):
        make(OilSensor, tmp_path, community="shoreside", false_positive=2)
    flat = tmp_path / "flat.moos"
    flat.write_text("ServerPort = 9000\nCommunity = shoreside\n")
    with pytest.raises(ValueError, match=r"flat\.moos: needs LatOrigin and LongOrigin"):
        OilSensor(flat).on_startup()


def test_fusion_config_errors_name_file_and_line(tmp_path):
    with pytest.raises(ValueError, match=r"m\.moos:\d+: report_interval"):
        make(OilFusion, tmp_path, community="shoreside", report_interval="often")
    with pytest.raises(ValueError, match=r"m\.moos:\d+: operating_area"):
        make(OilFusion, tmp_path, community="shoreside", operating_area="0,0:1")


def test_feedback_apps_warn_of_unhandled_parameters(tmp_path, caplog):
    for cls, community in ((OilSampler, "abe"), (OilSensor, "shoreside"), (OilFusion, "shoreside")):
        make(cls, tmp_path, community=community, sample_intervl=5)
        assert "m.moos:9: unhandled parameter 'sample_intervl'" in caplog.text, cls.default_name
        caplog.clear()


def test_sensor_answers_requests_and_jumps_its_clock_on_command(tmp_path):
    sensor = make(OilSensor, tmp_path, community="shoreside", scenario="steady_growth-2111", start_hour=20,
                  map_scale=0.02, sensor_range=15)
    centre = sensor.truth.at(20).centroid
    sensor.on_new_mail(mail(("OIL_SENSOR_REQUEST", f"vname=abe,id=4,x={centre.x},y={centre.y}"),
                            ("OIL_SENSOR_REQUEST", "vname=ben,id=1,x=99999,y=0"),
                            ("OIL_SENSOR_REQUEST", "vname=cal,x=1")))
    (k1, v1), (k2, v2), (k3, v3) = sensor.posts
    assert k1 == "OIL_SENSOR_REPORT_ABE" and ",oil=1," in v1 and "id=4" in v1
    assert k2 == "OIL_SENSOR_REPORT_BEN" and ",oil=0," in v2
    assert k3 == "OIL_SENSOR_WARNING" and "lacks id" in v3
    assert float(v1.split("utc=")[1].split(",")[0]) == pytest.approx(sensor.truth.utc(20))
    sensor.clock += 1800
    assert sensor.hour() == pytest.approx(20.5)
    sensor.on_new_mail(mail(("UFLDOILSENSOR_CMD", "hour=30"), ("UFLDOILSENSOR_CMD", "hour=soon")))
    assert sensor.hour() == pytest.approx(30.0) and "expected hour=H" in sensor.posts[-1][1]
