"""G1 smoothing (quartic midpoint interpolation, paper Fig. 3)."""

import numpy as np
import pytest
from hypothesis import given, settings
from smoothing_strategies import joint_angles, polylines

from companion.errors import SmoothingError
from companion.smoothing import bezier, smooth_g1


@settings(deadline=None, max_examples=60)
@given(polylines())
def test_g1_tangent_continuous_at_every_joint(path):
    curve = smooth_g1(path)
    np.testing.assert_allclose(curve.start, path[0], atol=1e-9)
    np.testing.assert_allclose(curve.end, path[-1], atol=1e-9)
    angles = joint_angles(curve.pieces)
    assert np.all(angles < 1e-9), angles
    assert curve.stop_s.size == 0
    assert all(p.shape[0] in (2, 5) for p in curve.pieces)


def test_joints_are_the_segment_midpoints():
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 20.0], [30.0, 20.0]])
    curve = smooth_g1(path)
    quartics = [p for p in curve.pieces if p.shape[0] == 5]
    assert len(quartics) == 2
    np.testing.assert_allclose(quartics[0][[0, 2, 4]], [[5.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    np.testing.assert_allclose(quartics[1][[0, 2, 4]], [[10.0, 10.0], [10.0, 20.0], [20.0, 20.0]])
    # the joints have zero curvature on both sides (the curve leaves each segment straight)
    for q in quartics:
        np.testing.assert_allclose(bezier.curvature(q, [0.0, 1.0]), 0.0, atol=1e-12)


def test_kappa_report_when_asked():
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    assert smooth_g1(path).kappa_ok
    tight = smooth_g1(path, kappa_max_1_m=0.1)
    assert not tight.kappa_ok and tight.tight_corners == [1]
    assert smooth_g1(path, kappa_max_1_m=10.0).kappa_ok


def test_collinear_repeated_and_two_nodes():
    assert len(smooth_g1(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [2.0, 2.0], [5.0, 5.0]])).pieces) == 1
    assert smooth_g1(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -5.0]])).length_m == pytest.approx(5.0)


def test_reversal_kept_as_stop():
    curve = smooth_g1(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 0.0]]))
    np.testing.assert_allclose(curve.stop_s, [10.0])
    assert not curve.kappa_ok


@pytest.mark.parametrize(
    "path, match",
    [
        (np.array([[0.0, 0.0]]), "path: needs at least 2 nodes"),
        (np.array([[0.0, np.inf], [1.0, 1.0]]), "path: node 0"),
        (np.ones((3,)), "path: expected shape"),
    ],
)
def test_bad_input(path, match):
    with pytest.raises(SmoothingError, match=match):
        smooth_g1(path)
    with pytest.raises(SmoothingError, match="kappa_max_1_m"):
        smooth_g1(np.array([[0.0, 0.0], [1.0, 1.0]]), kappa_max_1_m=-1.0)


def test_nearly_straight_node_leaves_no_tangent_jump():
    """A heading change of about 1e-8 rad (found by hypothesis) is one straight piece."""
    path = np.array([[0.0, 0.0], [-5.0, 5.96046448e-08], [-18.0, 0.0], [0.0, 1.0]])
    assert np.all(joint_angles(smooth_g1(path).pieces) < 1e-9)
