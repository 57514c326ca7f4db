"""Threat manager decisions (DESIGN section 7) on constructed encounters."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.manager import (HOVER_SPEED_M_S, Alternative, ReferenceState, ThreatManager, ThreatManagerError,
                                       first_conflict, join_trajectory, min_separation_m,
                                       threat_obstacles)
from companion.threats.model import Threat
from companion.threats.settings import ThreatSettings
from companion.world import World

GOAL = np.array([200.0, 0.0])
LIMITS = TrajectoryLimits(speed_m_s=5.0)
DETOUR = np.array([[0.0, 0.0], [30.0, 0.0], [60.0, 25.0], [170.0, 25.0], [200.0, 0.0]])


def straight_leg():
    world = World([], [-10.0, -50.0], [210.0, 50.0])
    traj = time_parameterize(smooth_g2(np.array([[0.0, 0.0], GOAL]), 0.1), LIMITS)
    return world, traj


def manager(world, traj, **kw):
    m = ThreatManager(world, GOAL, limits=LIMITS, rng=np.random.default_rng(0), **kw)
    m.set_active(traj, 0.0, "leg0")
    return m


def state(traj, t_s):
    p, v, _ = traj.sample(np.array([t_s]))
    return p[0], v[0]


def assert_continuous(decision, traj, t_s):
    p_old, v_old = state(traj, t_s)
    p_new, v_new = state(decision.trajectory, 0.0)
    assert np.linalg.norm(p_new - p_old) < 1e-6
    assert np.linalg.norm(v_new - v_old) < 0.15


def popup(tid, pos, radius=6.0, t=0.0):
    return Threat(tid, "popup", "local_ned", (pos[0], pos[1], 0.0), radius_m=radius, received_t_s=t)


def test_no_conflict_gives_none():
    world, traj = straight_leg()
    m = manager(world, traj)
    d = m.on_threats([popup("off", (100.0, 40.0))], 3.0)
    assert d.kind == "none" and d.trajectory is None


def test_far_popup_gives_replan_clear_and_continuous():
    world, traj = straight_leg()
    m = manager(world, traj)
    threats = [popup("p1", (150.0, 0.0), t=5.0)]
    d = m.on_threats(threats, 5.0)
    assert d.kind == "replan", d.reason
    assert d.conflict.threat_id == "p1" and d.conflict.time_to_conflict_s > m.replan_estimate_s
    assert_continuous(d, traj, 5.0)
    sep = min_separation_m(d.trajectory, 5.0, 5.0, 5.0 + d.trajectory.duration_s, threats, dim=2)
    assert sep >= m.settings.inflation_m - 0.05
    np.testing.assert_allclose(d.trajectory.end_pos_ned_m, GOAL, atol=1e-6)
    assert m.active_path_id == d.path_id and d.plan_ms > 0 and d.decide_ms >= d.plan_ms
    assert m.on_threats(threats, 6.0).kind == "none"


def test_close_moving_threat_gives_switch_without_jump():
    """Paper Fig. 8: an obstacle moving at sqrt(2) m/s met within 15 m, 2.3 s ahead."""
    world, traj = straight_leg()
    m = manager(world, traj)
    m.set_alternatives([np.array([[0.0, 0.0], GOAL]), DETOUR])
    t = 8.0
    p, _ = state(traj, t)
    threats = [Threat("m1", "moving", "local_ned", (p[0] + 15.0, 2.0, 0.0), (0.0, -math.sqrt(2), 0.0),
                      2.0, None, t)]
    d = m.on_threats(threats, t)
    assert d.kind == "switch", d.reason
    assert d.conflict.time_to_conflict_s <= m.replan_estimate_s + m.settings.replan_margin_s
    assert d.path_id == "alt1"
    assert_continuous(d, traj, t)
    sep = min_separation_m(d.trajectory, t, t, t + d.trajectory.duration_s, threats, dim=2)
    assert sep >= m.settings.inflation_m - 0.05


def test_nothing_safe_gives_hold_then_resume():
    world, traj = straight_leg()
    m = manager(world, traj)
    t = 8.0
    p, _ = state(traj, t)
    threats = [popup("wall", (p[0] + 16.0, 0.0), radius=4.0, t=t)]
    d = m.on_threats(threats, t)
    assert d.kind == "hold" and d.resume
    assert_continuous(d, traj, t)
    _, v_end = state(d.trajectory, d.trajectory.duration_s)
    assert np.linalg.norm(v_end) < 1e-6
    # the vehicle stops short of the inflated threat
    sep = min_separation_m(d.trajectory, t, t, t + d.trajectory.duration_s + 5.0, threats, dim=2)
    assert sep > 0.0
    r = m.on_threats(threats, t + d.trajectory.duration_s + 1.0)
    assert r.kind == "replan", r.reason
    sep = min_separation_m(r.trajectory, r.start_t_s, r.start_t_s, r.start_t_s + r.trajectory.duration_s,
                           threats, dim=2)
    assert sep >= m.settings.inflation_m - 0.05


def test_single_strategy_modes():
    world, traj = straight_leg()
    threats = [popup("p1", (150.0, 0.0), t=5.0)]
    m = manager(world, traj, mode="switch")
    m.set_alternatives([DETOUR])
    assert m.on_threats(threats, 5.0).kind in ("switch", "hold")
    m = manager(world, traj, mode="replan")
    assert m.on_threats(threats, 5.0).kind == "replan"
    with pytest.raises(ThreatManagerError, match="mode"):
        manager(world, traj, mode="pray")


def test_replan_estimate_follows_measurements():
    world, traj = straight_leg()
    m = manager(world, traj, settings=ThreatSettings(replan_budget_s=5.0))
    before = m.replan_estimate_s
    m.on_threats([popup("p1", (150.0, 0.0), t=5.0)], 5.0)
    assert m.replan_estimate_s < before


def test_first_conflict_in_space_and_time():
    world, traj = straight_leg()
    # crosses the path at x = 50 m at t = 20 s, when the vehicle is far past (it is there at ~11 s)
    late = Threat("late", "moving", "local_ned", (50.0, -20.0, 0.0), (0.0, 1.0, 0.0), 2.0, None, 0.0)
    assert first_conflict(traj, 0.0, 0.0, 30.0, [late], inflation_m=1.0, dim=2) is None
    on_time = Threat("on", "moving", "local_ned", (50.0, -11.0, 0.0), (0.0, 1.0, 0.0), 2.0, None, 0.0)
    c = first_conflict(traj, 0.0, 0.0, 30.0, [late, on_time], inflation_m=1.0, dim=2)
    assert c is not None and c.threat_id == "on" and 5.0 < c.t_s < 15.0


def test_threat_obstacles_sweep_and_keep_free():
    moving = Threat("m", "moving", "local_ned", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0, None, 0.0)
    obs = threat_obstacles([moving], 0.0, inflation_m=1.0, sweep_s=10.0, dim=3, keep_free=[])
    centers = np.array([o.center_m for o in obs])
    assert len(obs) >= 7 and centers[:, 0].min() == 0.0 and centers[:, 0].max() == pytest.approx(10.0)
    kept = threat_obstacles([moving], 0.0, inflation_m=1.0, sweep_s=10.0, dim=3,
                            keep_free=[np.array([0.0, 0.0, 0.0])])
    assert all(np.linalg.norm(o.center_m) > 3.0 for o in kept)


def test_alternative_entries_cover_the_path():
    alt = Alternative.from_path("a", DETOUR, spacing_m=2.0)
    gaps = np.linalg.norm(np.diff(alt.entry_pos_ned_m, axis=0), axis=1)
    assert gaps.max() <= 2.0 + 1e-9
    total = np.sum(np.linalg.norm(np.diff(DETOUR, axis=0), axis=1))
    assert alt.entry_remaining_m[0] == pytest.approx(total)
    nodes = alt.nodes_from(0)
    np.testing.assert_allclose(nodes[-1], DETOUR[-1])
    assert all(any(np.linalg.norm(nodes - p, axis=1) < 1e-9) for p in DETOUR)


@settings(deadline=None, max_examples=15)
@given(st.floats(0.0, 5.0), st.floats(-math.pi, math.pi), st.floats(-0.6 * math.pi, 0.6 * math.pi))
def test_join_starts_at_the_reference_state(speed, heading, turn):
    """Whatever the current speed and the direction of the target, no setpoint jump."""
    world = World([], [-200.0, -200.0], [200.0, 200.0])
    u = np.array([math.cos(heading), math.sin(heading)])
    ref = ReferenceState(0.0, np.zeros(2), speed * u, np.zeros(2))
    w = np.array([math.cos(heading + turn), math.sin(heading + turn)])
    nodes = np.array([60.0 * w, 60.0 * w + 80.0 * u])
    traj, poly = join_trajectory(ref, nodes, world=world, limits=LIMITS, kappa_max_1_m=0.1)
    assert traj is not None, poly
    p, v = state(traj, 0.0)
    assert np.linalg.norm(p) < 1e-9
    assert np.linalg.norm(v - speed * u) <= max(0.02 * speed + 0.06, HOVER_SPEED_M_S)
    np.testing.assert_allclose(traj.end_pos_ned_m, nodes[-1], atol=1e-6)
