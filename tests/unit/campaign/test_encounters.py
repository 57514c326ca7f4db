"""The campaign's encounters: intruder tracks (``tracks``), the parametric geometries
(``parametric``) against a synthetic own flight, and manned traffic's importance sampling
(``manned``).

The own flights are analytic (a level line at 6 m/s, and a vertical climb then a level leg), so
every closest approach is computed here independently of ``OwnFlight`` and ``IntruderTrack``.
Everything random has a fixed seed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from companion.campaign.delivery import DEFAULT_DELIVERY
from companion.campaign.manned import EMITTERS, draw_miss, make_manned, miss_weight
from companion.campaign.parametric import (
    CRUISE_M_S,
    GEOMETRIES,
    MISS_EXTRA_M,
    MOVER_CPA_S,
    POPUP_CPA_S,
    RADIUS_M,
    START_MARGIN_M,
    OwnFlight,
    make_parametric,
)
from companion.campaign.spec import MannedSpec
from companion.campaign.tracks import Encounter, IntruderTrack, straight_track

OWN_SPEED_M_S = 6.0
OWN_ALT_M = 20.0
DT_S = 0.02  # 50 Hz
END_S = 30.0
CLIMB_END_S = 12.0  # the vertical part of the vertical-then-level flight
CLIMB_RATE_M_S = 2.5
CLIMB_START_DOWN_M = -15.0
GOAL_LEVEL_NED_M = np.array([OWN_SPEED_M_S * END_S, 0.0, -OWN_ALT_M])
FINE_DT_S = 0.002  # the grid the closest approaches are searched on here

# ---------------------------------------------------------------------------------------------
# Independent own flights and intruder lines
# ---------------------------------------------------------------------------------------------


def level_own_at(t_s: np.ndarray) -> np.ndarray:
    """The level flight: (6 t, 0, -20), (K,) -> (K, 3)."""
    t = np.asarray(t_s, dtype=float)
    return np.column_stack([OWN_SPEED_M_S * t, np.zeros_like(t), np.full_like(t, -OWN_ALT_M)])


def vertical_own_at(t_s: np.ndarray) -> np.ndarray:
    """Climbs straight up at 2.5 m/s for 12 s, then flies level north at 6 m/s."""
    t = np.asarray(t_s, dtype=float)
    climb = np.minimum(t, CLIMB_END_S)
    level = np.maximum(t - CLIMB_END_S, 0.0)
    return np.column_stack([OWN_SPEED_M_S * level, np.zeros_like(t), CLIMB_START_DOWN_M - CLIMB_RATE_M_S * climb])


def own_flight(vertical: bool) -> OwnFlight:
    t = np.round(np.arange(0.0, END_S + 0.5 * DT_S, DT_S), 10)
    return OwnFlight(t, (vertical_own_at if vertical else level_own_at)(t))


def goal_of(vertical: bool) -> np.ndarray:
    return vertical_own_at(np.array([END_S]))[0] if vertical else GOAL_LEVEL_NED_M


def aim_line(track: IntruderTrack):
    """The intruder's first straight segment, extended: (p0, v, t0) with p(t) = p0 + v (t - t0)
    (for a turning or climbing one, the line it was aimed along before its manoeuvre)."""
    t0 = float(track.t_s[0])
    v = (track.pos_ned_m[1] - track.pos_ned_m[0]) / (track.t_s[1] - track.t_s[0])
    return track.pos_ned_m[0].copy(), v, t0


def line_at(line, t_s: np.ndarray) -> np.ndarray:
    p0, v, t0 = line
    return p0[None, :] + (np.asarray(t_s, dtype=float)[:, None] - t0) * v[None, :]


def closest_approach(own_at, line, t_from_s: float, t_to_s: float) -> tuple[float, float]:
    """(time, distance) of the least distance between the own flight and a line, on a fine grid."""
    t = np.arange(t_from_s, t_to_s, FINE_DT_S)
    d = np.linalg.norm(own_at(t) - line_at(line, t), axis=1)
    k = int(np.argmin(d))
    return float(t[k]), float(d[k])


def horizontal_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    ah, bh = a[:2], b[:2]
    c = float(ah @ bh) / (np.linalg.norm(ah) * np.linalg.norm(bh))
    return math.degrees(math.acos(np.clip(c, -1.0, 1.0)))


def draw(geometry: str, seed: int, *, goal=None) -> Encounter:
    vertical = geometry in ("above", "below")
    return make_parametric(
        seed,
        f"{geometry}/test",
        geometry,
        "climb" if vertical else "open",
        own_flight(vertical),
        goal_of(vertical) if goal is None else goal,
        dict(DEFAULT_DELIVERY),
        np.random.default_rng([99, seed]),
    )


SEEDS = range(25)

# ---------------------------------------------------------------------------------------------
# tracks.IntruderTrack and straight_track
# ---------------------------------------------------------------------------------------------

coordinate = st.floats(-500.0, 500.0, allow_nan=False)


@st.composite
def tracks(draw_):
    """An IntruderTrack of 2-6 samples, times at least 0.1 s apart."""
    k = draw_(st.integers(2, 6))
    t0 = draw_(st.floats(-50.0, 50.0))
    gaps = draw_(st.lists(st.floats(0.1, 20.0), min_size=k - 1, max_size=k - 1))
    t = t0 + np.concatenate([[0.0], np.cumsum(gaps)])
    pos = np.array(draw_(st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=k, max_size=k)))
    return IntruderTrack("t0", t, pos, 3.0, float(t[0]), float(t[-1]))


@given(tracks())
@settings(max_examples=100, deadline=None)
def test_position_exact_at_the_samples(track):
    np.testing.assert_array_equal(track.position_at(track.t_s), track.pos_ned_m)


@given(tracks(), st.floats(0.0, 1.0))
@settings(max_examples=100, deadline=None)
def test_position_linear_between_samples(track, fraction):
    """Between samples k and k+1, the position is the straight interpolation (each segment)."""
    for k in range(track.t_s.size - 1):
        t = track.t_s[k] + fraction * (track.t_s[k + 1] - track.t_s[k])
        expected = track.pos_ned_m[k] + fraction * (track.pos_ned_m[k + 1] - track.pos_ned_m[k])
        np.testing.assert_allclose(track.position_at(t)[0], expected, atol=1e-9 * (1 + np.abs(expected).max()))


@given(tracks(), st.floats(0.01, 100.0))
@settings(max_examples=100, deadline=None)
def test_straight_extrapolation_beyond_the_ends(track, beyond_s):
    """Before the first sample the track continues its first segment, after the last its last."""
    t, p = track.t_s, track.pos_ned_m
    v_first = (p[1] - p[0]) / (t[1] - t[0])
    v_last = (p[-1] - p[-2]) / (t[-1] - t[-2])
    before = track.position_at(t[0] - beyond_s)[0]
    after = track.position_at(t[-1] + beyond_s)[0]
    scale = 1e-9 * (1 + np.abs(p).max() + beyond_s * (np.abs(v_first).max() + np.abs(v_last).max()))
    np.testing.assert_allclose(before, p[0] - beyond_s * v_first, atol=scale)
    np.testing.assert_allclose(after, p[-1] + beyond_s * v_last, atol=scale)
    np.testing.assert_allclose(track.velocity_at(t[0] - beyond_s)[0], v_first, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(track.velocity_at(t[-1] + beyond_s)[0], v_last, rtol=1e-12, atol=1e-12)


@given(tracks(), st.floats(-0.5, 1.5))
@settings(max_examples=150, deadline=None)
def test_velocity_is_the_finite_difference_of_position(track, where):
    """Away from the knots the velocity is the central difference of the positions (anywhere
    on the time line, beyond the ends included)."""
    t, h = track.t_s, 1e-3
    span = t[-1] - t[0]
    query = t[0] + where * span
    if np.min(np.abs(t - query)) < 2 * h:
        query += 4 * h  # off a knot: the difference would straddle two segments
    fd = (track.position_at(query + h)[0] - track.position_at(query - h)[0]) / (2 * h)
    scale = np.abs(track.pos_ned_m).max() + 1.0
    np.testing.assert_allclose(track.velocity_at(query)[0], fd, atol=1e-6 * scale / h)


def test_position_and_velocity_shapes_for_scalar_and_array_times():
    track = straight_track("a", 0.0, 10.0, (1.0, 2.0, 3.0), (1.0, 0.0, -1.0), 2.0)
    assert track.position_at(5.0).shape == (1, 3)
    assert track.position_at(np.linspace(-1, 11, 7)).shape == (7, 3)
    assert track.velocity_at(np.linspace(-1, 11, 7)).shape == (7, 3)


@given(
    st.tuples(coordinate, coordinate, coordinate),
    st.tuples(*[st.floats(-30.0, 30.0)] * 3),
    st.floats(0.0, 100.0),
    st.floats(0.5, 100.0),
    st.floats(-20.0, 140.0),
)
@settings(max_examples=100, deadline=None)
def test_straight_track_without_turn(p0, v, start_s, length_s, query_s):
    p0, v = np.array(p0), np.array(v)
    track = straight_track("s1", start_s, start_s + length_s, p0, v, 4.0)
    assert track.t_s.size == 2
    assert track.first_report_t_s == start_s and track.last_report_t_s == start_s + length_s
    assert track.radius_m == 4.0 and not track.popup
    t = start_s + query_s
    expected = p0 + v * (t - start_s)
    np.testing.assert_allclose(track.position_at(t)[0], expected, atol=1e-9 * (1 + np.abs(expected).max()))
    np.testing.assert_allclose(track.velocity_at(t)[0], v, atol=1e-9 * (1 + np.abs(v).max()))


@given(
    st.tuples(coordinate, coordinate, coordinate),
    st.tuples(*[st.floats(-30.0, 30.0)] * 3),
    st.tuples(*[st.floats(-30.0, 30.0)] * 3),
    st.floats(0.1, 0.9),
    st.floats(-0.5, 1.5),
)
@settings(max_examples=100, deadline=None)
def test_straight_track_with_a_turn(p0, v, v_after, turn_fraction, where):
    """v until the turn, v_after from it; continuous at the turn; straight beyond the ends."""
    p0, v, v_after = np.array(p0), np.array(v), np.array(v_after)
    start, end = 10.0, 40.0
    turn = start + turn_fraction * (end - start)
    track = straight_track("s2", start, end, p0, v, 3.0, turn_t_s=turn, v_after_ned_m_s=v_after, popup=False)
    assert track.t_s.size == 3 and track.t_s[1] == turn
    p_turn = p0 + v * (turn - start)
    t = start + where * (end - start)
    expected = p0 + v * (t - start) if t <= turn else p_turn + v_after * (t - turn)
    np.testing.assert_allclose(track.position_at(t)[0], expected, atol=1e-9 * (1 + np.abs(expected).max()))
    if abs(t - turn) > 1e-6:
        np.testing.assert_allclose(track.velocity_at(t)[0], v if t < turn else v_after, atol=1e-9 * 30)
    np.testing.assert_allclose(track.position_at(turn)[0], p_turn, atol=1e-9 * (1 + np.abs(p_turn).max()))


@pytest.mark.parametrize("turn_s", [None, 10.0, 40.0, 5.0, 50.0])
def test_straight_track_ignores_a_turn_outside_its_span(turn_s):
    track = straight_track(
        "s3", 10.0, 40.0, (0.0, 0.0, -20.0), (1.0, 2.0, 0.0), 3.0, turn_t_s=turn_s, v_after_ned_m_s=(5.0, 5.0, 5.0)
    )
    assert track.t_s.tolist() == [10.0, 40.0]
    np.testing.assert_allclose(track.pos_ned_m[1], [30.0, 60.0, -20.0])


def test_popup_track_is_flagged_and_static():
    track = straight_track("p", 0.0, 10.0, (5.0, 0.0, -20.0), (0.0, 0.0, 0.0), 2.0, popup=True)
    assert track.popup
    np.testing.assert_array_equal(track.position_at([0.0, 3.0, 50.0]), np.tile([5.0, 0.0, -20.0], (3, 1)))


# ---------------------------------------------------------------------------------------------
# parametric.make_parametric against the synthetic own flights
# ---------------------------------------------------------------------------------------------


def drawn_cpa_s(enc: Encounter) -> float:
    return float(enc.params["t_cpa_s"])


def own_at_of(geometry: str):
    return vertical_own_at if geometry in ("above", "below") else level_own_at


SINGLE = tuple(g for g in GEOMETRIES if g != "multi")


@pytest.mark.parametrize("geometry", SINGLE)
def test_aimed_at_the_own_flight_at_the_drawn_time(geometry):
    """At the drawn closest-approach time the intruder (its aim line) is within radius +
    MISS_EXTRA_M of the own flight, and the closest approach computed here is no farther."""
    own_at = own_at_of(geometry)
    for seed in SEEDS:
        enc = draw(geometry, seed)
        (track,) = enc.intruders
        line = aim_line(track)
        t_cpa = drawn_cpa_s(enc)
        bound = track.radius_m + MISS_EXTRA_M
        d_drawn = float(np.linalg.norm(own_at(np.array([t_cpa]))[0] - line_at(line, np.array([t_cpa]))[0]))
        assert d_drawn <= bound + 0.05, (seed, d_drawn, bound)
        _, d_min = closest_approach(own_at, line, track.first_report_t_s, enc.end_t_s)
        assert d_min <= d_drawn + 1e-3  # sampled: the aim is the closest approach


@pytest.mark.parametrize("geometry", [g for g in SINGLE if g not in ("above", "below")])
def test_closest_approach_at_the_drawn_time_within_tolerance(geometry):
    """Straight relative motion: the closest approach comes at most |miss| / |relative speed|
    from the drawn time (the miss's component along the relative velocity shifts it)."""
    for seed in SEEDS:
        enc = draw(geometry, seed)
        (track,) = enc.intruders
        line = aim_line(track)
        t_cpa = drawn_cpa_s(enc)
        miss = float(np.linalg.norm(level_own_at(np.array([t_cpa]))[0] - line_at(line, np.array([t_cpa]))[0]))
        relative = np.linalg.norm(line[1] - np.array([OWN_SPEED_M_S, 0.0, 0.0]))
        t_found, _ = closest_approach(level_own_at, line, t_cpa - 30.0, t_cpa + 30.0)
        assert abs(t_found - t_cpa) <= miss / relative + 2 * FINE_DT_S + 0.02, (seed, t_found, t_cpa)


@pytest.mark.parametrize("geometry", [g for g in SINGLE])
def test_drawn_times_in_their_windows(geometry):
    for seed in SEEDS:
        enc = draw(geometry, seed)
        (track,) = enc.intruders
        delay = drawn_cpa_s(enc) - track.first_report_t_s
        lo, hi = POPUP_CPA_S.get(geometry, MOVER_CPA_S)
        assert lo - 1e-9 <= delay <= hi + 1e-9, (seed, delay)
        assert enc.params["t_report_s"] == track.first_report_t_s == enc.first_report_t_s
        assert RADIUS_M[0] <= track.radius_m <= RADIUS_M[1]
        assert enc.end_t_s >= drawn_cpa_s(enc) and enc.end_t_s >= END_S
        assert enc.weight == 1.0 and enc.traffic == "drone" and enc.params["kinds"] == [geometry]


@pytest.mark.parametrize("geometry", ("above", "below"))
def test_vertical_geometries_aim_inside_the_climb(geometry):
    for seed in SEEDS:
        enc = draw(geometry, seed)
        assert 0.0 <= drawn_cpa_s(enc) <= CLIMB_END_S + 1e-9, seed


def test_head_on_flies_against_the_own_velocity():
    for seed in SEEDS:
        v = draw("head_on", seed).intruders[0].velocity_at(0.0)[0]
        speed = float(np.linalg.norm(v))
        assert 0.3 * CRUISE_M_S - 1e-9 <= speed <= 1.5 * CRUISE_M_S + 1e-9
        np.testing.assert_allclose(v / speed, [-1.0, 0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("geometry, top", [("crossing", 1.5), ("popup_mover", 1.0)])
def test_crossing_angles(geometry, top):
    sides = set()
    for seed in SEEDS:
        track = draw(geometry, seed).intruders[0]
        v = track.velocity_at(track.first_report_t_s)[0]
        angle = horizontal_angle_deg(v, np.array([OWN_SPEED_M_S, 0.0, 0.0]))
        assert 30.0 - 1e-6 <= angle <= 150.0 + 1e-6, (seed, angle)
        assert abs(v[2]) < 1e-9
        assert 0.3 * CRUISE_M_S - 1e-9 <= np.linalg.norm(v) <= top * CRUISE_M_S + 1e-9
        assert not track.popup
        sides.add(bool(v[1] > 0))
    assert sides == {True, False}  # either side


def test_overtaking_is_faster_than_own_and_along_the_track():
    for seed in SEEDS:
        v = draw("overtaking", seed).intruders[0].velocity_at(0.0)[0]
        speed = float(np.linalg.norm(v))
        assert speed > OWN_SPEED_M_S
        assert 1.2 * OWN_SPEED_M_S - 1e-6 <= speed <= 2.0 * CRUISE_M_S + 1e-9
        np.testing.assert_allclose(v / speed, [1.0, 0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("geometry", ("popup_near", "popup_far"))
def test_popups_are_static(geometry):
    for seed in SEEDS:
        track = draw(geometry, seed).intruders[0]
        assert track.popup
        np.testing.assert_array_equal(track.pos_ned_m[0], track.pos_ned_m[-1])
        np.testing.assert_array_equal(track.velocity_at(track.t_s)[0], np.zeros(3))


@pytest.mark.parametrize("geometry, sign", [("above", 1.0), ("below", -1.0)])
def test_above_descends_and_below_climbs(geometry, sign):
    for seed in SEEDS:
        v = draw(geometry, seed).intruders[0].velocity_at(0.0)[0]
        assert 1.0 - 1e-9 <= sign * v[2] <= 3.0 + 1e-9, (seed, v)  # down positive
        assert np.hypot(v[0], v[1]) <= CRUISE_M_S + 1e-9


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_intruders_do_not_start_near_the_vehicle(geometry):
    """(Pop-ups near the path are drawn within the margin often: many seeds for them.)"""
    own_at = own_at_of(geometry)
    for seed in range(400) if geometry in ("popup_near", "multi") else SEEDS:
        for track in draw(geometry, seed).intruders:
            t0 = track.first_report_t_s
            d = float(np.linalg.norm(track.position_at(t0)[0] - own_at(np.array([t0]))[0]))
            assert d > track.radius_m + START_MARGIN_M, (seed, track.id, d)


def test_popups_keep_off_the_goal():
    """A goal in the middle of the path: no pop-up within its radius + 5 m of it."""
    goal = level_own_at(np.array([10.0]))[0]
    for seed in SEEDS:
        track = draw("popup_far", seed, goal=goal).intruders[0]
        assert np.linalg.norm(track.pos_ned_m[0] - goal) > track.radius_m + 5.0


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_deterministic_for_the_same_seed(geometry):
    a, b = draw(geometry, 7), draw(geometry, 7)
    assert len(a.intruders) == len(b.intruders)
    for ta, tb in zip(a.intruders, b.intruders):
        np.testing.assert_array_equal(ta.t_s, tb.t_s)
        np.testing.assert_array_equal(ta.pos_ned_m, tb.pos_ned_m)
        assert (ta.id, ta.radius_m, ta.popup, ta.first_report_t_s) == (
            tb.id,
            tb.radius_m,
            tb.popup,
            tb.first_report_t_s,
        )
    assert a.params == b.params and a.end_t_s == b.end_t_s
    c = draw(geometry, 8)
    assert not np.array_equal(a.intruders[0].pos_ned_m, c.intruders[0].pos_ned_m)


def test_multi_has_two_or_three_intruders():
    counts = set()
    for seed in range(40):
        enc = draw("multi", seed)
        n = len(enc.intruders)
        counts.add(n)
        assert 2 <= n <= 3
        assert [t.id for t in enc.intruders] == [f"t{j}" for j in range(n)]
        assert len(enc.params["kinds"]) == n
        assert set(enc.params["kinds"]) <= {"head_on", "crossing", "overtaking", "popup"}
        for track, kind in zip(enc.intruders, enc.params["kinds"]):
            assert track.popup == (kind == "popup")
            _, d_min = closest_approach(level_own_at, aim_line(track), track.first_report_t_s, enc.end_t_s)
            assert d_min <= track.radius_m + MISS_EXTRA_M + 0.05
    assert counts == {2, 3}


@pytest.mark.parametrize("geometry", ("turning", "climbing"))
def test_manoeuvre_one_to_three_seconds_after_the_first_report(geometry):
    for seed in SEEDS:
        track = draw(geometry, seed).intruders[0]
        assert track.t_s.size == 3
        delay = track.t_s[1] - track.t_s[0]
        assert 1.0 - 1e-9 <= delay <= 3.0 + 1e-9, (seed, delay)
        v_before = track.velocity_at(track.t_s[0] + 0.5 * delay)[0]
        v_after = track.velocity_at(track.t_s[1] + 0.5)[0]
        if geometry == "turning":
            turn = horizontal_angle_deg(v_before, v_after)
            assert 30.0 - 1e-6 <= turn <= 90.0 + 1e-6, (seed, turn)
            assert np.hypot(*v_after[:2]) == pytest.approx(np.hypot(*v_before[:2]), rel=1e-9)
        else:
            climb = v_after[2] - v_before[2]
            assert 1.0 - 1e-9 <= abs(climb) <= 3.0 + 1e-9, (seed, climb)
            np.testing.assert_allclose(v_after[:2], v_before[:2], atol=1e-9)


def test_unknown_geometry_names_the_field():
    with pytest.raises(ValueError, match="geometry.*'sideways'"):
        make_parametric(
            0,
            "x",
            "sideways",
            "open",
            own_flight(False),
            GOAL_LEVEL_NED_M,
            dict(DEFAULT_DELIVERY),
            np.random.default_rng(0),
        )


def test_no_geometry_against_a_hover_raises():
    t = np.arange(0.0, END_S, DT_S)
    hover = OwnFlight(t, np.tile([0.0, 0.0, -20.0], (t.size, 1)))
    with pytest.raises(RuntimeError, match=r"encounter 3 \(crossing/open\)"):
        make_parametric(
            3,
            "crossing/open",
            "crossing",
            "open",
            hover,
            GOAL_LEVEL_NED_M,
            dict(DEFAULT_DELIVERY),
            np.random.default_rng(0),
        )


@pytest.mark.parametrize("geometry", ("crossing", "popup_far", "head_on"))
def test_fraction_of_aimed_misses_inside_the_radius(geometry):
    """The miss at the drawn time is uniform on [0, radius + 6]: the fraction below the radius
    has expectation mean(radius / (radius + 6)) (binomial, 5 sigma); the miss is across the
    relative velocity, so against the straight own flight the true closest approach has the same
    fraction."""
    n = 400
    hits_drawn, hits_cpa, expected = [], [], []
    for seed in range(n):
        enc = draw(geometry, 1000 + seed)
        (track,) = enc.intruders
        line = aim_line(track)
        t = np.array([drawn_cpa_s(enc)])
        d_drawn = float(np.linalg.norm(level_own_at(t)[0] - line_at(line, t)[0]))
        _, d_min = closest_approach(level_own_at, line, track.first_report_t_s, enc.end_t_s)
        hits_drawn.append(d_drawn < track.radius_m)
        hits_cpa.append(d_min < track.radius_m)
        expected.append(track.radius_m / (track.radius_m + MISS_EXTRA_M))
    p = float(np.mean(expected))
    sigma = math.sqrt(p * (1 - p) / n)
    assert abs(np.mean(hits_drawn) - p) < 5 * sigma, (np.mean(hits_drawn), p)
    assert abs(np.mean(hits_cpa) - p) < 5 * sigma, (np.mean(hits_cpa), p)  # the aim is the CPA


def test_aimed_miss_uniform_in_length_and_direction():
    """The miss at the drawn time: its length over radius + 6 is uniform on [0, 1]; it is across
    the relative velocity, at an angle about it uniform on [0, 2 pi) (for these level crossings the
    relative velocity is horizontal, so the angle from the vertical is that angle): KS tests."""
    lengths, angles = [], []
    for seed in range(3000):
        enc = draw("crossing", 5000 + seed)
        (track,) = enc.intruders
        t = np.array([drawn_cpa_s(enc)])
        miss = line_at(aim_line(track), t)[0] - level_own_at(t)[0]
        rel = track.velocity_at(t)[0] - (level_own_at(t + 1e-3)[0] - level_own_at(t)[0]) / 1e-3
        assert abs(float(miss @ rel)) <= 1e-6 * np.linalg.norm(miss) * np.linalg.norm(rel) + 1e-9
        lengths.append(np.linalg.norm(miss) / (track.radius_m + MISS_EXTRA_M))
        across = np.cross([0.0, 0.0, 1.0], rel / np.linalg.norm(rel))
        angles.append(math.atan2(miss @ (across / np.linalg.norm(across)), miss[2]) % (2 * math.pi))
    assert sps.kstest(lengths, "uniform").pvalue > 1e-3
    assert sps.kstest(angles, "uniform", args=(0.0, 2 * math.pi)).pvalue > 1e-3
    assert sps.kstest(np.square(lengths), "uniform").pvalue < 1e-6  # the test has power


# ---------------------------------------------------------------------------------------------
# manned.miss_weight and draw_miss
# ---------------------------------------------------------------------------------------------

SPEC = MannedSpec()
N_DRAWS = 200_000


def _draws(spec: MannedSpec, own_alt_m: float, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.array([draw_miss(spec, own_alt_m, rng) for _ in range(n)])


@pytest.fixture(scope="module", params=[100.0, 40.0])
def manned_draws(request):
    """(own altitude, draws (N, 3): hmd, vmd, weight); at 40 m the vmd floor (15 m AGL) cuts."""
    return request.param, _draws(SPEC, request.param, N_DRAWS, 5)


def _vmd_low(spec: MannedSpec, own_alt_m: float) -> float:
    return max(-spec.vmd_max_m, spec.min_agl_m - own_alt_m)


def test_weights_average_to_one(manned_draws):
    _, d = manned_draws
    w = d[:, 2]
    assert np.all(w > 0)
    assert abs(w.mean() - 1.0) < 0.01, w.mean()


def test_draws_in_their_ranges_and_the_floor_respected(manned_draws):
    alt, d = manned_draws
    assert np.all((d[:, 0] >= 0) & (d[:, 0] <= SPEC.hmd_max_m))
    assert np.all(d[:, 1] <= SPEC.vmd_max_m)
    assert np.all(alt + d[:, 1] >= SPEC.min_agl_m - 1e-9)
    assert d[:, 1].min() < _vmd_low(SPEC, alt) + 5.0  # the floor is reached, not far above it


def _weighted_chi_square_p(values: np.ndarray, weights: np.ndarray, edges: np.ndarray, cdf) -> float:
    """p value of the weighted histogram against the nominal bin probabilities (each bin's
    weighted count has variance sum w^2; the total is not fixed, so B degrees of freedom)."""
    n = values.size
    which = np.digitize(values, edges) - 1
    observed = np.bincount(which, weights=weights, minlength=edges.size - 1)[: edges.size - 1]
    variance = np.bincount(which, weights=weights**2, minlength=edges.size - 1)[: edges.size - 1]
    expected = n * np.diff(cdf(edges))
    stat = float(np.sum((observed - expected) ** 2 / variance))
    return float(sps.chi2.sf(stat, edges.size - 1))


def _hmd_cdf(x):
    return np.clip(x / SPEC.hmd_max_m, 0, 1) ** 2


def test_weighted_hmd_and_vmd_follow_the_nominal_densities(manned_draws):
    alt, d = manned_draws
    lo, hi = _vmd_low(SPEC, alt), SPEC.vmd_max_m
    hmd_edges = np.linspace(0.0, SPEC.hmd_max_m, 31)
    vmd_edges = np.linspace(lo, hi, 31)
    vmd_cdf = lambda x: np.clip((x - lo) / (hi - lo), 0, 1)  # noqa: E731
    assert _weighted_chi_square_p(d[:, 0], d[:, 2], hmd_edges, _hmd_cdf) > 1e-3
    assert _weighted_chi_square_p(d[:, 1], d[:, 2], vmd_edges, vmd_cdf) > 1e-3
    # the same test has the power to see the proposal is not the nominal
    ones = np.ones(d.shape[0])
    assert _weighted_chi_square_p(d[:, 0], ones, hmd_edges, _hmd_cdf) < 1e-6
    assert _weighted_chi_square_p(d[:, 1], ones, vmd_edges, vmd_cdf) < 1e-6


def test_weighted_empirical_cdf_close_to_the_nominal(manned_draws):
    """Weighted KS distance (the weights normalised) of hmd and vmd, below 1 %."""
    alt, d = manned_draws
    lo, hi = _vmd_low(SPEC, alt), SPEC.vmd_max_m
    for column, cdf in ((0, _hmd_cdf), (1, lambda x: np.clip((x - lo) / (hi - lo), 0, 1))):
        order = np.argsort(d[:, column])
        x, w = d[order, column], d[order, 2]
        ecdf = np.cumsum(w) / w.sum()
        assert np.max(np.abs(ecdf - cdf(x))) < 0.01


@given(st.floats(0.0, 1500.0), st.floats(-150.0, 150.0), st.floats(20.0, 400.0))
@settings(max_examples=200, deadline=None)
def test_weight_is_the_density_ratio(hmd, vmd, alt):
    """The weight is nominal / proposal, computed here from the MannedSpec docstring."""
    lo = _vmd_low(SPEC, alt)
    if vmd < lo:
        vmd = lo
    s, H, Hn, V, Vn = SPEC.near_share, SPEC.hmd_max_m, SPEC.hmd_near_m, SPEC.vmd_max_m, SPEC.vmd_near_m
    vn_lo = max(-Vn, lo)
    p = 2 * hmd / H**2 / (V - lo)
    q = (s * (hmd <= Hn) / Hn + (1 - s) / H) * (s * (vn_lo <= vmd <= Vn) / (Vn - vn_lo) + (1 - s) / (V - lo))
    assert miss_weight(hmd, vmd, SPEC, alt) == pytest.approx(p / q, rel=1e-12)
    assert miss_weight(hmd, vmd, SPEC, alt) >= 0


def test_draw_miss_is_deterministic():
    a = _draws(SPEC, 100.0, 50, 3)
    b = _draws(SPEC, 100.0, 50, 3)
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------------------------
# manned.make_manned with the MIT LL models (skipped without them)
# ---------------------------------------------------------------------------------------------


def _manned_model(kind: str):
    from companion.campaign.traffic_model import MODEL_FILES, load_model, models_directory

    if not (models_directory() / MODEL_FILES[kind]).is_file():
        pytest.skip(f"encounter models not in {models_directory()} (COMPANION_ENCOUNTER_MODELS)")
    return load_model(kind)


def _long_own() -> OwnFlight:
    t = np.round(np.arange(0.0, 120.0 + 1e-9, DT_S), 10)
    return OwnFlight(t, np.column_stack([OWN_SPEED_M_S * t, np.zeros_like(t), np.full_like(t, -100.0)]))


@pytest.mark.parametrize("kind", sorted(EMITTERS))
def test_manned_intruder_passes_at_the_drawn_miss(kind):
    from companion.threats.transport.adsb import AdsbSettings, emitter_radius_m

    model = _manned_model(kind)
    own = _long_own()
    for index in range(6):
        enc = make_manned(
            index, f"manned/{kind}", kind, model, own, SPEC, AdsbSettings(), np.random.default_rng([4, index])
        )
        (track,) = enc.intruders
        params = enc.params
        p_own = own.at(params["t_cpa_s"])[0]
        p_int = track.position_at(params["t_cpa_s"])[0]
        assert np.hypot(*(p_int - p_own)[:2]) == pytest.approx(params["hmd_target_m"], abs=1e-6)
        if p_int[2] > -SPEC.min_agl_m - 1e-9:  # clamped at the floor
            assert -p_int[2] == pytest.approx(SPEC.min_agl_m)
        else:
            assert -(p_int[2] - p_own[2]) == pytest.approx(params["vmd_target_m"], abs=1e-6)
        assert np.all(-track.pos_ned_m[:, 2] >= SPEC.min_agl_m - 1e-9)
        assert enc.weight == pytest.approx(
            miss_weight(params["hmd_target_m"], params["vmd_target_m"], SPEC, 100.0), rel=1e-9
        )
        assert track.id == f"adsb-{track.icao_address:06x}" and len(track.id) == 11
        assert track.emitter_type == EMITTERS[kind]
        assert track.radius_m == emitter_radius_m(EMITTERS[kind], AdsbSettings())
        assert track.t_s[0] == pytest.approx(params["t_cpa_s"] - SPEC.before_s)
        assert enc.traffic == kind and enc.delivery["update_hz"] == 1.0 and enc.weight > 0
