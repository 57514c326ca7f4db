"""Speed profile under speed, acceleration, lateral-acceleration and jerk limits.

Tolerances on dense samples (every 2 ms of flight): speed, acceleration and jerk 1e-6
relative (they are exact by construction); lateral acceleration 1 % (the curvature is taken on
the profile's arc-length grid, which includes every joint and curvature peak); jerk is measured by finite differences of the along-track
acceleration, which is piecewise linear, so it is exact between kinks.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from smoothing_strategies import polylines

from companion.errors import SmoothingError
from companion.smoothing import TrajectoryLimits, smooth_g1, smooth_g2, time_parameterize
from companion.smoothing.timing import retime

limit_values = st.tuples(st.floats(2.0, 15.0), st.floats(0.5, 4.0), st.floats(0.5, 5.0), st.floats(1.0, 20.0))


def dense_check(traj, limits: TrajectoryLimits, dt=0.002):
    t = np.arange(0.0, traj.duration_s, dt)
    s, v, a = traj.progress(t)
    assert np.all(np.diff(s) >= -1e-9)
    assert np.max(v) <= limits.speed_m_s * (1 + 1e-6)
    assert np.min(v) >= -1e-9
    assert np.max(np.abs(a)) <= limits.accel_m_s2 * (1 + 1e-6)
    jerk = np.diff(a) / dt
    assert np.max(np.abs(jerk)) <= limits.jerk_m_s3 * (1 + 1e-6)
    kappa = traj.curve.curvature(s)
    assert np.max(v**2 * kappa) <= limits.lat_accel_m_s2 * 1.01
    pos, vel, acc = traj.sample(t)
    np.testing.assert_allclose(np.linalg.norm(vel, axis=1), v, atol=1e-9)
    return t, pos, vel, acc


@settings(deadline=None, max_examples=30)
@given(polylines(), st.sampled_from(["g1", "g2", "none"]), limit_values)
def test_limits_never_exceeded_on_dense_samples(path, method, lim):
    limits = TrajectoryLimits(*lim)
    curve = {"g1": lambda: smooth_g1(path), "g2": lambda: smooth_g2(path, 0.1), "none": lambda: path}[method]()
    traj = time_parameterize(curve, limits)
    t, pos, vel, acc = dense_check(traj, limits)
    np.testing.assert_allclose(pos[0], path[0], atol=1e-9)
    np.testing.assert_allclose(traj.end_pos_ned_m, path[-1], atol=1e-9)
    np.testing.assert_allclose(vel[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(traj.sample(traj.duration_s)[1], 0.0, atol=1e-9)


def test_velocity_and_acceleration_are_derivatives():
    path = np.array([[0.0, 0.0, 0.0], [60.0, 0.0, 0.0], [60.0, 50.0, -10.0], [10.0, 80.0, -10.0]])
    traj = time_parameterize(smooth_g2(path, 0.1))
    t = np.linspace(0, traj.duration_s, 20001)
    pos, vel, acc = traj.sample(t)
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(pos, dt, axis=0)[1:-1], vel[1:-1], atol=2e-4)
    np.testing.assert_allclose(np.gradient(vel, dt, axis=0)[1:-1], acc[1:-1], atol=5e-3)


def test_polyline_stops_at_each_corner():
    path = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0]])
    traj = time_parameterize(path)
    t_corner = traj.time_at_s([30.0])[0]
    pos, vel, acc = traj.sample(t_corner)
    np.testing.assert_allclose(pos, [30.0, 0.0], atol=1e-6)
    assert np.linalg.norm(vel) < 1e-3
    dense_check(traj, traj.limits)


def test_cruise_reaches_speed_limit_on_a_long_line():
    traj = time_parameterize(np.array([[0.0, 0.0], [500.0, 0.0]]))
    _, v, _ = traj.progress(np.array([traj.duration_s / 2]))
    assert v[0] == pytest.approx(8.0)
    # rest-to-rest on a line: 500 m at 8 m/s plus the ramps (v/a + a/j each)
    assert traj.duration_s == pytest.approx(500 / 8 + 8 / 2 + 2 / 3, rel=0.02)


def test_corner_speed_respects_lateral_acceleration():
    path = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 200.0]])
    curve = smooth_g2(path, 0.1)
    traj = time_parameterize(curve)
    s_joint = curve.piece_start_s[2]  # peak curvature 0.1
    _, v, _ = traj.progress(traj.time_at_s([s_joint]))
    assert v[0] <= np.sqrt(2.5 / curve.max_curvature_1_m) * 1.001
    assert v[0] >= 0.9 * np.sqrt(2.5 / 0.1)


def test_start_and_end_speeds_for_splicing():
    curve = smooth_g2(np.array([[0.0, 0.0], [100.0, 0.0], [150.0, 60.0]]), 0.1)
    traj = time_parameterize(curve, start_speed_m_s=6.0, end_speed_m_s=3.0)
    pos, vel, acc = traj.sample(np.array([0.0, traj.duration_s]))
    np.testing.assert_allclose(vel[0], [6.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(acc[0], 0.0, atol=1e-9)
    assert np.linalg.norm(vel[1]) == pytest.approx(3.0)
    np.testing.assert_allclose(pos[1], [150.0, 60.0], atol=1e-9)
    dense_check(traj, traj.limits)
    assert not traj.notes


def test_yaw_follows_tangent_or_holds():
    path = np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 50.0]])
    traj = time_parameterize(smooth_g2(path, 0.1))
    yaw = traj.yaw_rad(np.array([0.5, traj.duration_s - 0.5]))
    np.testing.assert_allclose(yaw, [0.0, np.pi / 2], atol=1e-9)
    held = time_parameterize(smooth_g2(path, 0.1), yaw_mode="hold", yaw_hold_rad=1.0)
    np.testing.assert_allclose(held.yaw_rad(np.array([0.0, 10.0])), 1.0)
    t = np.linspace(0.0, traj.duration_s, 4001)
    rate = traj.yaw_rate_rad_s(t)
    fd = np.gradient(np.unwrap(traj.yaw_rad(t)), t)
    np.testing.assert_allclose(rate[1:-1], fd[1:-1], atol=2e-3)


def test_vertical_segment_holds_last_heading():
    path = np.array([[0.0, 0.0, 0.0], [0.0, 30.0, 0.0], [0.0, 30.0, -30.0]])
    traj = time_parameterize(path)
    np.testing.assert_allclose(traj.yaw_rad(np.array([traj.duration_s])), np.pi / 2, atol=1e-9)


def test_2d_lifted_to_ned():
    traj = time_parameterize(np.array([[0.0, 0.0], [30.0, 40.0]])).to_ned(-25.0)
    pos, vel, acc = traj.sample(np.array([0.0, 3.0]))
    assert pos.shape == (2, 3) and traj.d == 3
    np.testing.assert_allclose(pos[:, 2], -25.0)
    np.testing.assert_allclose(vel[:, 2], 0.0)
    np.testing.assert_allclose(traj.end_pos_ned_m, [30.0, 40.0, -25.0], atol=1e-9)


def test_stretched_limits_scale_time_exactly():
    curve = smooth_g2(np.array([[0.0, 0.0], [80.0, 0.0], [80.0, 60.0]]), 0.1)
    base = time_parameterize(curve)
    slow = retime(base, base.limits.stretched(2.0))
    scaled = base.time_scaled(2.0)
    assert slow.duration_s == pytest.approx(2.0 * base.duration_s, rel=1e-6)
    assert scaled.duration_s == pytest.approx(2.0 * base.duration_s, rel=1e-12)
    t = np.linspace(0, base.duration_s, 50)
    for other in (slow, scaled):
        pos, vel, acc = other.sample(2.0 * t)
        p0, v0, a0 = base.sample(t)
        np.testing.assert_allclose(pos, p0, atol=1e-6)
        np.testing.assert_allclose(vel, v0 / 2.0, atol=1e-6)
        np.testing.assert_allclose(acc, a0 / 4.0, atol=1e-6)
    assert scaled.limits == base.limits.stretched(2.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"speed_m_s": 0.0}, "limits.speed_m_s"),
        ({"accel_m_s2": -1.0}, "limits.accel_m_s2"),
        ({"lat_accel_m_s2": float("nan")}, "limits.lat_accel_m_s2"),
        ({"jerk_m_s3": 0.0}, "limits.jerk_m_s3"),
    ],
)
def test_bad_limits(kwargs, match):
    with pytest.raises(SmoothingError, match=match):
        TrajectoryLimits(**kwargs)


def test_bad_timing_arguments():
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    with pytest.raises(SmoothingError, match="start_speed_m_s"):
        time_parameterize(line, start_speed_m_s=-1.0)
    with pytest.raises(SmoothingError, match="end_speed_m_s"):
        time_parameterize(line, end_speed_m_s=100.0)
    with pytest.raises(SmoothingError, match="limits"):
        time_parameterize(line, {"speed_m_s": 3})
    with pytest.raises(SmoothingError, match="curve"):
        time_parameterize(np.array([[0.0, 0.0]]))
    with pytest.raises(SmoothingError, match="grid_step_m"):
        time_parameterize(line, grid_step_m=0.0)
