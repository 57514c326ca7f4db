"""The space-time check (DESIGN 7.2): never a false "clear" against the analytic closest approach."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.threats.decision.prediction import predict_tubes
from companion.threats.decision.spacetime import STATIC_ID, check_candidates, sample_times, segment_min_distance
from companion.threats.model import Threat
from companion.world import Disc, Sphere, World

coord = st.floats(-50.0, 50.0, allow_nan=False)
speed = st.floats(-8.0, 8.0, allow_nan=False)


def analytic_min_distance(p0, v, c0, w, t_end):
    """Closest approach of p0 + v t and c0 + w t over [0, t_end] (closed form)."""
    dp, dv = np.asarray(p0) - np.asarray(c0), np.asarray(v) - np.asarray(w)
    dd = float(dv @ dv)
    t = 0.0 if dd < 1e-12 else min(max(-float(dp @ dv) / dd, 0.0), t_end)
    return float(np.linalg.norm(dp + dv * t))


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(coord, coord, coord),
    st.tuples(speed, speed, speed),
    st.tuples(coord, coord, coord),
    st.tuples(speed, speed, speed),
    st.floats(0.5, 10.0),
    st.sampled_from([0.05, 0.3, 1.0, 2.5]),
)
def test_never_clear_when_the_closest_approach_intrudes(p0, v, c0, w, radius, step_s):
    horizon = 12.0
    threat = Threat("t", "moving", "local_ned", c0, w, radius, None, 0.0)
    tubes = predict_tubes([threat], inflation_m=0.0)
    t = sample_times(0.0, horizon, step_s)
    pos = np.asarray(p0)[None, :] + t[:, None] * np.asarray(v)[None, :]
    res = check_candidates(t, pos, tubes, accel_bound_m_s2=0.0)
    cpa = analytic_min_distance(p0, v, c0, w, t[-1])
    if cpa < radius - 1e-9:
        assert not res.clear[0]
        assert res.conflicts[0].threat_id == "t"
    # the reported clearance is exact for straight lines
    assert math.isclose(res.min_clearance_m[0], cpa - radius, abs_tol=1e-6)


@settings(max_examples=100, deadline=None)
@given(st.floats(1.0, 8.0), st.floats(0.5, 6.0), st.floats(-3.0, 3.0))
def test_curved_candidates_are_never_falsely_clear(speed_m_s, radius, offset):
    """A circle flown at constant speed, sampled coarsely: the chord error bound keeps it safe."""
    r_circle = 20.0
    omega = speed_m_s / r_circle
    accel = speed_m_s * omega
    t = sample_times(0.0, 10.0, 0.5)
    pos = r_circle * np.stack([np.cos(omega * t), np.sin(omega * t)], axis=1)
    # a static threat placed near the arc between two samples
    mid = 0.5 * (t[3] + t[4])
    center = (r_circle + offset) * np.array([math.cos(omega * mid), math.sin(omega * mid)])
    tubes = predict_tubes(
        [Threat("s", "popup", "local_ned", (center[0], center[1], 0.0), (0, 0, 0), radius)], inflation_m=0.0
    )
    res = check_candidates(t, pos, tubes, accel_bound_m_s2=accel)
    fine = np.linspace(0.0, 10.0, 20001)
    true = (
        np.min(
            np.linalg.norm(
                r_circle * np.stack([np.cos(omega * fine), np.sin(omega * fine)], 1) - center[None, :], axis=1
            )
        )
        - radius
    )
    assert res.min_clearance_m[0] <= true + 1e-9
    if true < 0:
        assert not res.clear[0]


def test_segment_min_distance_endpoints_and_interior():
    r0 = np.array([[-1.0, 1.0], [2.0, 0.0]])
    r1 = np.array([[1.0, 1.0], [3.0, 0.0]])
    np.testing.assert_allclose(segment_min_distance(r0, r1), [1.0, 2.0])


def test_static_world_and_bounds_conflicts():
    world = World([Disc((10.0, 0.0), 2.0)], [-20.0, -20.0], [20.0, 20.0])
    t = sample_times(0.0, 10.0, 0.5)
    through = np.stack([t * 2.0 - 5.0, np.zeros_like(t)], axis=1)  # crosses the sphere
    beside = np.stack([t * 2.0 - 5.0, np.full_like(t, 5.0)], axis=1)  # 3 m from it
    out = np.stack([np.zeros_like(t), t * 3.0], axis=1)  # leaves the bounds
    res = check_candidates(t, np.stack([through, beside, out]), [], world, accel_bound_m_s2=0.0)
    assert list(res.clear) == [False, True, False]
    assert res.conflicts[0].threat_id == STATIC_ID and res.conflicts[2].threat_id == STATIC_ID
    assert 2.5 < res.min_clearance_m[1] <= 3.0


def test_uncertainty_grows_a_moving_tube_only():
    mover = Threat("m", "moving", "local_ned", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0, None, 0.0)
    popup = Threat("p", "popup", "local_ned", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2.0, None, 0.0)
    tm, tp = predict_tubes([mover, popup], inflation_m=1.0, uncertainty_m_s=0.5, uncertainty_max_m=2.0)
    np.testing.assert_allclose(tm.radius_at(np.array([0.0, 2.0, 10.0])), [3.0, 4.0, 5.0])
    np.testing.assert_allclose(tp.radius_at(np.array([0.0, 10.0])), [3.0, 3.0])


def test_a_tube_outlives_its_reports_ttl_but_a_tube_given_an_end_is_gone_after_it():
    """A threat's ttl bounds how long its report is valid, not the threat: its tube lives over
    the horizon, so waiting for a reported pop-up to expire is never clear. A tube with an end of
    its own (another vehicle that yields) is gone after it."""
    th = Threat("e", "popup", "local_ned", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 5.0, 2.0, 0.0)
    tube = predict_tubes([th], inflation_m=0.0)[0]
    t = sample_times(0.0, 10.0, 0.5)
    hover_later = np.zeros((t.size, 3))
    assert not check_candidates(t[t > 3.0], hover_later[t > 3.0], [tube]).clear[0]
    ended = dataclasses.replace(tube, expires_t_s=2.0)
    assert check_candidates(t[t > 3.0], hover_later[t > 3.0], [ended]).clear[0]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_static_clearance_is_exact_near_obstacles_and_a_lower_bound_far(seed):
    from companion.threats.decision.spacetime import STATIC_REACH_M, _obstacle_clearance
    from companion.world import Cylinder, Prism

    rng = np.random.default_rng(seed)
    obstacles = [
        Prism(((0.0, 0.0), (10.0, 0.0), (5.0, 8.0)), -30.0, 0.0),
        Cylinder((30.0, 5.0), float(rng.uniform(1.0, 5.0)), -25.0, -5.0),
        Sphere((10.0, 30.0, -15.0), 4.0),
    ]
    world = World(obstacles, [-20.0, -20.0, -40.0], [60.0, 60.0, 0.0], margin_m=float(rng.uniform(0.0, 3.0)))
    pts = rng.uniform([-20.0, -20.0, -40.0], [60.0, 60.0, 0.0], size=(500, 3))
    exact = world.clearance_m(pts)
    fast = _obstacle_clearance(pts, world)
    assert np.all(fast <= exact + 1e-9)
    near = fast < STATIC_REACH_M - world.margin_m
    np.testing.assert_allclose(fast[near], exact[near], atol=1e-9)


MANNED_AXES = (609.6, 76.2)


def _cylinder_clearance(rel: np.ndarray, radius_m: float, half_height_m: float, scale: float) -> np.ndarray:
    """The manned cylinder's clearance at points (K, 3), straight from its definition."""
    return np.maximum(np.linalg.norm(rel[:, :2], axis=1) - radius_m, scale * (np.abs(rel[:, 2]) - half_height_m))


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(st.floats(-2000, 2000), st.floats(-2000, 2000), st.floats(-200, 200)),
    st.tuples(st.floats(-60, 60), st.floats(-60, 60), st.floats(-8, 8)),
    st.sampled_from([0.1, 0.25, 1.0, 3.0]),
)
def test_a_manned_aircraft_is_never_falsely_clear_of_its_well_clear_cylinder(p0, v_rel, step_s):
    """A manned aircraft's tube is the well-clear cylinder (2000 ft / 250 ft): the check's
    clearance is a lower bound of the cylinder's own, sampled every millisecond, and a path that
    enters the cylinder is never clear."""
    threat = Threat("m", "moving", "local_ned", (0.0, 0.0, -100.0), (0.0, 0.0, 0.0), 25.0, None, 0.0, traffic="manned")
    tube = predict_tubes([threat], inflation_m=0.0, manned_axes_m=MANNED_AXES)[0]
    assert (tube.radius_m, tube.half_height_m, tube.bare_radius_m) == (609.6, 76.2, 25.0)
    t = sample_times(0.0, 20.0, step_s)
    own0 = np.array(p0) + np.array([0.0, 0.0, -100.0])
    pos = own0[None, :] + t[:, None] * np.array(v_rel)[None, :]
    res = check_candidates(t, pos, [tube], accel_bound_m_s2=0.0)
    fine = np.arange(0.0, 20.0 + 1e-9, 0.001)
    rel = np.array(p0)[None, :] + fine[:, None] * np.array(v_rel)[None, :]
    true = _cylinder_clearance(rel, 609.6, 76.2, 609.6 / 76.2).min()
    assert res.min_clearance_m[0] <= true + 1e-6
    if true < 0:
        assert not res.clear[0] and res.conflicts[0].threat_id == "m"


def test_a_manned_tube_spans_the_horizon_and_a_drone_tube_is_unchanged():
    manned = Threat("m", "moving", "local_ned", (0.0, 0.0, -100.0), (50.0, 0.0, 0.0), 25.0, 5.0, 0.0, traffic="manned")
    drone = dataclasses.replace(manned, id="d", traffic="drone")
    m, d = predict_tubes([manned, drone], inflation_m=2.0, manned_axes_m=MANNED_AXES)
    assert m.expires_t_s == math.inf and m.radius_m == 611.6 and m.vertical_scale == 609.6 / 76.2
    assert d.expires_t_s == 5.0 and d.radius_m == 27.0 and d.half_height_m == math.inf
    # without the manned volume (another vehicle's check), manned traffic is a ball of its radius
    plain = predict_tubes([manned], inflation_m=2.0)[0]
    assert plain.radius_m == 27.0 and plain.half_height_m == math.inf
