"""Closed-loop feasibility on the default helicopter model, and duration stretching."""

import numpy as np
import pytest

from companion.errors import SmoothingError
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.smoothing.feasibility import FeasibilityChecker, check_and_stretch
from companion.smoothing.settings import FeasibilitySettings
from heli_model.model import HeliModel

PATH = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 60.0], [0.0, 80.0], [-20.0, 20.0]])


@pytest.fixture(scope="module")
def checker():
    return FeasibilityChecker(HeliModel.default())


def test_default_limits_are_feasible_with_margin(checker):
    traj = time_parameterize(smooth_g2(PATH, 0.1))
    report = checker.check_and_stretch(traj)
    assert report.feasible and report.stretch == 1.0 and report.attempts == 1
    assert report.trajectory is traj
    assert report.max_abs_delta < 0.8 and report.delta_margin > 0
    assert report.max_tracking_error_m < 2.0 and report.error_margin_m > 0
    assert not report.saturated and report.reason == ""


def test_aggressive_trajectory_saturates_and_stretching_removes_it(checker):
    aggressive = TrajectoryLimits(speed_m_s=15.0, accel_m_s2=5.0, lat_accel_m_s2=6.0, jerk_m_s3=20.0)
    traj = time_parameterize(smooth_g2(PATH, 0.1), aggressive)
    plain = checker.check(traj)
    assert not plain.feasible and plain.saturated and "saturate" in plain.reason
    report = checker.check_and_stretch(traj)
    assert report.initial_max_abs_delta > 1.0
    assert report.feasible and not report.saturated
    assert report.stretch > 1.0 and report.attempts > 1
    assert report.trajectory.duration_s == pytest.approx(report.stretch * traj.duration_s)
    assert report.max_abs_delta <= 0.8
    # the stretched trajectory is the same path, flown slower
    np.testing.assert_allclose(report.trajectory.end_pos_ned_m, traj.end_pos_ned_m, atol=1e-9)
    again = checker.check(report.trajectory)
    assert again.feasible and again.max_abs_delta == pytest.approx(report.max_abs_delta)


def test_gives_up_and_says_why(checker):
    wild = TrajectoryLimits(speed_m_s=30.0, accel_m_s2=20.0, lat_accel_m_s2=20.0, jerk_m_s3=200.0)
    traj = time_parameterize(smooth_g2(PATH, 0.5), wild)
    settings = FeasibilitySettings(max_stretch=1.2)
    report = FeasibilityChecker(checker.model, settings).check_and_stretch(traj)
    assert not report.feasible and report.reason
    assert report.stretch <= 1.2


def test_3d_trajectory_and_yaw_rate_feedforward_matters(checker):
    path3 = np.array([[0.0, 0.0, -10.0], [50.0, 0.0, -15.0], [50.0, 40.0, -20.0]])
    traj = time_parameterize(smooth_g2(path3, 0.1))
    with_ff = checker.check(traj)
    without = FeasibilityChecker(checker.model, FeasibilitySettings(yaw_rate_feedforward=False)).check(traj)
    assert with_ff.feasible
    assert without.max_abs_delta > with_ff.max_abs_delta


def test_reference_stream_shapes(checker):
    traj = time_parameterize(smooth_g2(PATH, 0.1))
    t, pos, vel, acc, yaw, rate = checker.reference(traj)
    assert pos.shape == (t.size, 3) and yaw.shape == (t.size,)
    assert np.all(np.diff(t) > 0)
    assert t[-1] == pytest.approx(traj.duration_s + 2.0, abs=0.03)
    np.testing.assert_allclose(pos[:, 2], -20.0)


def test_bad_arguments():
    with pytest.raises(SmoothingError, match="trajectory"):
        check_and_stretch("not a trajectory", model=HeliModel.default())
    with pytest.raises(SmoothingError, match="feasibility.stretch_step"):
        FeasibilitySettings(stretch_step=1.0)
    with pytest.raises(SmoothingError, match="feasibility.max_abs_delta"):
        FeasibilitySettings(max_abs_delta=0.0)
