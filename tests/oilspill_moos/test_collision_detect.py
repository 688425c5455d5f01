"""uFldCollisionDetect: vehicles passing at hand-chosen distances are ranked as the ranges say;
counts, UCD_REPORT, flags and their macros; jitter, conditions and groups."""
from __future__ import annotations

import pytest

from moosdb_py.source import MissionFileError
from oilspill_moos.field.collision_detect import CollisionDetect, CollisionMonitor, CollisionParams


def monitor(**config) -> CollisionMonitor:
    return CollisionMonitor(CollisionParams.from_config({k: str(v) for k, v in config.items()}))


def pass_by(mon, offset, seconds=60, t0=0.0, names=("abe", "ben"), speed=2.0):
    """Two vehicles on opposite courses along x, `offset` metres apart in y, meeting at t0 + 30 s."""
    posts = []
    for t in range(seconds):
        x = speed * (t - 30)
        mon.on_mail("NODE_REPORT", f"NAME={names[0]},X={x},Y=0,SPD={speed},HDG=90")
        mon.on_mail("NODE_REPORT", f"NAME={names[1]},X={-x},Y={offset},SPD={speed},HDG=270")
        posts += mon.iterate(t0 + t)
    return posts


def values(posts, key):
    return [v for k, v in posts if k == key]


@pytest.mark.parametrize("offset, rank", [(0.5, "collision"), (3.0, "collision"), (4.0, "near_miss"),
                                          (6.0, "near_miss"), (12.0, "encounter"), (20.0, "encounter"),
                                          (25.0, None)])
def test_a_pass_is_ranked_by_its_cpa(offset, rank):
    mon = monitor()
    posts = pass_by(mon, offset)
    assert mon.totals == {"collision": int(rank == "collision"), "near_miss": int(rank == "near_miss"),
                          "encounter": int(rank is not None)}
    reports = values(posts, "UCD_REPORT")
    if rank in ("collision", "near_miss"):
        assert reports == [f"vname1=abe,vname2=ben,cpa={offset:g},rank={rank}"]
        assert values(posts, f"{rank.upper()}_TOTAL") == [1.0]
    else:
        assert reports == []
    assert values(posts, "ENCOUNTER_TOTAL") == ([1.0] if rank else [])


def test_counts_add_up_over_several_passes_and_vehicles():
    mon = monitor()
    pass_by(mon, 2, t0=0)
    pass_by(mon, 5, t0=100)
    pass_by(mon, 10, t0=200, names=("abe", "cal"))
    assert mon.totals == {"collision": 1, "near_miss": 1, "encounter": 3}
    assert mon.per_vehicle["abe"] == {"collision": 1, "near_miss": 1, "encounter": 3}
    assert mon.per_vehicle["cal"] == {"collision": 0, "near_miss": 0, "encounter": 1}


def test_flags_expand_vehicle_names_and_the_cpa():
    mon = monitor(encounter_flag="ENCOUNTER = $CPA", collision_flag="COLLISION_$UP_V1 = $V1 hit $V2 at $CPA",
                  near_miss_flag="NEAR_MISS = vname1=$V1,vname2=$V2,cpa=$CPA")
    posts = pass_by(mon, 1.25)
    assert values(posts, "ENCOUNTER") == [1.25]              # a lone $CPA posts a number
    assert values(posts, "COLLISION_ABE") == ["abe hit ben at 1.25"]
    assert values(posts, "NEAR_MISS") == []                  # a collision is not also a near miss


def test_report_all_encounters_and_closest_range():
    mon = monitor(report_all_encounters="true", post_closest_range="true", pulse_render="false")
    posts = pass_by(mon, 15)
    assert values(posts, "UCD_REPORT") == ["vname1=abe,vname2=ben,cpa=15,rank=encounter"]
    assert min(values(posts, "UCD_CLOSEST_RANGE")) == 15 and mon.closest_ever == 15
    assert values(posts, "VIEW_RANGE_PULSE") == []


def test_range_jitter_within_a_metre_is_no_pass():
    mon = monitor()
    for t in range(40):   # two vehicles 2 m apart whose range wobbles by 0.8 m
        mon.on_mail("NODE_REPORT", "NAME=abe,X=0,Y=0")
        mon.on_mail("NODE_REPORT", f"NAME=ben,X={2 + 0.8 * (t % 2)},Y=0")
        assert mon.iterate(t) == []
    assert mon.totals["encounter"] == 0


def test_events_count_only_while_the_conditions_hold():
    mon = monitor(condition="DEPLOY_ALL = true")
    pass_by(mon, 2)
    assert mon.totals["encounter"] == 0
    mon.on_mail("DEPLOY_ALL", "true")
    pass_by(mon, 2, t0=100)
    assert mon.totals == {"collision": 1, "near_miss": 0, "encounter": 1}


def test_ignored_pairs_and_rejected_groups():
    mon = monitor(ignore_group="buoys", reject_group="ghosts")
    for t in range(60):
        x = 2.0 * (t - 30)
        for name, xx, y, group in (("b1", x, 0, "buoys"), ("b2", -x, 1, "buoys"), ("abe", x, 40, "red"),
                                   ("gho", -x, 41, "ghosts")):
            mon.on_mail("NODE_REPORT", f"NAME={name},X={xx},Y={y},GROUP={group}")
        mon.iterate(t)
    assert mon.totals["encounter"] == 0 and "gho" not in mon.records


def test_range_order_is_enforced_and_bad_lines_are_named(tmp_path):
    params = CollisionParams.from_config({"collision_range": "8", "near_miss_range": "5", "encounter_range": "4"})
    assert (params.collision_range, params.near_miss_range, params.encounter_range) == (8, 8, 8)
    assert len(params.warnings) == 2
    path = tmp_path / "shore.moos"
    path.write_text("ServerPort = 9000\n\nProcessConfig = uFldCollisionDetect\n{\n  condition = DEPLOY_ALL true\n}\n")
    with pytest.raises(MissionFileError, match=r"shore\.moos:5: condition"):
        CollisionDetect(path).on_startup()
