"""pMarinePID control law: scalar PID arithmetic, thrust and rudder rules, config keys."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oilspill_moos.marine.marine_pid import PIDEngine, PIDGains, PIDParams, ScalarPID, angle180

ALPHA = {  # s1_alpha's pMarinePIDV22 block
    "depth_control": "false",
    "yaw_pid_kp": "0.9", "yaw_pid_kd": "0.3", "yaw_pid_ki": "0.3", "yaw_pid_integral_limit": "0.07",
    "speed_pid_kp": "1.0", "speed_pid_kd": "0.0", "speed_pid_ki": "0.0", "speed_pid_integral_limit": "0.07",
    "maxrudder": "100", "maxthrust": "100", "speed_factor": "20",
}


def test_alpha_block_parses():
    p = PIDParams.from_config(ALPHA)
    assert p.yaw == PIDGains(0.9, 0.3, 0.3, 0.07)
    assert p.speed_factor == 20 and p.depth_control is False and p.simulation is False


def test_missing_gains_are_zero_and_depth_control_defaults_true():
    p = PIDParams.from_config({"yaw_pid_ki_limit": "0.2"})
    assert p.yaw == PIDGains(0, 0, 0, 0.2)
    assert p.depth_control is True and p.max_rudder == 100


@pytest.mark.parametrize("cfg, word", [({"depth_control": "maybe"}, "depth_control"),
                                       ({"yaw_pid_kp": "x"}, "yaw_pid_kp"),
                                       ({"maxthrust": "-1"}, "maxthrust")])
def test_bad_values_name_the_parameter(cfg, word):
    with pytest.raises(ValueError, match=word):
        PIDParams.from_config(cfg)


def test_angle180():
    assert angle180(190) == -170 and angle180(-190) == 170 and angle180(180) == 180 and angle180(360) == 0


def test_scalar_pid_proportional_derivative_integral():
    pid = ScalarPID(PIDGains(kp=2.0, kd=1.0, ki=0.5, integral_limit=10.0), output_limit=100.0)
    assert pid.run(4.0, 10.0) == pytest.approx(8.0)  # first call: no derivative, no dt for I
    # e=2 at dt=1: derivative -2, integral 0.5*2*1 = 1
    assert pid.run(2.0, 11.0) == pytest.approx(4.0 - 2.0 + 1.0)
    # e=2 at dt=1: derivatives (-2, 0) -> mean -1, integral 2
    assert pid.run(2.0, 12.0) == pytest.approx(4.0 - 1.0 + 2.0)
    assert pid.run(7.0, 12.0) == pytest.approx(5.0)  # dt = 0 repeats the last output


def test_scalar_pid_limits_and_derivative_window():
    pid = ScalarPID(PIDGains(kp=0.0, kd=1.0, ki=1.0, integral_limit=0.5), output_limit=3.0)
    pid.run(0.0, 0.0)
    for t in range(1, 12):
        pid.run(float(t), float(t))  # derivative 1 each step
    assert pid.integral == 0.5
    assert pid.output == pytest.approx(1.5)
    pid.run(100.0, 12.0)  # derivative spike averaged over 9: (8*1 + 89)/9
    assert pid.output == 3.0  # clipped


def test_thrust_from_speed_factor_and_never_negative():
    eng = PIDEngine(PIDParams.from_config(ALPHA))
    assert eng.desired_thrust(2.0, 0.0, 1.0) == 40.0
    assert eng.desired_thrust(9.0, 0.0, 2.0) == 100.0
    assert eng.desired_thrust(-1.0, 0.0, 3.0) == 0.0


def test_incremental_speed_pid_without_factor():
    eng = PIDEngine(PIDParams.from_config({**ALPHA, "speed_factor": "0", "speed_pid_kp": "5"}))
    assert eng.desired_thrust(2.0, 0.0, 1.0) == 10.0
    assert eng.desired_thrust(2.0, 1.0, 2.0) == 15.0  # previous thrust + 5*1
    assert eng.desired_thrust(0.0, 3.0, 3.0) == 0.0


def test_rudder_turns_toward_desired_heading_and_needs_thrust():
    eng = PIDEngine(PIDParams.from_config({**ALPHA, "yaw_pid_kd": "0", "yaw_pid_ki": "0"}))
    # heading 350, desired 10: error -20 -> rudder +18 (turn right)
    rudder, thrust = eng.control(10.0, 2.0, 350.0, 2.0, 1.0)
    assert (rudder, thrust) == pytest.approx((18.0, 40.0))
    rudder, thrust = eng.control(-90.0, 0.0, 0.0, 2.0, 2.0)
    assert (rudder, thrust) == (0.0, 0.0)
    rudder, _ = eng.control(270.0, 2.0, 0.0, 2.0, 3.0)
    assert rudder == pytest.approx(-81.0)


def test_depth_loop_sign():
    eng = PIDEngine(PIDParams.from_config({"z_to_pitch_pid_kp": "1", "pitch_pid_kp": "1",
                                           "maxpitch": "15", "maxelevator": "13"}))
    # 10 m too shallow: desired pitch -10 (nose down); pitch 0 -> elevator +10 (dive)
    assert eng.desired_elevator(20.0, 10.0, 0.0, 1.0) == pytest.approx(10.0)


@settings(max_examples=60, deadline=None)
@given(dh=st.floats(-720, 720), h=st.floats(0, 359.99), ds=st.floats(-5, 10), s=st.floats(0, 5))
def test_outputs_stay_within_limits(dh, h, ds, s):
    eng = PIDEngine(PIDParams.from_config({**ALPHA, "maxrudder": "40", "maxthrust": "80"}))
    for t in (0.0, 0.05, 0.1):
        rudder, thrust = eng.control(dh, ds, h, s, t)
        assert -40 <= rudder <= 40 and 0 <= thrust <= 80
