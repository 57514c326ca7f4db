"""Property tests of the world queries against brute-force references (2D and 3D, every shape)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import WorldError
from companion.world import Box, Cylinder, Disc, Prism, Sphere, World

SETTINGS = settings(deadline=None, max_examples=40)
coord = st.floats(-30.0, 30.0, allow_nan=False)
radius = st.floats(0.5, 10.0)


def pt(d):
    return st.tuples(*[coord] * d)


@st.composite
def star_polygon(draw):
    """A simple (star-shaped, possibly non-convex) polygon around a random centre."""
    n = draw(st.integers(3, 7))
    cx, cy = draw(coord), draw(coord)
    angles = np.sort(np.array(draw(st.lists(st.floats(0, 2 * math.pi - 1e-3), min_size=n, max_size=n, unique=True))))
    if np.min(np.diff(np.concatenate([angles, [angles[0] + 2 * math.pi]]))) < 0.05:
        angles = np.linspace(0, 2 * math.pi, n, endpoint=False)
    radii = draw(st.lists(st.floats(1.0, 12.0), min_size=n, max_size=n))
    return [(cx + r * math.cos(a), cy + r * math.sin(a)) for a, r in zip(angles, radii)]


@st.composite
def shape(draw, d):
    kinds = ["ball", "cylinder", "box", "prism"]
    kind = draw(st.sampled_from(kinds))
    if kind == "ball":
        c = draw(pt(d))
        return Disc(c, draw(radius)) if d == 2 else Sphere(c, draw(radius))
    if kind == "cylinder":
        lo = draw(st.floats(-20, 10))
        hi = lo + draw(st.floats(1, 20))
        if draw(st.booleans()):
            lo, hi = -math.inf, math.inf
        return Cylinder(draw(pt(2)), draw(radius), lo, hi)
    if kind == "box":
        lo = np.array(draw(pt(d)))
        size = np.array(draw(st.tuples(*[st.floats(0.5, 15)] * d)))
        return Box(lo, lo + size)
    lo = draw(st.floats(-20, 10))
    hi = lo + draw(st.floats(1, 20))
    if draw(st.booleans()):
        lo, hi = -math.inf, hi
    return Prism(draw(star_polygon()), lo, hi)


def inside_reference(ob, p) -> bool:
    """Membership by an independent test: winding angle for polygons, analytic otherwise."""
    p = np.asarray(p, dtype=float)
    if isinstance(ob, (Disc, Sphere)):
        return np.linalg.norm(p - ob.center_m) < ob.radius_m
    if isinstance(ob, Box):
        return bool(np.all(p > ob.min_m) and np.all(p < ob.max_m))
    if len(p) == 3 and not (ob.down_min_m < p[2] < ob.down_max_m):
        return False
    if isinstance(ob, Cylinder):
        return np.hypot(*(p[:2] - ob.center_ne_m)) < ob.radius_m
    v = np.asarray(ob.vertices_ne_m) - p[:2]
    ang = np.arctan2(v[:, 1], v[:, 0])
    turn = np.diff(np.concatenate([ang, ang[:1]]))
    turn = (turn + np.pi) % (2 * np.pi) - np.pi
    return abs(turn.sum()) > np.pi


def surface_samples(ob, d, step=0.05):
    """Dense points on the shape's surface (the boundary of its cross-section in 2D)."""
    if isinstance(ob, (Disc, Sphere)) or (isinstance(ob, Cylinder) and d == 2):
        c = np.asarray(ob.center_m if not isinstance(ob, Cylinder) else ob.center_ne_m)
        if d == 2:
            a = np.arange(0, 2 * math.pi, step / ob.radius_m)
            return c + ob.radius_m * np.c_[np.cos(a), np.sin(a)]
        n = int(4 * math.pi * ob.radius_m**2 / step**2 / 4)
        g = np.random.default_rng(0).normal(size=(max(n, 2000), 3))
        return c + ob.radius_m * g / np.linalg.norm(g, axis=1, keepdims=True)
    raise NotImplementedError


@given(data=st.data(), d=st.sampled_from([2, 3]))
@SETTINGS
def test_scalar_and_batch_sdf_agree_and_sign_matches_membership(data, d):
    ob = data.draw(shape(d))
    pts = np.array(data.draw(st.lists(pt(d), min_size=1, max_size=20)))
    scalar = np.array([ob.sdf(tuple(p)) for p in pts])
    assert np.allclose(scalar, ob.sdf_batch(pts), atol=1e-9)
    for p, s in zip(pts, scalar):
        if abs(s) > 1e-6:
            assert (s < 0) == inside_reference(ob, p)


