"""control: LQI design, the flight controller in closed loop with RK4, and the fast prediction."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model import dynamics as D
from heli_model.control import (
    ControlError,
    ControllerSettings,
    FlightController,
    Setpoint,
    design_lqi,
    simulate_closed_loop,
    wrap_pi,
)
from heli_model.model import HeliModel
from sim_vehicle import references

MODEL = HeliModel.default()
SETTINGS = ControllerSettings()
PHYSICS_DT = 1.0 / 400.0
CONTROL_DT = 1.0 / 100.0


def circle_reference(t_s, **kwargs):
    """The standard circle; a fixed heading is 0.3 rad here (not north)."""
    return references.circle_reference(t_s, yaw_fixed_rad=0.3, **kwargs)


def fly(controller, x, setpoint_at, t_end_s, wind=None):
    """Full loop: controller at 100 Hz, RK4 physics at 400 Hz. Returns states and raw inputs."""
    n = int(round(t_end_s / CONTROL_DT))
    states = [x]
    max_raw = 0.0
    saturated = False
    for k in range(n):
        delta = controller.update(x, setpoint_at(k), CONTROL_DT)
        max_raw = max(max_raw, float(np.max(np.abs(controller.delta_unclipped))))
        saturated |= controller.saturated
        for _ in range(4):
            x = D.step_rk4(controller.model, x, delta, PHYSICS_DT, wind)
        states.append(x)
    return np.array(states), max_raw, saturated


def test_lqi_closed_loop_is_stable():
    gains = design_lqi(MODEL, CONTROL_DT, SETTINGS.q_weights, SETTINGS.r_weights)
    assert gains.K.shape == (4, 18)
    assert np.max(np.abs(gains.closed_loop_eigenvalues)) < 1.0
    # rebuild the augmented closed loop ourselves: z+ = z + dt C x
    n = 14
    acl = np.zeros((18, 18))
    acl[:n, :n] = gains.Ad - gains.Bd @ gains.Kx
    acl[:n, n:] = -gains.Bd @ gains.Kz
    acl[n:, :n] = CONTROL_DT * gains.C
    acl[n:, n:] = np.eye(4)
    assert np.max(np.abs(np.linalg.eigvals(acl))) < 1.0


def test_design_is_cached_per_model_step_and_weights():
    a = design_lqi(MODEL, CONTROL_DT, SETTINGS.q_weights, SETTINGS.r_weights)
    b = design_lqi(MODEL, CONTROL_DT, list(SETTINGS.q_weights), list(SETTINGS.r_weights))
    assert a is b
    c = design_lqi(MODEL, 0.02, SETTINGS.q_weights, SETTINGS.r_weights)
    assert c is not a


@pytest.mark.parametrize(
    ("q", "r", "name"),
    [
        ((1.0,) * 17, (1.0,) * 4, "q_weights"),
        ((1.0,) * 18, (1.0, 1.0, 0.0, 1.0), "r_weights\\[2\\]"),
        ((1.0,) * 17 + (float("nan"),), (1.0,) * 4, "q_weights\\[17\\]"),
    ],
)
def test_bad_weights_are_rejected_naming_them(q, r, name):
    with pytest.raises(ControlError, match=name):
        design_lqi(MODEL, CONTROL_DT, q, r)


def test_feedforward_trim_holds_a_steady_velocity():
    gains = design_lqi(MODEL, CONTROL_DT, SETTINGS.q_weights, SETTINGS.r_weights)
    ref = np.array([0, 0, 0, 0, 4.0, -1.0, 0.5, 0.0])
    sol = gains.ff_map @ ref
    x_ff, d_ff = sol[:14], sol[14:]
    assert np.allclose(x_ff[:3], [4.0, -1.0, 0.5])
    xdot = MODEL.A @ x_ff[:13] + MODEL.B @ d_ff
    assert np.max(np.abs(xdot)) < 1e-9


@pytest.mark.parametrize("step_m", [(1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, -2.0), (2.0, -2.0, 1.0)])
def test_position_step_settles_without_saturating(step_m):
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -20.0))
    fc.reset(x)
    target = np.array([0.0, 0.0, -20.0]) + step_m
    states, max_raw, saturated = fc_states = fly(fc, x, lambda k: Setpoint(pos_ned_m=target, yaw_rad=0.0), 10.0)
    err = np.linalg.norm(states[:, 14:17] - target, axis=1)
    size = np.linalg.norm(step_m)
    outside = np.nonzero(err > 0.05 * size)[0]
    settle_s = (outside[-1] + 1) * CONTROL_DT if outside.size else 0.0
    assert not saturated and max_raw < 1.0, fc_states[1]
    assert settle_s < 6.0
    assert err[-1] < 0.01 * size
    assert np.max(np.abs(states[:, 13])) < 0.05  # heading held


@pytest.mark.parametrize("heading", ["path", "fixed"])
def test_circle_is_tracked_within_the_goal_without_saturating(heading):
    t = np.arange(0.0, 60.0 + CONTROL_DT / 2, CONTROL_DT)
    pos, vel, acc, yaw = circle_reference(t, heading=heading)
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, pos[0], yaw[0])
    fc.reset(x)
    states, max_raw, saturated = fly(fc, x, lambda k: Setpoint(pos[k], vel[k], acc[k], yaw[k]), 60.0)
    err = np.linalg.norm(states[:, 14:17] - pos, axis=1)
    assert math.sqrt(np.mean(err**2)) <= 0.3
    assert np.max(err) <= 0.6
    assert not saturated and max_raw < 1.0


@pytest.mark.parametrize("use_rate", [False, True])
def test_fast_prediction_agrees_with_the_step_loop(use_rate):
    t = np.arange(0.0, 40.0 + CONTROL_DT / 2, CONTROL_DT)
    pos, vel, acc, yaw = circle_reference(t, radius_m=20.0, speed_m_s=6.0)
    rate = np.gradient(np.unwrap(yaw), t) if use_rate else None
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, pos[0], yaw[0])
    fc.reset(x)
    states, max_raw, _ = fly(
        fc, x, lambda k: Setpoint(pos[k], vel[k], acc[k], yaw[k], None if rate is None else rate[k]), 40.0
    )
    pred = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw, SETTINGS, yaw_rate_rad_s=rate)
    assert pred.pos_ned_m.shape == (t.size, 3) and pred.delta.shape == (t.size, 4)
    assert np.max(np.linalg.norm(pred.pos_ned_m - states[:, 14:17], axis=1)) < 0.03
    full_err = np.linalg.norm(states[:, 14:17] - pos, axis=1)
    assert pred.max_tracking_error_m == pytest.approx(np.max(full_err), abs=0.02)
    assert pred.max_abs_delta == pytest.approx(max_raw, abs=0.05)
    assert not pred.saturated


def test_fast_prediction_flags_saturation_and_resamples():
    t = np.linspace(0.0, 20.0, 801)  # 40 Hz samples, not the control rate
    pos, vel, acc, yaw = circle_reference(t, radius_m=8.0, speed_m_s=12.0, ramp_s=1.0)
    pred = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw)
    assert pred.t_s.shape == (801,) and pred.tracking_error_m.shape == (801,)
    assert pred.saturated and pred.max_abs_delta > 1.0


def test_fast_prediction_from_a_given_state_closes_the_gap():
    t = np.arange(0.0, 15.0, CONTROL_DT)
    pos = np.tile([0.0, 0.0, -10.0], (t.size, 1))
    zeros = np.zeros_like(pos)
    x0 = D.hover_state(MODEL, (1.0, 0.0, -10.0))
    pred = simulate_closed_loop(MODEL, t, pos, zeros, zeros, np.zeros(t.size), x0=x0)
    assert pred.tracking_error_m[0] == pytest.approx(1.0)
    assert pred.tracking_error_m[-1] < 0.02


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"t_s": np.zeros(5)}, "t_s"),
        ({"pos_ned_m": np.zeros((5, 2))}, "pos_ned_m"),
        ({"yaw_rad": np.full(5, np.nan)}, "yaw_rad"),
    ],
)
def test_fast_prediction_rejects_bad_input_naming_it(kwargs, name):
    args = {
        "t_s": np.arange(5.0),
        "pos_ned_m": np.zeros((5, 3)),
        "vel_ned_m_s": np.zeros((5, 3)),
        "acc_ned_m_s2": np.zeros((5, 3)),
        "yaw_rad": np.zeros(5),
    }
    args.update(kwargs)
    with pytest.raises(ControlError, match=name):
        simulate_closed_loop(MODEL, **args)


def test_velocity_only_setpoint_tracks_velocity():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -15.0))
    fc.reset(x)
    states, _, _ = fly(fc, x, lambda k: Setpoint(vel_ned_m_s=(3.0, -1.0, 0.0), yaw_rad=0.0), 8.0)
    assert np.allclose(D.vel_ned_m_s(states[-1]), [3.0, -1.0, 0.0], atol=0.05)
    assert fc.pos_integral_m == [0.0, 0.0, 0.0]


def test_mixed_axes_altitude_hold_with_horizontal_velocity():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    sp = Setpoint(pos_ned_m=(np.nan, np.nan, -14.0), vel_ned_m_s=(2.0, 0.0, np.nan), yaw_rad=0.0)
    states, _, _ = fly(fc, x, lambda k: sp, 10.0)
    assert states[-1][16] == pytest.approx(-14.0, abs=0.05)
    assert D.vel_ned_m_s(states[-1])[0] == pytest.approx(2.0, abs=0.05)


def test_yaw_turns_the_short_way_across_pi():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0), yaw_rad=3.0)
    fc.reset(x)
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos_ned_m=(0.0, 0.0, -10.0), yaw_rad=-3.0), 6.0)
    psi = states[:, 13]
    assert np.all(psi >= 2.95)  # went up through pi, never back down through 0
    assert math.remainder(psi[-1] - (-3.0), 2 * math.pi) == pytest.approx(0.0, abs=0.01)


def test_large_heading_step_is_flown_as_a_turn_without_saturating():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    states, max_raw, saturated = fly(fc, x, lambda k: Setpoint(pos_ned_m=(0.0, 0.0, -10.0), yaw_rad=3.0), 6.0)
    assert not saturated and max_raw < 1.0
    assert np.max(np.diff(states[:, 13])) / PHYSICS_DT / 4 <= SETTINGS.max_yaw_rate_rad_s * 1.1
    assert states[-1][13] == pytest.approx(3.0, abs=0.01)
    assert np.max(np.linalg.norm(states[:, 14:17] - [0.0, 0.0, -10.0], axis=1)) < 0.05


def test_yaw_rate_setpoint_integrates_a_heading():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos_ned_m=(0.0, 0.0, -10.0), yaw_rate_rad_s=0.4), 5.0)
    assert states[-1][5] == pytest.approx(0.4, abs=0.03)
    assert states[-1][13] == pytest.approx(2.0, abs=0.15)


def test_speed_is_limited_and_far_targets_are_reached_without_windup():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    target = np.array([120.0, 0.0, -10.0])
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos_ned_m=target, yaw_rad=0.0), 25.0)
    speeds = np.hypot(*np.array([D.vel_ned_m_s(s)[:2] for s in states]).T)
    assert np.max(speeds) <= 12.0 * 1.02
    assert np.max(speeds) > 11.0
    assert np.max(states[:, 14]) < 121.0  # arrives without a large overshoot
    assert abs(states[-1][14] - 120.0) < 0.1


def test_integrators_freeze_while_saturated():
    fc = FlightController(MODEL, ControllerSettings(cmd_accel_xy_m_s2=1000.0, max_speed_xy_m_s=30.0))
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    fc.update(x, Setpoint(pos_ned_m=(25.0, 0.0, -10.0), yaw_rad=0.0), CONTROL_DT)
    assert fc.saturated
    assert np.all(fc.z == 0.0)
    assert np.all(np.abs(fc.delta) <= 1.0)


def test_steady_wind_is_rejected_at_a_position_hold():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL, (0.0, 0.0, -10.0))
    fc.reset(x)
    hold = Setpoint(pos_ned_m=(0.0, 0.0, -10.0), yaw_rad=0.0)
    states, _, saturated = fly(fc, x, lambda k: hold, 25.0, wind=np.array([5.0, 3.0, 0.0]))
    assert not saturated
    assert np.linalg.norm(states[-1][14:17] - [0.0, 0.0, -10.0]) < 0.05


def test_servo_lag_profile_still_flies():
    model = MODEL.replace(servo_tau_s=0.02)
    fc = FlightController(model)
    x = D.hover_state(model, (0.0, 0.0, -10.0))
    fc.reset(x)
    target = np.array([2.0, 0.0, -10.0])
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos_ned_m=target, yaw_rad=0.0), 8.0)
    assert np.linalg.norm(states[-1][14:17] - target) < 0.05


def test_settings_from_dict_name_bad_keys():
    s = ControllerSettings.from_dict({"kp_xy_1_s": 0.8, "max_speed_xy_m_s": 8})
    assert s.kp_xy_1_s == 0.8 and s.max_speed_xy_m_s == 8.0
    with pytest.raises(ControlError, match="control.kp_xyz"):
        ControllerSettings.from_dict({"kp_xyz": 1.0}, prefix="control")
    with pytest.raises(ControlError, match="max_speed_xy_m_s"):
        ControllerSettings.from_dict({"max_speed_xy_m_s": -1.0})
    with pytest.raises(ControlError, match="r_weights"):
        ControllerSettings.from_dict({"r_weights": [1.0, 2.0]})


def test_bad_setpoints_are_rejected_naming_the_field():
    fc = FlightController(MODEL)
    x = D.hover_state(MODEL)
    fc.reset(x)
    with pytest.raises(ControlError, match="setpoint.pos_ned_m"):
        fc.update(x, Setpoint(pos_ned_m=(1.0, np.inf, 0.0)), CONTROL_DT)
    with pytest.raises(ControlError, match="setpoint.vel_ned_m_s"):
        fc.update(x, Setpoint(vel_ned_m_s=(1.0, 2.0)), CONTROL_DT)
    with pytest.raises(ControlError, match="setpoint.yaw_rad"):
        fc.update(x, Setpoint(yaw_rad=float("nan")), CONTROL_DT)


@pytest.mark.parametrize("heading", ["path", "fixed"])
def test_modal_solution_equals_the_stepped_recursion(heading):
    """The modal (lfilter) solution and the per-period recursion are the same linear system.

    A negligible PID integral gain forces the stepped recursion on turning trajectories.
    """
    t = np.arange(0.0, 30.0, CONTROL_DT)
    pos, vel, acc, yaw = circle_reference(t, radius_m=25.0, speed_m_s=6.0, heading=heading)
    fast = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw)
    cl = MODEL.cached(("closed_loop", SETTINGS), lambda: None)
    assert cl is not None and cl.modal is not None
    stepped = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw, ControllerSettings(ki_xy_1_s2=1e-12, ki_z_1_s2=1e-12))
    assert np.max(np.abs(fast.pos_ned_m - stepped.pos_ned_m)) < 1e-5
    assert np.max(np.abs(fast.delta - stepped.delta)) < 1e-5


def test_fast_prediction_with_pid_integrators_agrees_with_the_step_loop():
    settings = ControllerSettings(ki_xy_1_s2=0.1, ki_z_1_s2=0.1, kd_xy=0.2, kd_z=0.2)
    t = np.arange(0.0, 30.0 + CONTROL_DT / 2, CONTROL_DT)
    pos, vel, acc, yaw = circle_reference(t, radius_m=20.0, speed_m_s=5.0)
    fc = FlightController(MODEL, settings)
    x = D.hover_state(MODEL, pos[0], yaw[0])
    fc.reset(x)
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos[k], vel[k], acc[k], yaw[k]), 30.0)
    pred = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw, settings)
    assert np.max(np.linalg.norm(pred.pos_ned_m - states[:, 14:17], axis=1)) < 0.03


@settings(deadline=None, max_examples=50)
@given(
    vel=st.lists(st.floats(-12.0, 12.0), min_size=3, max_size=3),
    acc=st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3),
    rate=st.floats(-1.5, 1.5),
)
def test_feedforward_trim_produces_the_commanded_acceleration(vel, acc, rate):
    """x_ff, delta_ff make the model accelerate exactly as asked, all other states steady."""
    gains = design_lqi(MODEL, CONTROL_DT, SETTINGS.q_weights, SETTINGS.r_weights)
    sol = gains.ff_map @ np.array([*acc, rate, *vel, 0.0])
    x_ff, d_ff = sol[:14], sol[14:]
    xdot = MODEL.A @ x_ff[:13] + MODEL.B @ d_ff
    assert np.allclose(x_ff[:3], vel, atol=1e-9)
    assert np.allclose(xdot[:3], acc, atol=1e-9)
    assert np.allclose(xdot[3:], 0.0, atol=1e-9)
    assert x_ff[5] == pytest.approx(rate, abs=1e-9)


@settings(deadline=None, max_examples=100)
@given(angle=st.floats(-100.0, 100.0))
def test_wrap_pi_keeps_the_direction(angle):
    w = wrap_pi(angle)
    assert -math.pi <= w <= math.pi
    assert math.cos(w) == pytest.approx(math.cos(angle), abs=1e-9)
    assert math.sin(w) == pytest.approx(math.sin(angle), abs=1e-9)


def test_fast_prediction_models_the_servo_lag():
    """With a (long) servo lag the prediction that models it is the closer one."""
    model = MODEL.replace(servo_tau_s=0.1)
    t = np.arange(0.0, 30.0 + CONTROL_DT / 2, CONTROL_DT)
    pos, vel, acc, yaw = circle_reference(t, radius_m=20.0, speed_m_s=6.0, heading="fixed")
    fc = FlightController(model)
    x = D.hover_state(model, pos[0], yaw[0])
    fc.reset(x)
    states, _, _ = fly(fc, x, lambda k: Setpoint(pos[k], vel[k], acc[k], yaw[k]), 30.0)
    lagged = simulate_closed_loop(model, t, pos, vel, acc, yaw)
    ideal = simulate_closed_loop(MODEL, t, pos, vel, acc, yaw)
    gap_lagged = np.max(np.linalg.norm(lagged.pos_ned_m - states[:, 14:17], axis=1))
    gap_ideal = np.max(np.linalg.norm(ideal.pos_ned_m - states[:, 14:17], axis=1))
    assert gap_lagged < 0.01
    assert gap_lagged < gap_ideal
