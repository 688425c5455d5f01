"""uSimMarine model: config parsing, thrust map, speed/heading/position arithmetic, drift."""
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from oilspill_moos.marine.sim_marine import MarineModel, NavState, SimParams, ThrustMap, parse_drift_vector

ALPHA = {  # the s1_alpha uSimMarineV22 block, lower-case keys as ProcessConfig.get sees them
    "start_pos": "x=0, y=-20, heading=180, speed=0",
    "prefix": "NAV",
    "turn_rate": "95",
    "thrust_map": "0:0, 20:1, 40:2, 60:3, 80:4, 100:5",
    "turn_spd_loss": "0.4",
}


def test_alpha_block_parses():
    p = SimParams.from_config(ALPHA)
    assert (p.start.x, p.start.y, p.start.heading, p.start.speed) == (0, -20, 180, 0)
    assert p.prefix == "NAV" and p.turn_rate == 95 and p.turn_spd_loss == 0.4
    assert p.thrust_map.speed(50) == pytest.approx(2.5)
    assert p.max_deceleration == 0.5 and p.max_speed == 5


def test_defaults_and_start_keys():
    p = SimParams.from_config({"start_x": "3", "start_y": "-4", "start_heading": "370"})
    assert p.prefix == "USM" and p.turn_rate == 70
    assert (p.start.x, p.start.y, p.start.heading) == (3, -4, 10)
    assert p.thrust_map.speed(100) == 5.0  # thrust / thrust_factor 20


@pytest.mark.parametrize("text, expected", [
    ("0,0, 180, 0", (0, 0, 180, 0)),
    ("x=10,y=-5,heading=90", (10, -5, 90, 0)),
    ("5, 7", (5, 7, 0, 0)),
    ("x=0,y=0,heading=90, 1.5", (0, 0, 90, 1.5)),     # m2_berta: `$(START_POS), 0`, the bare 4th field is speed
])
def test_start_pos_forms(text, expected):
    s = NavState.parse(text)
    assert (s.x, s.y, s.heading, s.speed) == expected


@pytest.mark.parametrize("cfg, word", [
    ({"start_pos": "x=1, q=2"}, "start_pos"),
    ({"start_pos": "a,b"}, "start_pos x"),
    ({"turn_rate": "150"}, "turn_rate"),
    ({"thrust_map": "0:0, 50"}, "thrust_map"),
    ({"thrust_map": "20:2, 40:1"}, "thrust_map"),
    ({"turn_spd_loss": "lots"}, "turn_spd_loss"),
    ({"drift_vector": "90"}, "drift_vector"),
])
def test_bad_parameters_name_themselves(cfg, word):
    with pytest.raises(ValueError, match=word):
        SimParams.from_config(cfg)


def test_thrust_map_interpolates_clamps_and_reflects():
    m = ThrustMap.parse("20:1, 40:2, 100:5")
    assert m.speed(10) == pytest.approx(0.5)
    assert m.speed(70) == pytest.approx(3.5)
    assert m.speed(100) == 5 and m.speed(0) == 0
    assert m.speed(-50) == 0
    r = ThrustMap.parse("20:1, 100:5", reflect=True)
    assert r.speed(-20) == pytest.approx(-1)


def test_speed_halves_the_gap_each_step():
    model = MarineModel(SimParams.from_config(ALPHA))
    model.set_thrust(40)
    speeds = []
    for _ in range(3):
        model.step(0.25)
        speeds.append(model.state.speed)
    assert speeds == pytest.approx([1.0, 1.5, 1.75])


def test_acceleration_and_deceleration_limits():
    p = SimParams.from_config({**ALPHA, "max_acceleration": "0.4"})
    model = MarineModel(p)
    model.set_thrust(100)
    model.step(1.0)  # next limited to 0.4, stored mean 0.2
    assert model.state.speed == pytest.approx(0.2)
    model.state.speed = 4.0
    model.set_thrust(0)
    model.step(1.0)  # decel 0.5: next 3.5, stored (4+3.5)/2
    assert model.state.speed == pytest.approx(3.75)


def test_heading_turn_scales_with_speed_thrust_and_rudder():
    model = MarineModel(SimParams.from_config({**ALPHA, "turn_spd_loss": "0", "start_pos": "0,0,0,2.5"}))
    model.set_thrust(50)  # map speed 2.5, so speed stays 2.5 and thrust factor is 1
    model.set_rudder(100, 0.0)
    model.step(0.5)
    # 100 * (95 * 2.5/5)/100 * 0.5 * 1
    assert model.state.heading == pytest.approx(23.75)
    model.set_rudder(-40, 0.1)  # a 140 jump is cut to 100 ...
    assert model.rudder == 0
    model.set_rudder(-40, 0.2)  # ... and the next message gets there
    model.step(1.0)
    assert model.state.heading == pytest.approx(23.75 - 40 * 0.475)