@given(c=pt(2), r=radius, p=pt(2))
@SETTINGS
def test_disc_sdf_matches_dense_surface(c, r, p):
    ob = Disc(c, r)
    ref = np.min(np.linalg.norm(surface_samples(ob, 2) - np.asarray(p), axis=1))
    assert abs(abs(ob.sdf(p)) - ref) < 0.03


@given(lo=pt(3), size=st.tuples(*[st.floats(0.5, 15)] * 3), p=pt(3))
@SETTINGS
def test_box_sdf_matches_analytic_reference(lo, size, p):
    lo, p = np.asarray(lo), np.asarray(p)
    hi = lo + np.asarray(size)
    ob = Box(lo, hi)
    clamped = np.clip(p, lo, hi)
    if np.allclose(clamped, p):
        ref = -np.min(np.minimum(p - lo, hi - p))
    else:
        ref = np.linalg.norm(p - clamped)
    assert ob.sdf(tuple(p)) == pytest.approx(ref, abs=1e-9)


@given(data=st.data(), p=pt(2))
@SETTINGS
def test_polygon_sdf_matches_dense_boundary(data, p):
    verts = np.asarray(data.draw(star_polygon()))
    ob = Prism(verts)
    edges = zip(verts, np.roll(verts, -1, axis=0))
    samples = np.concatenate([a + np.linspace(0, 1, 400)[:, None] * (b - a) for a, b in edges])
    ref = np.min(np.linalg.norm(samples - np.asarray(p), axis=1))
    assert abs(abs(ob.sdf(p)) - ref) < 0.05


@given(data=st.data(), d=st.sampled_from([2, 3]))
@SETTINGS
def test_segment_distance_matches_dense_sampling(data, d):
    ob = data.draw(shape(d))
    a, b = np.array(data.draw(pt(d))), np.array(data.draw(pt(d)))
    n = 4000
    ts = np.linspace(0.0, 1.0, n)
    sampled = np.maximum(ob.sdf_batch(a + ts[:, None] * (b - a)), 0.0).min()
    exact = ob.segment_distance(tuple(a), tuple(b))
    spacing = np.linalg.norm(b - a) / (n - 1)
    # rounding grows with the segment's length (hypothesis found 2.2e-7 on a 23 m segment)
    assert exact <= sampled + 1e-7 * (1.0 + np.linalg.norm(b - a))
    assert sampled - exact <= spacing / 2 + 1e-6


@given(data=st.data(), d=st.sampled_from([2, 3]), margin=st.floats(0.0, 2.0))
@SETTINGS
def test_world_point_and_segment_queries_agree_with_brute_force(data, d, margin):
    obstacles = [data.draw(shape(d)) for _ in range(data.draw(st.integers(1, 5)))]
    world = World(obstacles, [-40.0] * d, [40.0] * d, margin_m=margin)
    pts = np.array(data.draw(st.lists(pt(d), min_size=2, max_size=20)))
    ref_clear = np.min([ob.sdf_batch(pts) for ob in obstacles], axis=0) - margin
    assert np.allclose(world.clearance_m(pts), ref_clear, atol=1e-9)
    assert np.array_equal(world.is_free(pts), ref_clear > 0)
    a, b = pts[0], pts[1]
    ts = np.linspace(0, 1, 2000)
    seg_pts = a + ts[:, None] * (b - a)
    sampled_free = bool(np.all(np.min([ob.sdf_batch(seg_pts) for ob in obstacles], axis=0) > margin))
    exact_free = world.segment_free(a, b)
    if exact_free:
        assert sampled_free
    exact_dist = min(ob.segment_distance(tuple(a), tuple(b)) for ob in obstacles)
    assert exact_free == (exact_dist > margin)


