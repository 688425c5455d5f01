"""The demo's timeline: phase marks taken from pPathAssign's own stamps, and the sanity check it runs
before writing the report (a cycle once came out with station_keeping_s ~1.8e10 and a negative transit)."""
from moosdb_py.message import MOOSMsg
from oilspill_moos.demo import timeline_problems
from oilspill_moos.oilspill_mission import Observer
from oilspill_moos.response.path_assign import OIL_PATH, STARTING_POSITION, STATION_KEEPING


def cycle(number, push, sk, sp, op, looped):
    return {"boundary": number, "pushed_moos_s": push, "station_keeping_moos_s": sk,
            "starting_position_moos_s": sp, "oil_path_moos_s": op, "looped_moos_s": looped,
            "station_keeping_s": round(sp - sk, 2), "transit_s": round(op - sp, 2),
            "push_to_loop_s": round(op - push, 2)}


def events(*phases):
    return [{"event": "phase", "what": what, "moos_s": t, "wall_s": t / 10} for what, t in phases]


def test_a_sane_timeline_passes():
    report = {"cycles": [cycle(1, 10, 10.2, 16, 150, 270), cycle(2, 271, 271.1, 277, 330, 450)],
              "events": events((STATION_KEEPING, 10.2), (STARTING_POSITION, 16), (OIL_PATH, 150))}
    assert timeline_problems(report, 460) == []


def test_the_old_mix_of_absolute_and_relative_stamps_is_caught():
    absolute = 1.76e10
    bad = cycle(1, 10, 10.2, absolute, 150, 270)     # a mark on the absolute clock, as the old demo took it
    problems = timeline_problems({"cycles": [bad], "events": []}, 460)
    assert any("OIL-PATH at 150 s mission comes before STARTING-POSITION" in p for p in problems)
    late = cycle(1, 10, 10.2, 16, 150, 9e9)
    assert any("outside the run" in p for p in timeline_problems({"cycles": [late], "events": []}, 460))
    overlap = [cycle(1, 10, 10.2, 16, 150, 270), cycle(2, 200, 201, 205, 300, 400)]
    assert any("boundary 2: push" in p for p in timeline_problems({"cycles": overlap, "events": []}, 460))
    shuffled = events((STARTING_POSITION, 16), (STATION_KEEPING, 10.2))
    assert any("out of time order" in p
               for p in timeline_problems({"cycles": [], "events": shuffled}, 460))


def test_phase_marks_carry_the_sender_stamp_relative_to_the_observer_start():
    observer = Observer("127.0.0.1", 1, warp=10.0)
    t0 = observer.t0
    push = observer.note("push", "boundary 1: 4 line(s)")
    assert 0 <= push["moos_s"] < 5
    for key, value, dt in (("OILSPILL_PHASE", STATION_KEEPING, 3.0), ("OILSPILL_WARNING", "x", 4.0),
                           ("OILSPILL_PHASE", STARTING_POSITION, 9.5), ("OILSPILL_PHASE", OIL_PATH, 80.25)):
        observer.on_mail([MOOSMsg.notification(key, value, time=t0 + dt, source="pPathAssign")])
    first = observer.phase_event(STATION_KEEPING, 0)
    start = observer.phase_event(STARTING_POSITION, first)
    loop = observer.phase_event(OIL_PATH, start)
    assert [observer.events[i]["moos_s"] for i in (first, start, loop)] == [3.0, 9.5, 80.25]
    assert observer.phase_event(STATION_KEEPING, first) is None


def test_the_phase_the_db_sends_again_on_a_reconnection_is_no_new_phase():
    from types import SimpleNamespace

    observer = Observer("127.0.0.1", 1, warp=10.0)
    observer.t0 = 100.0
    mail = [SimpleNamespace(key="OILSPILL_PHASE", value=v, time=t, community="shoreside")
            for v, t in (("STARTING-POSITION", 150.0), ("OIL-PATH", 150.0))]   # both in one tick: both count
    observer.on_mail(mail)
    observer.on_mail([SimpleNamespace(key="OILSPILL_PHASE", value="OIL-PATH", time=150.0, community="shoreside")])
    assert [e["what"] for e in observer.events if e["event"] == "phase"] == ["STARTING-POSITION", "OIL-PATH"]
