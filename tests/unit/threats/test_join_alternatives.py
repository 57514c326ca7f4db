"""Joins and alternatives (the one splice, M-GART switching targets) and the replan estimate."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.pipeline import TrajectoryPipeline
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.decision.alternatives import Alternative, switch_candidates
from companion.threats.decision.join import HOVER_SPEED_M_S, join_trajectory
from companion.threats.decision.step import (
    ActiveTrajectory,
    DecisionPolicy,
    DecisionState,
    LegContext,
    Observation,
    decide,
)
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


def state(traj, t_s):
    p, v, _ = traj.sample(np.array([t_s]))
    return p[0], v[0]


def test_replan_estimate_follows_measurements():
    world, traj = straight_leg()
    policy = DecisionPolicy(ThreatSettings(replan_budget_s=5.0), TrajectoryPipeline.for_limits(LIMITS))
    far = Threat("p1", "popup", "local_ned", (90.0, 0.0, 0.0), radius_m=6.0, received_t_s=5.0)
    _, state = decide(
        DecisionState.initial(policy, 0),
        Observation(5.0, (far,), ActiveTrajectory(traj, 0.0, "leg0")),
        LegContext(0, world, GOAL),
        policy,
    )
    assert state.replan_estimate_s < 5.0


def test_alternative_entries_cover_the_path():
    alt = Alternative.from_path("a", DETOUR, spacing_m=2.0)
    gaps = np.linalg.norm(np.diff(alt.entry_pos_ned_m, axis=0), axis=1)
    assert gaps.max() <= 2.0 + 1e-9
    total = np.sum(np.linalg.norm(np.diff(DETOUR, axis=0), axis=1))
    assert alt.entry_remaining_m[0] == pytest.approx(total)
    nodes = alt.nodes_from(0)
    np.testing.assert_allclose(nodes[-1], DETOUR[-1])
    assert all(any(np.linalg.norm(nodes - p, axis=1) < 1e-9) for p in DETOUR)


def test_switch_candidates_are_in_range_cheapest_first_and_diverse():
    near = Alternative.from_path("near", DETOUR, spacing_m=2.0)
    other = Alternative.from_path("other", DETOUR * [1.0, -1.0], spacing_m=2.0)
    picked = switch_candidates([near, other], np.array([10.0, 0.0]), 20.0, 2.0)
    assert {c[1].path_id for c in picked[:2]} == {"near", "other"}  # one of each first
    for _cost, alt, i in picked:
        assert np.linalg.norm(alt.entry_pos_ned_m[i] - [10.0, 0.0]) <= 20.0
    costs = [c[0] for c in picked if c[1].path_id == "near"]
    assert costs == sorted(costs)


@settings(deadline=None, max_examples=15)
@given(st.floats(0.0, 5.0), st.floats(-math.pi, math.pi), st.floats(-0.6 * math.pi, 0.6 * math.pi))
def test_join_starts_at_the_reference_state(speed, heading, turn):
    """Whatever the current speed and the direction of the target, no setpoint jump."""
    world = World([], [-200.0, -200.0], [200.0, 200.0])
    u = np.array([math.cos(heading), math.sin(heading)])
    w = np.array([math.cos(heading + turn), math.sin(heading + turn)])
    nodes = np.array([60.0 * w, 60.0 * w + 80.0 * u])
    traj, poly = join_trajectory(
        np.zeros(2), speed * u, nodes, world=world, pipeline=TrajectoryPipeline.for_limits(LIMITS, 0.1)
    )
    assert traj is not None, poly
    p, v = state(traj, 0.0)
    assert np.linalg.norm(p) < 1e-9
    assert np.linalg.norm(v - speed * u) <= max(0.02 * speed + 0.06, HOVER_SPEED_M_S)
    np.testing.assert_allclose(traj.end_pos_ned_m, nodes[-1], atol=1e-6)


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.tuples(st.integers(-5, 5), st.integers(-5, 5)), min_size=1, max_size=12),
    st.lists(st.integers(0, 3), min_size=12, max_size=12),
)
def test_clean_nodes_keeps_the_path_and_its_corners(steps, repeats):
    """Repeated and collinear nodes go; the ends, every corner and so the polyline itself stay."""
    from companion.threats.decision.join import _clean_nodes

    nodes = [np.zeros(2)]
    for (dx, dy), rep in zip(steps, repeats):
        nodes.extend([nodes[-1] + (dx, dy)] + [nodes[-1] + (dx, dy)] * rep)
    nodes = np.asarray(nodes, float)
    out = _clean_nodes(nodes)
    assert np.array_equal(out[0], nodes[0]) and np.array_equal(out[-1], nodes[-1])
    assert out.shape[0] == 1 or np.all(np.linalg.norm(np.diff(out, axis=0), axis=1) > 0.05)
    for p in nodes:  # every input node lies on the cleaned polyline
        a, b = out[:-1], out[1:]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0, 1)
        gap = np.linalg.norm(a + t[:, None] * ab - p, axis=1).min() if out.shape[0] > 1 else np.linalg.norm(p - out[0])
        assert gap < 1e-9
    seg = np.diff(out, axis=0)
    if seg.shape[0] > 1:  # no interior node left on a straight line
        cross = seg[:-1, 0] * seg[1:, 1] - seg[:-1, 1] * seg[1:, 0]
        dot = np.einsum("ij,ij->i", seg[:-1], seg[1:])
        assert np.all((np.abs(cross) > 1e-9) | (dot < 0))