@given(seed=st.integers(0, 10_000), d=st.sampled_from([2, 3]))
@settings(deadline=None, max_examples=10)
def test_grid_index_gives_the_same_answers_as_a_linear_scan(seed, d):
    rs = np.random.RandomState(seed)
    n = 1000 if seed % 2 else 60
    radii = rs.uniform(0.3, 2.0, n) if n > 100 else rs.uniform(3.0, 8.0, n)
    world = World.from_spheres(rs.uniform(0, 100, (n, d)), radii, [0] * d, [100] * d, 0.5)
    centers = np.array([ob.center_m for ob in world.obstacles])
    radii = np.array([ob.radius_m for ob in world.obstacles]) + 0.5
    pts = rs.uniform(0, 100, (200, d))
    ref = np.all(np.linalg.norm(pts[:, None] - centers[None], axis=2) > radii, axis=1)
    assert np.array_equal(world.is_free(pts), ref)
    ref_clear = (np.linalg.norm(pts[:, None] - centers[None], axis=2) - radii).min(axis=1)
    assert np.allclose(world.clearance_m(pts), ref_clear, atol=1e-9)
    for n, (a, b) in enumerate(zip(pts[:100], pts[100:200])):
        if n % 2:
            b = a + (b - a) * 0.1
        if n % 5 == 0:  # axis-parallel and cell-corner cases
            b = a.copy()
            b[n % d] = 100.0 * (n % 3 == 0)
        ab = b - a
        if not ab.any():
            continue
        t = np.clip(((centers - a) @ ab) / (ab @ ab), 0, 1)
        dist = np.linalg.norm(a + t[:, None] * ab - centers, axis=1)
        assert world.segment_free(a, b) == bool(np.all(dist > radii))


def test_queries_outside_bounds_and_nan_are_not_free():
    world = World([Disc((50, 50), 5)], (0, 0), (100, 100))
    assert world.is_free([[0, 0], [100, 100]]).tolist() == [True, True]
    assert world.is_free([[-0.1, 5], [5, 100.1], [math.nan, 3]]).tolist() == [False, False, False]
    assert not world.segment_free((1, 1), (101, 1))
    assert not world.segment_free((1, 1), (math.nan, 1))
    assert world.clearance_m([[50, 60]])[0] == pytest.approx(5.0)


def test_with_threats_returns_a_new_world_and_leaves_the_old_one():
    world = World([Sphere((10, 10, -10), 2)], (0, 0, -50), (50, 50, 0), margin_m=1)
    threat = Sphere((30, 30, -20), 4)
    both = world.with_threats([threat])
    assert len(world.obstacles) == 1 and len(both.obstacles) == 2
    assert world.is_free([[30, 30, -20]])[0] and not both.is_free([[30, 30, -20]])[0]
    assert both.margin_m == 1 and np.array_equal(both.bounds_max, world.bounds_max)
    with pytest.raises(AttributeError):
        world._margin = 3.0
    flat = World([Disc((1, 1), 1)], (0, 0), (50, 50)).with_threats([threat])
    assert isinstance(flat.obstacles[-1], Disc) and not flat.is_free([[30, 30]])[0]


@pytest.mark.parametrize(
    "call, key",
    [
        (lambda: World([], (0, 0), (0, 10)), "bounds_max"),
        (lambda: World([], (0, math.nan), (10, 10)), "bounds_min"),
        (lambda: World([], (0, 0, 0, 0), (1, 1, 1, 1)), "bounds_min"),
        (lambda: World([], (0, 0), (1, 1, 1)), "bounds_max"),
        (lambda: World([], (0, 0), (1, 1), margin_m=-1), "margin_m"),
        (lambda: World([Disc((1, 1), 1)], (0, 0, 0), (1, 1, 1)), "obstacles[0]"),
        (lambda: World([Sphere((1, 1, 1), 1)], (0, 0), (1, 1)), "obstacles[0]"),
        (lambda: World([Box((0, 0), (1, 1))], (0, 0, 0), (1, 1, 1)), "obstacles[0]"),
        (lambda: Disc((1, math.inf), 1), "Disc.center_m"),
        (lambda: Sphere((1, 1, 1), 0), "Sphere.radius_m"),
        (lambda: Cylinder((1, 1), 2, 5, 1), "Cylinder.down_min_m"),
        (lambda: Box((0, 0), (0, 1)), "Box.max_m"),
        (lambda: Prism([(0, 0), (1, 1)]), "Prism.vertices_ne_m"),
        (lambda: World.from_spheres([[1, 1]], [-1], (0, 0), (5, 5)), "radii[0]"),
        (lambda: World([], (0, 0), (5, 5)).is_free([[1, 2, 3]]), "points"),
    ],
)
def test_bad_arguments_raise_world_error_naming_them(call, key):
    with pytest.raises(WorldError, match=key.replace("[", r"\[").replace("]", r"\]")):
        call()


def test_world_without_obstacles_is_free_with_infinite_clearance():
    world = World([], (0, 0, 0), (10, 10, 10))
    assert world.segment_free((0, 0, 0), (10, 10, 10))
    assert np.isinf(world.clearance_m([[5, 5, 5]])[0])
