"""Splicing from the current reference state onto a path without a setpoint jump."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import SmoothingError
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.smoothing.splice import join_from_state, lead_in_length
from companion.world import World


@settings(deadline=None, max_examples=25)
@given(st.floats(0.0, 8.0), st.floats(-np.pi, np.pi), st.floats(-60, 60), st.floats(-60, 60), st.sampled_from([2, 3]))
def test_join_is_continuous_in_position_and_velocity(speed, heading, tn, te, d):
    pos = np.zeros(d)
    vel = np.zeros(d)
    vel[0], vel[1] = speed * np.cos(heading), speed * np.sin(heading)
    target = np.zeros(d)
    target[0], target[1] = 80.0 + tn, 40.0 + te
    path = np.array([target, target + np.r_[30.0, 0.0, np.zeros(d - 2)]])
    traj = join_from_state(pos, vel, path)
    p0, v0, a0 = traj.sample(0.0)
    np.testing.assert_allclose(p0, pos, atol=1e-9)
    if speed >= 0.05:
        np.testing.assert_allclose(v0, vel, atol=1e-6)
        assert np.linalg.norm(a0) < 1e-6
    np.testing.assert_allclose(traj.end_pos_ned_m, path[-1], atol=1e-9)
    t = np.arange(0.0, traj.duration_s, 0.01)
    _, v, a = traj.progress(t)
    assert np.max(v) <= 8.0 * (1 + 1e-6) and np.max(np.abs(a)) <= 2.0 * (1 + 1e-6)


def test_splice_from_a_running_trajectory():
    active = time_parameterize(smooth_g2(np.array([[0.0, 0.0], [200.0, 0.0]]), 0.1))
    t_switch = active.duration_s / 2
    pos, vel, acc = active.sample(t_switch)
    alternative = np.array([[150.0, 40.0], [200.0, 60.0]])
    new = join_from_state(pos, vel, alternative, acc=acc)
    p0, v0, _ = new.sample(0.0)
    np.testing.assert_allclose(p0, pos, atol=1e-9)
    np.testing.assert_allclose(v0, vel, atol=1e-6)
    assert not new.notes
    assert new.curve.kappa_ok


def test_lead_in_covers_braking_and_corner():
    lim = TrajectoryLimits()
    slow = lead_in_length(2.0, np.pi / 2, 0.1, lim)
    fast = lead_in_length(8.0, np.pi / 2, 0.1, lim)
    assert fast > slow > 15.8            # 15.88 m: the 90 deg corner at K_max 0.1


def test_blocked_lead_in_is_shortened():
    world = World.from_spheres(np.array([[30.0, 0.0]]), np.array([3.0]), [-100, -100], [200, 200])
    traj = join_from_state([0.0, 0.0], [6.0, 0.0], np.array([[20.0, 40.0], [60.0, 60.0]]), world=world)
    s = np.linspace(0, traj.length_m, 4000)
    assert np.all(world.is_free(traj.curve.evaluate(s)))
    v0 = traj.sample(0.0)[1]
    assert v0[1] == pytest.approx(0.0, abs=1e-9) and v0[0] > 0         # same direction
    if abs(v0[0] - 6.0) > 1e-6:                                         # slower only if said so
        assert any("start speed" in n for n in traj.notes)


def test_too_fast_start_is_noted_not_refused():
    traj = join_from_state([0.0, 0.0], [9.0, 0.0], np.array([[150.0, 20.0]]))
    assert any("above the speed limit" in n for n in traj.notes)
    np.testing.assert_allclose(traj.sample(0.0)[1], [8.0, 0.0], atol=1e-6)


def test_bad_state():
    with pytest.raises(SmoothingError, match="pos"):
        join_from_state([0.0, np.nan], [1.0, 0.0], np.array([[10.0, 0.0]]))
    with pytest.raises(SmoothingError, match="vel"):
        join_from_state([0.0, 0.0], [1.0, 0.0, 0.0], np.array([[10.0, 0.0]]))
    with pytest.raises(SmoothingError, match="path"):
        join_from_state([0.0, 0.0], [1.0, 0.0], np.zeros((0, 2)))
