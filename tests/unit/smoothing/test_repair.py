"""Collision re-check and repair: the smoothed path is never less safe than the polyline."""

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from smoothing_strategies import polylines

from companion.smoothing import smooth_g1, smooth_g2
from companion.smoothing.repair import corners_clear
from companion.world import World

BOUND = 300.0


def corner_obstacles(path: np.ndarray, depth: np.ndarray, size: np.ndarray):
    """Discs/spheres inside each corner, on its bisector, clear of both segments."""
    centers, radii = [], []
    for i in range(1, path.shape[0] - 1):
        a = path[i - 1] - path[i]
        b = path[i + 1] - path[i]
        la, lb = np.linalg.norm(a), np.linalg.norm(b)
        a, b = a / la, b / lb
        bis = a + b
        if np.linalg.norm(bis) < 1e-6:
            continue
        bis /= np.linalg.norm(bis)
        half = 0.5 * np.arccos(np.clip(np.dot(a, b), -1, 1))
        t = depth[i - 1] * min(la, lb)
        centers.append(path[i] + t * bis)
        radii.append(size[i - 1] * t * np.sin(half))  # < distance to the two lines
    return np.array(centers), np.array(radii)


def sampled_free(world: World, curve) -> bool:
    s = np.linspace(0.0, curve.length_m, max(2, int(curve.length_m / 0.02)))
    pts = curve.evaluate(s)
    return bool(np.all(world.is_free(pts)))


@settings(deadline=None, max_examples=30)
@given(
    polylines(max_nodes=6),
    st.lists(st.floats(0.05, 0.6), min_size=5, max_size=5),
    st.lists(st.floats(0.2, 0.9), min_size=5, max_size=5),
    st.floats(0.0, 1.0),
    st.sampled_from(["g1", "g2"]),
)
def test_smoothed_curve_free_whenever_polyline_is(path, depth, size, margin, method):
    centers, radii = corner_obstacles(path, np.array(depth), np.array(size))
    assume(centers.shape[0] > 0)
    radii = radii - margin
    keep = radii > 0.05
    assume(np.any(keep))
    d = path.shape[1]
    world = World.from_spheres(centers[keep], radii[keep], [-BOUND] * d, [BOUND] * d, margin_m=margin)
    assume(world.path_free(path))
    curve = smooth_g1(path, world=world) if method == "g1" else smooth_g2(path, 0.2, world=world)
    assert sampled_free(world, curve)
    assert all(corners_clear(world, p[None, None])[0] for p in curve.pieces if p.shape[0] > 2)


def test_corner_that_would_clip_is_shrunk_and_reported():
    path = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 60.0]])
    world = World.from_spheres(np.array([[57.0, 3.0]]), np.array([1.5]), [-10, -10], [100, 100], margin_m=1.0)
    assert world.path_free(path)
    naive = smooth_g2(path, 0.1)
    assert not sampled_free(world, naive)
    repaired = smooth_g2(path, 0.1, world=world)
    assert sampled_free(world, repaired)
    assert any("shrunk" in n for n in repaired.notes)
    assert not repaired.kappa_ok and repaired.tight_corners == [1]
    world = World.from_spheres(np.array([[55.0, 5.0]]), np.array([2.0]), [-10, -10], [100, 100], margin_m=1.0)
    assert world.path_free(path)
    repaired_g1 = smooth_g1(path, world=world)
    assert not sampled_free(world, smooth_g1(path))
    assert sampled_free(world, repaired_g1)


def test_corner_kept_sharp_when_no_smooth_corner_is_free():
    path = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 60.0]])
    world = World.from_spheres(np.array([[57.0, 3.0]]), np.array([1.5]), [-10, -10], [100, 100], margin_m=1.0)
    curve = smooth_g2(path, 0.1, world=world, max_halvings=0)
    np.testing.assert_allclose(curve.stop_s, [60.0])
    assert "kept the polyline corner" in " ".join(curve.notes)
    assert sampled_free(world, curve)


def test_free_corners_untouched():
    path = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 60.0]])
    world = World.from_spheres(np.array([[30.0, 30.0]]), np.array([3.0]), [-10, -10], [100, 100])
    a = smooth_g2(path, 0.1, world=world)
    b = smooth_g2(path, 0.1)
    assert a.kappa_ok and not a.notes
    for p, q in zip(a.pieces, b.pieces):
        np.testing.assert_array_equal(p, q)


def test_corners_clear_detects_a_touching_curve():
    world = World.from_spheres(np.array([[0.5, 0.3]]), np.array([0.2]), [-5, -5], [5, 5])
    ctrl = np.array([[0.0, 0.0], [0.5, 1.0], [1.0, 0.0]])  # passes through (0.5, 0.5)
    assert not corners_clear(world, ctrl[None, None])[0]
    assert corners_clear(world, (ctrl + [0.0, 1.0])[None, None])[0]