def test_no_turn_without_speed():
    model = MarineModel(SimParams.from_config(ALPHA))
    model.set_rudder(100, 0.0)
    model.step(1.0)
    assert model.state.heading == 180


def test_rudder_message_moves_at_most_100():
    model = MarineModel(SimParams.from_config(ALPHA))
    model.set_rudder(-100, 0.0)
    model.set_rudder(100, 0.1)
    assert model.rudder == 0
    rate = MarineModel(SimParams.from_config({**ALPHA, "max_rudder_degs_per_sec": "20"}))
    rate.set_rudder(50, 0.0)  # first message: no time reference yet
    rate.set_rudder(-50, 2.0)
    assert rate.rudder == pytest.approx(10)


def test_straight_run_south_from_start():
    model = MarineModel(SimParams.from_config(ALPHA))
    model.set_thrust(40)
    for _ in range(400):
        model.step(0.25)
    s = model.state
    assert s.x == pytest.approx(0, abs=1e-9)
    assert s.speed == pytest.approx(2.0)
    # 100 s at ~2 m/s minus the first step lag, heading south from y=-20
    assert s.y == pytest.approx(-20 - 2.0 * 100 + 0.5, abs=0.6)


def test_drift_moves_a_stopped_vehicle_and_shows_over_ground():
    model = MarineModel(SimParams.from_config({**ALPHA, "drift_vector": "90, 0.5", "drift_y": "0.1"}))
    res = model.step(2.0)
    assert (model.state.x, model.state.y) == pytest.approx((1.0, -20 + 0.2))
    assert res.speed_over_ground == pytest.approx(math.hypot(0.5, 0.1))
    assert res.heading_over_ground == pytest.approx(math.degrees(math.atan2(0.5, 0.1)))
    model.drift_x, model.drift_y = parse_drift_vector("180, 1.0", "DRIFT_VECTOR")
    assert model.drift_angle == pytest.approx(180) and model.drift_magnitude == pytest.approx(1.0)


def test_rotate_speed_turns_even_when_stopped_and_pause_freezes():
    model = MarineModel(SimParams.from_config({**ALPHA, "rotate_speed": "2"}))
    model.step(5.0)
    assert model.state.heading == pytest.approx(190)
    model.paused = True
    model.step(5.0)
    assert model.state.heading == pytest.approx(190)


def test_surface_craft_stays_at_depth_zero_and_elevator_dives():
    model = MarineModel(SimParams.from_config({**ALPHA, "start_pos": "0,0,0,2"}))
    model.set_thrust(40)
    model.step(1.0)
    assert model.state.depth == 0
    model.set_elevator(100)
    model.step(1.0)
    assert model.state.depth == pytest.approx(0.5 - 0.025)


@settings(max_examples=60, deadline=None)
@given(rudder=st.floats(-100, 100), thrust=st.floats(-100, 100), dt=st.floats(0.01, 2.0),
       heading=st.floats(0, 359.9), speed=st.floats(0, 5))
def test_step_stays_bounded(rudder, thrust, dt, heading, speed):
    model = MarineModel(SimParams.from_config({**ALPHA, "start_pos": f"0,0,{heading},{speed}"}))
    model.set_rudder(rudder, 0.0)
    model.set_thrust(thrust)
    res = model.step(dt)
    s = model.state
    assert 0 <= s.heading < 360
    assert 0 <= s.speed <= 5
    assert math.hypot(s.x, s.y) <= 5 * dt + 1e-9
    assert res.speed_over_ground == pytest.approx(math.hypot(s.x, s.y) / dt)


@settings(max_examples=200)
@given(pairs=st.dictionaries(st.floats(-100, 100), st.floats(0, 10), min_size=1, max_size=7),
       thrust=st.floats(-100, 100))
@example(pairs={5e-324: 1.0, -1.0: 0.0}, thrust=0.0)       # a subnormal segment: inf x 0 unless done as numpy does
def test_thrust_map_interpolates_as_numpy_does_to_the_bit(pairs, thrust):
    """The speed of a thrust: np.interp's value over the sorted map (plain floats, one scalar a step)."""
    table = ThrustMap(sorted(pairs.items()))
    table_with_zero = dict(pairs)
    table_with_zero.setdefault(0.0, 0.0)
    thrusts = sorted(table_with_zero)
    expected = float(np.interp(thrust, thrusts, [table_with_zero[t] for t in thrusts]))
    if thrust < 0.0 and thrusts[0] >= 0.0:
        expected = 0.0
    assert table.speed(thrust) == expected
