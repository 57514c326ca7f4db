"""G2 smoothing (Yang-Sukkarieh cubic spiral pairs, paper eqs. 15-19)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from smoothing_strategies import joint_angles, polylines

from companion.errors import SmoothingError
from companion.smoothing import bezier, smooth_g2
from companion.smoothing.g2 import C4, spiral_distance_m

KAPPA_ZERO_1_M = 1e-6  # both sides below this (a radius over 1000 km): a numerically flat joint


def joint_curvatures(pieces):
    ends = np.array([bezier.curvature(p, [1.0])[0] for p in pieces[:-1]])
    starts = np.array([bezier.curvature(p, [0.0])[0] for p in pieces[1:]])
    return ends, starts


@settings(deadline=None, max_examples=60)
@given(polylines(), st.floats(0.02, 1.0))
def test_g2_curvature_continuous_and_bounded(path, kappa_max):
    curve = smooth_g2(path, kappa_max)
    np.testing.assert_allclose(curve.start, path[0], atol=1e-9)
    np.testing.assert_allclose(curve.end, path[-1], atol=1e-9)
    stops = set(np.round(curve.stop_s, 9))
    joints_s = curve.piece_start_s[1:-1]
    smooth = np.array([round(s, 9) not in stops for s in joints_s], dtype=bool)
    angles = joint_angles(curve.pieces)
    assert np.all(angles[smooth] < 1e-9)
    ends, starts = joint_curvatures(curve.pieces)
    jump = np.abs(ends - starts)
    scale = np.maximum(ends, starts)
    ok = (jump <= 1e-6 * scale) | (scale < KAPPA_ZERO_1_M)
    assert np.all(ok[smooth]), (jump[smooth], scale[smooth])
    if curve.kappa_ok:
        assert curve.max_curvature_1_m <= kappa_max + 1e-6
        assert curve.stop_s.size == 0
    else:
        assert curve.notes and curve.tight_corners
    # never exceeded silently
    if curve.max_curvature_1_m > kappa_max + 1e-6:
        assert not curve.kappa_ok


def test_d_follows_eq_19_and_bound_is_met_with_room():
    kappa = 0.1
    path = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    curve = smooth_g2(path, kappa)
    beta = math.pi / 4
    d = C4 * math.sin(beta) / (kappa * math.cos(beta) ** 2)
    assert spiral_distance_m(math.pi / 2, kappa) == pytest.approx(d)
    np.testing.assert_allclose(curve.pieces[1][0], [100.0 - d, 0.0], atol=1e-12)  # B0
    np.testing.assert_allclose(curve.pieces[2][-1], [100.0, d], atol=1e-12)  # E0
    assert curve.kappa_ok
    assert 0.999 * kappa < curve.max_curvature_1_m <= kappa


def test_spiral_curvature_grows_monotonically_to_the_joint():
    curve = smooth_g2(np.array([[0.0, 0.0], [60.0, 0.0], [90.0, 40.0]]), 0.1)
    spiral = curve.pieces[1]
    kappa = bezier.curvature(spiral, np.linspace(0, 1, 201))
    assert kappa[0] < 1e-12
    assert np.all(np.diff(kappa) >= -1e-12)


def test_3d_corner_stays_in_its_plane():
    path = np.array([[0.0, 0.0, 0.0], [40.0, 0.0, 0.0], [60.0, 30.0, -20.0]])
    curve = smooth_g2(path, 0.1)
    normal = np.cross(path[0] - path[1], path[2] - path[1])
    normal /= np.linalg.norm(normal)
    for piece in curve.pieces:
        np.testing.assert_allclose((piece - path[1]) @ normal, 0.0, atol=1e-9)
    assert curve.kappa_ok and curve.max_curvature_1_m <= 0.1 + 1e-9


def test_straight_and_repeated_nodes_need_no_spiral():
    path = np.array([[0.0, 0.0], [10.0, 10.0], [10.0, 10.0], [20.0, 20.0], [30.0, 30.0]])
    curve = smooth_g2(path, 0.1)
    assert len(curve.pieces) == 1
    assert curve.length_m == pytest.approx(math.hypot(30, 30))
    assert curve.max_curvature_1_m == 0.0 and curve.kappa_ok


def test_two_nodes_give_a_line():
    curve = smooth_g2(np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]]), 0.5)
    assert curve.length_m == pytest.approx(5.0)
    assert curve.kappa_ok and not curve.notes


def test_short_segments_shrink_d_and_report_the_corner():
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [40.0, 10.0]])
    curve = smooth_g2(path, 0.1)
    assert not curve.kappa_ok
    assert curve.tight_corners == [1, 2]
    assert any(note.startswith("corner 1") and "1/m > K_max" in note for note in curve.notes)
    assert curve.max_curvature_1_m > 0.1
    ends, starts = joint_curvatures(curve.pieces)  # still G2 where it is tight
    scale = np.maximum(ends, starts)
    assert np.all((np.abs(ends - starts) <= 1e-6 * scale) | (scale < KAPPA_ZERO_1_M))


def test_reversal_is_a_stop():
    curve = smooth_g2(np.array([[0.0, 0.0], [20.0, 0.0], [5.0, 0.0]]), 0.1)
    assert not curve.kappa_ok and curve.tight_corners == [1]
    np.testing.assert_allclose(curve.stop_s, [20.0])
    assert "reverses" in curve.notes[0]


@pytest.mark.parametrize(
    "path, kappa, match",
    [
        (np.array([[0.0, 0.0]]), 0.1, "path: needs at least 2 nodes"),
        (np.zeros((0, 2)), 0.1, "path"),
        (np.array([[0.0, 0.0], [np.nan, 1.0]]), 0.1, "path: node 1 is not finite"),
        (np.array([[0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]]), 0.1, "path: expected shape"),
        (np.array([[1.0, 1.0], [1.0, 1.0]]), 0.1, "path: all 2 nodes"),
        (np.array([[0.0, 0.0], [1.0, 1.0]]), 0.0, "kappa_max_1_m"),
        (np.array([[0.0, 0.0], [1.0, 1.0]]), -1.0, "kappa_max_1_m"),
        (np.array([[0.0, 0.0], [1.0, 1.0]]), float("nan"), "kappa_max_1_m"),
        ("abc", 0.1, "path"),
    ],
)
def test_bad_input_raises_naming_argument(path, kappa, match):
    with pytest.raises(SmoothingError, match=match):
        smooth_g2(path, kappa)
