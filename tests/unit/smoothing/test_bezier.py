"""Bezier machinery: Bernstein evaluation, derivatives, curvature, arc length, splitting."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import SmoothingError
from companion.smoothing import bezier
from companion.smoothing.bezier import BezierPath

coord = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False, allow_infinity=False)


@st.composite
def control_points(draw, n=None, d=None):
    n = draw(st.integers(1, 5)) if n is None else n
    d = draw(st.sampled_from([2, 3])) if d is None else d
    return np.array(draw(st.lists(st.lists(coord, min_size=d, max_size=d), min_size=n + 1, max_size=n + 1)))


def test_bernstein_partition_of_unity_and_endpoints():
    u = np.linspace(0, 1, 11)
    for n in range(6):
        basis = bezier.bernstein(n, u)
        assert basis.shape == (11, n + 1)
        np.testing.assert_allclose(basis.sum(axis=1), 1.0, atol=1e-14)
    ctrl = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
    np.testing.assert_allclose(bezier.evaluate(ctrl, [0.0, 1.0]), ctrl[[0, -1]])


def test_circle_quadrant_curvature_close_to_one_over_radius():
    # standard cubic approximation of a unit quarter circle (radius within 3e-4, curvature 2.5 %)
    k = 4.0 / 3.0 * (math.sqrt(2) - 1)
    ctrl = np.array([[1.0, 0.0], [1.0, k], [k, 1.0], [0.0, 1.0]])
    kappa = bezier.curvature(ctrl, np.linspace(0, 1, 50))
    np.testing.assert_allclose(kappa, 1.0, atol=0.025)
    assert bezier.arc_length(ctrl) == pytest.approx(math.pi / 2, rel=1e-3)


@settings(deadline=None, max_examples=40)
@given(control_points(), st.floats(0.05, 0.95))
def test_split_reproduces_both_halves(ctrl, u_split):
    left, right = bezier.split(ctrl, u_split)
    u = np.linspace(0, 1, 9)
    np.testing.assert_allclose(bezier.evaluate(left, u), bezier.evaluate(ctrl, u * u_split), atol=1e-9)
    np.testing.assert_allclose(bezier.evaluate(right, u), bezier.evaluate(ctrl, u_split + u * (1 - u_split)), atol=1e-9)


@settings(deadline=None, max_examples=40)
@given(control_points(), st.integers(0, 3))
def test_elevation_keeps_curve_and_derivatives(ctrl, extra):
    high = bezier.elevate(ctrl, ctrl.shape[0] - 1 + extra)
    u = np.linspace(0, 1, 7)
    for order in range(3):
        np.testing.assert_allclose(
            bezier.derivative(high, u, order),
            bezier.derivative(ctrl, u, order),
            atol=1e-8 * max(1.0, np.abs(ctrl).max()),
        )


@settings(deadline=None, max_examples=40)
@given(control_points(n=3), st.integers(1, 3))
def test_derivatives_match_finite_differences(ctrl, order):
    u = np.array([0.2, 0.5, 0.8])
    h = 1e-5
    fd = (bezier.derivative(ctrl, u + h, order - 1) - bezier.derivative(ctrl, u - h, order - 1)) / (2 * h)
    np.testing.assert_allclose(bezier.derivative(ctrl, u, order), fd, atol=1e-4 * max(1.0, np.abs(ctrl).max()))


def test_derivative_beyond_degree_is_zero():
    ctrl = np.array([[0.0, 0.0], [1.0, 1.0]])
    np.testing.assert_array_equal(bezier.derivative(ctrl, [0.3], 2), [[0.0, 0.0]])


def test_path_arc_length_addressing_is_accurate():
    ctrl = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, -3.0], [20.0, 12.0, -5.0]])
    line = np.array([[20.0, 12.0, -5.0], [30.0, 14.0, -7.0]])  # tangent-continuous
    path = BezierPath([ctrl, line])
    assert path.length_m == pytest.approx(bezier.arc_length(ctrl, intervals=64) + math.sqrt(108.0), rel=1e-10)
    s = np.linspace(0, path.length_m, 20001)
    pts = path.evaluate(s)
    chord = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    np.testing.assert_allclose(chord, np.diff(s), rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(path.derivative(s, 1), axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(path.evaluate([0.0, path.length_m]), [ctrl[0], line[-1]], atol=1e-9)


def test_path_arc_length_derivatives_match_finite_differences():
    ctrl = np.array([[0.0, 0.0], [4.0, 3.0], [8.0, -2.0], [12.0, 1.0], [15.0, 6.0]])
    path = BezierPath([ctrl])
    s = np.array([2.0, 7.5, 12.0])
    h = 1e-3
    for order in (1, 2, 3):
        fd = (path.derivative(s + h, order - 1) - path.derivative(s - h, order - 1)) / (2 * h)
        np.testing.assert_allclose(path.derivative(s, order), fd, atol=2e-5)
    np.testing.assert_allclose(path.curvature(s), np.linalg.norm(path.derivative(s, 2), axis=1), rtol=1e-9)


def test_signed_curvature_turns_right_positive():
    # north then turning east (a right turn in NED) is positive
    k = 4.0 / 3.0 * (math.sqrt(2) - 1)
    ctrl = np.array([[0.0, 0.0], [k, 0.0], [1.0, 1.0 - k], [1.0, 1.0]])
    path = BezierPath([ctrl])
    assert np.all(path.curvature(np.linspace(0, path.length_m, 5), signed=True) > 0)


def test_path_detects_stops_at_kinks():
    path = BezierPath([np.array([[0.0, 0.0], [5.0, 0.0]]), np.array([[5.0, 0.0], [5.0, 5.0]])])
    np.testing.assert_allclose(path.stop_s, [5.0])
    straight = BezierPath([np.array([[0.0, 0.0], [5.0, 0.0]]), np.array([[5.0, 0.0], [9.0, 0.0]])])
    assert straight.stop_s.size == 0


@pytest.mark.parametrize(
    "bad, name",
    [
        ([np.array([[0.0, 0.0]])], "pieces[0]"),
        ([np.array([[0.0, np.nan], [1.0, 1.0]])], "pieces[0]"),
        ([], "pieces"),
        ([np.array([[1.0, 1.0], [1.0, 1.0]])], "pieces"),
    ],
)
def test_bad_pieces_raise_naming_argument(bad, name):
    with pytest.raises(SmoothingError, match=name.replace("[", r"\[").replace("]", r"\]")):
        BezierPath(bad)


def test_bad_arc_length_query_raises():
    path = BezierPath([np.array([[0.0, 0.0], [5.0, 0.0]])])
    with pytest.raises(SmoothingError, match="s_m"):
        path.evaluate([np.nan])


def test_mixed_degrees_round_trip_and_evaluate():
    cubic = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
    quartic = np.array([[4.0, 0.0], [5.0, -2.0], [6.0, -1.0], [7.0, 1.0], [8.0, 0.0]])
    line = np.array([[8.0, 0.0], [10.0, -1.0]])
    path = BezierPath([cubic, quartic, line])
    for given_piece, stored in zip([cubic, quartic, line], path.pieces):
        np.testing.assert_allclose(stored, given_piece, atol=1e-12)
    np.testing.assert_allclose(path.piece_start_s[1], bezier.arc_length(cubic, intervals=64), rtol=1e-10)
    np.testing.assert_allclose(path.evaluate(path.piece_start_s[1:3]), [quartic[0], line[0]], atol=1e-9)
