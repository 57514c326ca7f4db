"""companion.flight.trajectory.Trajectory: sampling by time, shapes, errors, derived trajectories."""

import numpy as np
import pytest

from companion.errors import TrajectoryError
from companion.flight.trajectory import RawProfile, Trajectory
from companion.smoothing import smooth_g2, time_parameterize

PATH = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 30.0]])


@pytest.fixture(scope="module")
def traj():
    return time_parameterize(smooth_g2(PATH, 0.1))


def test_scalar_and_batch_shapes(traj):
    pos, vel, acc = traj.sample(1.0)
    assert pos.shape == vel.shape == acc.shape == (2,)
    pos, vel, acc = traj.sample(np.linspace(0, 5, 7))
    assert pos.shape == (7, 2)
    assert np.ndim(traj.yaw_rad(1.0)) == 0 and traj.yaw_rad(np.zeros(3)).shape == (3,)


def test_times_outside_are_clipped_to_the_ends(traj):
    pos, vel, _ = traj.sample(np.array([-5.0, traj.duration_s + 10.0]))
    np.testing.assert_allclose(pos, [PATH[0], PATH[-1]], atol=1e-9)
    np.testing.assert_allclose(vel, 0.0, atol=1e-9)


def test_progress_is_monotone_and_time_at_s_inverts_it(traj):
    t = np.linspace(0, traj.duration_s, 500)
    s = traj.s_at(t)
    assert np.all(np.diff(s) >= -1e-12)
    assert s[0] == pytest.approx(0.0, abs=1e-12) and s[-1] == pytest.approx(traj.length_m)
    targets = np.array([1.0, 20.0, traj.length_m - 1.0])
    np.testing.assert_allclose(traj.s_at(traj.time_at_s(targets)), targets, atol=1e-6)


def test_nan_time_raises(traj):
    with pytest.raises(TrajectoryError, match="t_s"):
        traj.sample(np.array([0.0, np.nan]))


def test_lifting_rules(traj):
    lifted = traj.to_ned(-30.0)
    with pytest.raises(TrajectoryError, match="to_ned"):
        lifted.to_ned(-10.0)
    with pytest.raises(TrajectoryError, match="down_m"):
        traj.to_ned(float("nan"))
    assert lifted.duration_s == traj.duration_s and lifted.length_m == traj.length_m
    np.testing.assert_allclose(lifted.start_pos_ned_m, [0.0, 0.0, -30.0])


def test_bad_yaw_mode_and_time_scale(traj):
    with pytest.raises(TrajectoryError, match="yaw_mode"):
        Trajectory(traj.curve, traj.profile, traj.limits, 0.0, 1.0, yaw_mode="spin")
    with pytest.raises(TrajectoryError, match="factor"):
        traj.time_scaled(0.0)


def test_raw_profile_box_filter_closed_form():
    # one constant-acceleration interval: s = t^2 / 2 on [0, 2], then speed 2 forever
    prof = RawProfile(
        tau_s=np.array([0.0, 2.0]),
        s_m=np.array([0.0, 2.0]),
        v_m_s=np.array([0.0, 2.0]),
        a_m_s2=np.array([1.0]),
        window_s=1.0,
        start_speed_m_s=0.0,
        end_speed_m_s=2.0,
    )
    s, v, a = prof.filtered(np.array([1.0, 5.0]))
    # window [0.5, 1.5]: mean of t^2/2 is (1.5^3 - 0.5^3) / 6
    np.testing.assert_allclose(s, [(1.5**3 - 0.5**3) / 6.0, 2.0 + 2.0 * 3.0], atol=1e-12)
    np.testing.assert_allclose(v, [1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(a, [1.0, 0.0], atol=1e-12)
