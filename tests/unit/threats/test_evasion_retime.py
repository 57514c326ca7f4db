"""Escape manoeuvres and retimed references: feasible, continuous, ending where they say."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.decision.evasion import EscapeLimits, escape_library
from companion.threats.decision.retime import RetimedTrajectory, ramp_time_s
from companion.world import World

LIM = EscapeLimits(speed_m_s=5.0, accel_m_s2=2.5, climb_m_s=2.5, descent_m_s=1.5, vertical_accel_m_s2=1.5)
vel = st.floats(-6.0, 6.0, allow_nan=False)


@settings(max_examples=20, deadline=None)
@given(st.tuples(vel, vel, st.floats(-1.0, 1.0)))
def test_every_manoeuvre_starts_at_the_state_respects_the_limits_and_ends_in_a_hover(v0):
    p0 = np.array([10.0, -5.0, -20.0])
    lib = escape_library(p0, np.array(v0), LIM, vertical=True)
    for i in range(0, len(lib), 7):
        m = lib.manoeuvre(i, 0.3)
        t = np.linspace(0.0, m.duration_s + 2.0, 800)
        pos, v, acc = m.sample(t)
        np.testing.assert_allclose(pos[0], p0, atol=1e-9)
        np.testing.assert_allclose(v[0], v0, atol=1e-9)
        assert np.all(np.linalg.norm(acc[:, :2], axis=1) <= LIM.accel_m_s2 + 1e-6)
        assert np.all(np.abs(acc[:, 2]) <= LIM.vertical_accel_m_s2 + 1e-6)
        np.testing.assert_allclose(v[-1], 0.0, atol=1e-9)
        np.testing.assert_allclose(pos[-1], m.end_pos_ned_m, atol=1e-6)
        # velocity is the derivative of position
        num = np.gradient(pos, t, axis=0)
        assert np.max(np.abs(num[5:-5] - v[5:-5])) < 0.2
    # the vectorised positions agree with each manoeuvre's own sampling
    t = np.linspace(0.0, 12.0, 61)
    batch, dur = lib.positions(t)
    for i in (0, 5, len(lib) - 1):
        np.testing.assert_allclose(batch[i], lib.manoeuvre(i, 0.0).sample(t)[0], atol=1e-9)


def test_library_has_the_ap_avoidance_repertoire():
    lib = escape_library(np.zeros(3), np.array([6.0, 0.0, 0.0]), LIM, vertical=True)
    labels = set(lib.labels)
    for name in ("brake", "left", "right", "climb", "descend", "back", "left + climb", "right + descend"):
        assert name in labels
    flat = escape_library(np.zeros(2), np.array([6.0, 0.0]), LIM, vertical=False)
    assert not any("climb" in lab for lab in flat.labels)
    # right of a north-bound vehicle is east
    i = lib.labels.index("right")
    assert lib.targets[i][1] > 0 and abs(lib.targets[i][0]) < 1e-9


def test_brake_stops_at_the_deceleration_limit():
    lib = escape_library(np.zeros(2), np.array([5.0, 0.0]), LIM, vertical=False)
    brake = lib.manoeuvre(0, 0.0)
    assert brake.duration_s == pytest.approx(5.0 / 2.5)
    assert brake.end_pos_ned_m[0] == pytest.approx(5.0**2 / (2 * 2.5))


@pytest.fixture(scope="module")
def base():
    world = World([], [-10.0, -10.0], [120.0, 60.0])
    path = np.array([[0.0, 0.0], [50.0, 0.0], [90.0, 40.0]])
    return time_parameterize(smooth_g2(path, 0.1, world=world), TrajectoryLimits(speed_m_s=6.0))


@pytest.mark.parametrize("rate,wait", [(0.0, 0.0), (0.0, 4.0), (0.4, 3.0), (0.0, 30.0)])
def test_retime_is_continuous_stays_on_the_path_and_arrives_later(base, rate, wait):
    tau0 = 5.0
    speed = float(np.linalg.norm(base.sample(np.array([tau0]))[1][0]))
    r = RetimedTrajectory(base, tau0, rate, wait, ramp_time_s(rate, 6.0, 2.5))
    p, v, a = r.sample(np.array([0.0]))
    bp, bv, _ = base.sample(np.array([tau0]))
    np.testing.assert_allclose(p, bp, atol=1e-9)
    np.testing.assert_allclose(v, bv, atol=1e-9)
    assert r.delay_s >= (1.0 - rate) * wait - 1e-6
    np.testing.assert_allclose(r.end_pos_ned_m, base.end_pos_ned_m, atol=1e-9)
    t = np.linspace(0.0, r.duration_s, 3000)
    pos, vel, acc = r.sample(t)
    # on the base path: every point is a base point
    dense = base.sample(np.linspace(0.0, base.duration_s, 20000))[0]
    gap = np.min(np.linalg.norm(pos[:, None, :] - dense[None, ::4, :], axis=2), axis=1)
    assert gap.max() < 0.1
    # along-track deceleration within the retime limit (plus the base's own acceleration)
    along = np.einsum("ij,ij->i", acc, vel) / np.maximum(np.linalg.norm(vel, axis=1), 1e-6)
    assert along.min() > -(2.5 + 2.0 + 0.2)
    assert speed > 1.0
    if rate == 0.0 and wait > 0:
        stopped = np.linalg.norm(vel, axis=1) < 1e-6
        assert stopped.any()


def test_refined_variants_stay_within_the_limits_and_around_their_parents():
    lib = escape_library(np.array([0.0, 0.0, -20.0]), np.array([6.0, 1.0, 0.0]), LIM, vertical=True)
    parents = [3, 40]
    refined = lib.refined(parents)
    assert len(refined) == len(parents) * 7 * 3 * 3
    for i in range(0, len(refined), 5):
        m = refined.manoeuvre(i, 0.0)
        t = np.linspace(0.0, m.duration_s, 300)
        pos, v, acc = m.sample(t)
        np.testing.assert_allclose(v[0], [6.0, 1.0, 0.0], atol=1e-9)
        assert np.all(np.linalg.norm(acc[:, :2], axis=1) <= LIM.accel_m_s2 + 1e-6)
        assert np.linalg.norm(refined.targets[i][:2]) <= LIM.speed_m_s + 1e-9 or any(
            np.allclose(refined.targets[i][:2], lib.targets[p][:2]) for p in parents
        )
    assert all(label.endswith("(refined)") for label in refined.labels)
