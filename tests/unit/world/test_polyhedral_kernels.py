"""The compiled Prism kernels give, bit for bit, what the plain-Python queries gave.

The reference below is the Python code the kernels replaced (``companion.world.geometry``,
``obstacles.slab_interval``/``lerp``, ``heli_common.geometry.point_in_polygon`` and the former
``Prism.sdf``/``Prism.segment_distance``), copied so that it stays fixed. Results are compared
with ``==`` on the float's bits (``struct``), which also tells 0.0 from -0.0.
"""

from __future__ import annotations

import dataclasses
import math
import pickle
import random
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.world import Prism, World
from companion.world import polyhedral_kernels as kern

SETTINGS = settings(deadline=None, max_examples=150)
coord = st.floats(-40.0, 40.0, allow_nan=False)
_EPS = 1e-12


# --- reference: the plain-Python code, as it was -------------------------------------------


def ref_point_in_polygon(point, polygon) -> bool:
    x, y = float(point[0]), float(point[1])
    inside = False
    n = len(polygon)
    if n == 0:
        return False
    xj, yj = polygon[n - 1]
    for i in range(n):
        xi, yi = polygon[i]
        if (yi > y) != (yj > y):
            x_cross = xi + (y - yi) * (xj - xi) / (yj - yi)
            if x < x_cross:
                inside = not inside
        xj, yj = xi, yi
    return inside


def ref_point_segment_dist2(p, a, b) -> float:
    ab2 = 0.0
    ap_ab = 0.0
    for pi, ai, bi in zip(p, a, b):
        d = bi - ai
        ab2 += d * d
        ap_ab += (pi - ai) * d
    if ab2 <= _EPS or ap_ab <= 0.0:
        t = 0.0
    elif ap_ab >= ab2:
        t = 1.0
    else:
        t = ap_ab / ab2
    s = 0.0
    for pi, ai, bi in zip(p, a, b):
        q = ai + t * (bi - ai) - pi
        s += q * q
    return s


def ref_segment_segment_dist2(p1, q1, p2, q2) -> float:
    d1 = [b - a for a, b in zip(p1, q1)]
    d2 = [b - a for a, b in zip(p2, q2)]
    r = [a - b for a, b in zip(p1, p2)]
    a = sum(x * x for x in d1)
    e = sum(x * x for x in d2)
    f = sum(x * y for x, y in zip(d2, r))
    if a <= _EPS and e <= _EPS:
        return sum(x * x for x in r)
    if a <= _EPS:
        s = 0.0
        t = min(max(f / e, 0.0), 1.0)
    else:
        c = sum(x * y for x, y in zip(d1, r))
        if e <= _EPS:
            t = 0.0
            s = min(max(-c / a, 0.0), 1.0)
        else:
            b = sum(x * y for x, y in zip(d1, d2))
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > _EPS * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t = 1.0
                s = min(max((b - c) / a, 0.0), 1.0)
    total = 0.0
    for x1, dd1, x2, dd2 in zip(p1, d1, p2, d2):
        q = (x1 + s * dd1) - (x2 + t * dd2)
        total += q * q
    return total


def ref_segments_cross_2d(a, b, c, d) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    o1 = orient(a, b, c)
    o2 = orient(a, b, d)
    o3 = orient(c, d, a)
    o4 = orient(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and ((o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)):
        return True
    return ref_segment_segment_dist2(a, b, c, d) <= _EPS


def ref_polygon_sdf(x, y, vertices) -> float:
    best = math.inf
    n = len(vertices)
    prev = vertices[n - 1]
    for i in range(n):
        cur = vertices[i]
        d2 = ref_point_segment_dist2((x, y), prev, cur)
        if d2 < best:
            best = d2
        prev = cur
    d = math.sqrt(best)
    return -d if ref_point_in_polygon((x, y), vertices) else d


def ref_segment_polygon_dist_2d(a, b, vertices) -> float:
    if ref_point_in_polygon(a, vertices) or ref_point_in_polygon(b, vertices):
        return 0.0
    best = math.inf
    n = len(vertices)
    prev = vertices[n - 1]
    for i in range(n):
        cur = vertices[i]
        if ref_segments_cross_2d(a, b, prev, cur):
            return 0.0
        d2 = ref_segment_segment_dist2(a, b, prev, cur)
        if d2 < best:
            best = d2
        prev = cur
    return math.sqrt(best)


def ref_slab_interval(a_z, b_z, lo, hi):
    dz = b_z - a_z
    if abs(dz) < 1e-15:
        return (0.0, 1.0) if lo <= a_z <= hi else None
    t_lo = (lo - a_z) / dz
    t_hi = (hi - a_z) / dz
    if t_lo > t_hi:
        t_lo, t_hi = t_hi, t_lo
    t0 = max(t_lo, 0.0)
    t1 = min(t_hi, 1.0)
    return (t0, t1) if t0 <= t1 else None


def ref_lerp(a, b, t):
    return tuple(x + t * (y - x) for x, y in zip(a, b))


def ref_prism_sdf(ob: Prism, p) -> float:
    dxy = ref_polygon_sdf(p[0], p[1], ob.vertices_ne_m)
    if len(p) == 2:
        return dxy
    dz = max(ob.down_min_m - p[2], p[2] - ob.down_max_m)
    if dxy <= 0.0 and dz <= 0.0:
        return max(dxy, dz)
    return math.hypot(max(dxy, 0.0), max(dz, 0.0))


def ref_prism_segment_distance(ob: Prism, a, b) -> float:
    verts = ob.vertices_ne_m
    if len(a) == 2:
        return ref_segment_polygon_dist_2d(a, b, verts)
    seg_lo, seg_hi = min(a[2], b[2]), max(a[2], b[2])
    z_lo = ob.down_min_m if math.isfinite(ob.down_min_m) else min(seg_lo, ob.down_max_m) - 1.0
    z_hi = ob.down_max_m if math.isfinite(ob.down_max_m) else max(seg_hi, z_lo) + 1.0
    slab = ref_slab_interval(a[2], b[2], z_lo, z_hi)
    if slab is not None:
        pa, pb = ref_lerp(a, b, slab[0]), ref_lerp(a, b, slab[1])
        if ref_segment_polygon_dist_2d(pa[:2], pb[:2], verts) <= 0.0:
            return 0.0
    best2 = min(max(ref_prism_sdf(ob, a), 0.0), max(ref_prism_sdf(ob, b), 0.0)) ** 2
    n = len(verts)
    prev = verts[n - 1]
    for i in range(n):
        cur = verts[i]
        for e0, e1 in (
            ((prev[0], prev[1], z_lo), (cur[0], cur[1], z_lo)),
            ((prev[0], prev[1], z_hi), (cur[0], cur[1], z_hi)),
            ((cur[0], cur[1], z_lo), (cur[0], cur[1], z_hi)),
        ):
            d2 = ref_segment_segment_dist2(a, b, e0, e1)
            if d2 < best2:
                best2 = d2
        prev = cur
    return math.sqrt(best2)


def bits(x: float) -> bytes:
    return struct.pack("<d", x)


# --- strategies ----------------------------------------------------------------------------


@st.composite
def convex_polygon(draw):
    """An affine image of a regular polygon (convex), random size, rotation and shear."""
    n = draw(st.integers(3, 8))
    cx, cy = draw(coord), draw(coord)
    rot = draw(st.floats(0.0, 2 * math.pi))
    sx, sy, shear = draw(st.floats(0.5, 15.0)), draw(st.floats(0.5, 15.0)), draw(st.floats(-1.0, 1.0))
    pts = []
    for k in range(n):
        u, v = math.cos(rot + 2 * math.pi * k / n), math.sin(rot + 2 * math.pi * k / n)
        pts.append((cx + sx * u + shear * v, cy + sy * v))
    return pts


@st.composite
def star_polygon(draw):
    """A simple star-shaped polygon, non-convex for most radii."""
    n = draw(st.integers(3, 9))
    cx, cy = draw(coord), draw(coord)
    radii = draw(st.lists(st.floats(1.0, 15.0), min_size=n, max_size=n))
    phase = draw(st.floats(0.0, 1.0))
    return [
        (cx + r * math.cos(2 * math.pi * (k + phase) / n), cy + r * math.sin(2 * math.pi * (k + phase) / n))
        for k, r in enumerate(radii)
    ]


@st.composite
def rectangle(draw):
    """An axis-aligned rectangle with integer corners (the campaign's fences)."""
    x0, y0 = draw(st.integers(-30, 30)), draw(st.integers(-30, 30))
    w, h = draw(st.integers(1, 40)), draw(st.integers(1, 40))
    return [
        (float(x0), float(y0)),
        (float(x0 + w), float(y0)),
        (float(x0 + w), float(y0 + h)),
        (float(x0), float(y0 + h)),
    ]


@st.composite
def down_limits(draw):
    lo = draw(st.floats(-30.0, 10.0))
    hi = lo + draw(st.floats(0.5, 30.0))
    kind = draw(st.sampled_from(["finite", "no floor", "no ceiling", "infinite"]))
    return {
        "finite": (lo, hi),
        "no floor": (lo, math.inf),
        "no ceiling": (-math.inf, hi),
        "infinite": (-math.inf, math.inf),
    }[kind]


@st.composite
def prism(draw):
    verts = draw(st.one_of(convex_polygon(), star_polygon(), rectangle()))
    lo, hi = draw(down_limits())
    return Prism(verts, lo, hi)


@st.composite
def point_near(draw, ob: Prism, d: int):
    """A point anywhere, on a vertex, on an edge, or with its height on a limit."""
    verts = ob.vertices_ne_m
    kind = draw(st.sampled_from(["free", "vertex", "edge", "edge-offset"]))
    i = draw(st.integers(0, len(verts) - 1))
    v0, v1 = verts[i], verts[(i + 1) % len(verts)]
    if kind == "free":
        xy = (draw(coord), draw(coord))
    elif kind == "vertex":
        xy = v0
    else:
        t = draw(st.sampled_from([0.0, 0.5, 1.0]) | st.floats(-0.5, 1.5))
        xy = ref_lerp(v0, v1, t)
        if kind == "edge-offset":
            xy = (xy[0] + draw(st.sampled_from([-1.0, 1.0, 0.5])), xy[1])
    if d == 2:
        return (float(xy[0]), float(xy[1]))
    limits = [z for z in (ob.down_min_m, ob.down_max_m) if math.isfinite(z)]
    z = draw(st.sampled_from(limits) | coord) if limits else draw(coord)
    return (float(xy[0]), float(xy[1]), float(z))


@st.composite
def segment_case(draw, d: int):
    ob = draw(prism())
    a = draw(point_near(ob, d))
    b = a if draw(st.integers(0, 5)) == 0 else draw(point_near(ob, d))  # degenerate a == b
    return ob, a, b


# --- the kernels against the reference -----------------------------------------------------


@given(case=segment_case(3))
@SETTINGS
def test_3d_segment_distance_is_bit_identical(case):
    ob, a, b = case
    assert bits(ob.segment_distance(a, b)) == bits(ref_prism_segment_distance(ob, a, b))
    assert bits(ob.segment_distance(b, a)) == bits(ref_prism_segment_distance(ob, b, a))


@given(case=segment_case(2))
@SETTINGS
def test_2d_segment_distance_is_bit_identical(case):
    ob, a, b = case
    assert bits(ob.segment_distance(a, b)) == bits(ref_prism_segment_distance(ob, a, b))
    verts = np.asarray(ob.vertices_ne_m)
    direct = kern.segment_polygon_dist_2d(a[0], a[1], b[0], b[1], verts)
    assert bits(direct) == bits(ref_segment_polygon_dist_2d(a, b, ob.vertices_ne_m))


@given(case=segment_case(3))
@SETTINGS
def test_point_sdf_is_bit_identical_in_2d_and_3d(case):
    ob, a, _ = case
    assert bits(ob.sdf(a)) == bits(ref_prism_sdf(ob, a))
    assert bits(ob.sdf(a[:2])) == bits(ref_prism_sdf(ob, a[:2]))


@given(case=segment_case(3), margin=st.sampled_from([0.0, 0.5, 1.0, 3.0]))
@settings(deadline=None, max_examples=60)
def test_world_segment_free_gives_the_former_booleans(case, margin):
    ob, a, b = case
    other = Prism([(100.0, 100.0), (110.0, 100.0), (105.0, 108.0)], -5.0, 5.0)
    world = World([ob, other], (-60.0, -60.0, -60.0), (120.0, 120.0, 60.0), margin_m=margin)
    world_2d = World([ob, other], (-60.0, -60.0), (120.0, 120.0), margin_m=margin)
    fast = (world.segment_free(a, b), world_2d.segment_free(a[:2], b[:2]))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Prism, "segment_distance", ref_prism_segment_distance)
        before = (world.segment_free(a, b), world_2d.segment_free(a[:2], b[:2]))
    assert fast == before


def test_the_fences_world_matches_on_random_segments():
    """The campaign's two fences (infinite prisms), 2000 random segments, short and long."""
    fences = [
        Prism(((60.0, 8.0), (120.0, 8.0), (120.0, 45.0), (60.0, 45.0))),
        Prism(((95.0, -10.0), (150.0, -10.0), (150.0, -50.0), (95.0, -50.0))),
    ]
    rng = np.random.default_rng(3)
    lo, hi = np.array([-60.0, -80.0, -60.0]), np.array([240.0, 80.0, -5.0])
    a = rng.uniform(lo, hi, (2000, 3))
    b = np.where(rng.random((2000, 1)) < 0.5, rng.uniform(lo, hi, (2000, 3)), a + rng.normal(0, 10, (2000, 3)))
    for p, q in zip(a, b):
        p, q = tuple(map(float, p)), tuple(map(float, q))
        for ob in fences:
            assert bits(ob.segment_distance(p, q)) == bits(ref_prism_segment_distance(ob, p, q))


# --- the two places where a naive compiled version would differ ----------------------------


def test_square_is_the_c_librarys_pow_not_a_product():
    """Python's ``x ** 2`` is ``pow(x, 2.0)``, which differs from ``x * x`` now and then."""
    rng = random.Random(5)
    xs = [rng.uniform(0.0, 100.0) for _ in range(20000)]
    differing = [x for x in xs if x**2 != x * x]
    assert differing  # otherwise this test would prove nothing on this platform
    assert all(kern._py_square(x) == x**2 for x in differing + xs[:2000] + [0.0, -0.0, 1.0])
    with pytest.raises(OverflowError):
        kern._py_square(1e200)


@given(x=st.floats(0.0, 1e300) | st.floats(0.0, 1e-300), y=st.floats(0.0, 1e300) | st.floats(0.0, 1e-300))
@settings(deadline=None, max_examples=300)
def test_hypot_is_pythons(x, y):
    assert bits(kern._python_hypot(x, y)) == bits(math.hypot(x, y))


def test_hypot_of_infinities_and_zeros():
    for x, y in ((math.inf, 1.0), (2.0, math.inf), (0.0, 0.0), (5e-324, 5e-324), (3.0, 4.0)):
        assert bits(kern._python_hypot(x, y)) == bits(math.hypot(x, y))


# --- the Prism value -----------------------------------------------------------------------


def test_the_vertex_array_follows_replace_and_pickle():
    ob = Prism([(0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (0.0, 3.0), (0.0, 0.0)], -2.0, 2.0)
    assert ob._vertices_array.shape == (4, 2) and ob._vertices_array.flags.c_contiguous
    moved = dataclasses.replace(ob, vertices_ne_m=[(10.0, 0.0), (14.0, 0.0), (14.0, 3.0)])
    assert np.array_equal(moved._vertices_array, np.asarray(moved.vertices_ne_m))
    restored = pickle.loads(pickle.dumps(ob))
    assert restored == ob
    a, b = (-1.0, 1.0, 0.0), (5.0, 2.0, 3.0)
    assert bits(restored.segment_distance(a, b)) == bits(ref_prism_segment_distance(ob, a, b))


def test_warm_up_compiles_every_public_kernel():
    kern.warm_up()
    for name in kern.__all__:
        fn = getattr(kern, name)
        assert name == "warm_up" or fn.signatures, name


def test_many_random_segments_near_finite_prisms_match():
    """Random prisms with finite limits, 6000 segments ending beside their faces and edges: the
    cases where an end point's distance (``** 2`` of a ``math.hypot``) is the answer."""
    rng = np.random.default_rng(11)
    for _ in range(60):
        n = int(rng.integers(3, 8))
        ang = np.sort(rng.uniform(0.0, 2 * math.pi, n)) if rng.random() < 0.5 else np.arange(n) * 2 * math.pi / n
        r = rng.uniform(2.0, 12.0, n)
        verts = np.c_[r * np.cos(ang), r * np.sin(ang)] + rng.uniform(-20, 20, 2)
        try:
            ob = Prism(verts, float(rng.uniform(-10, 0)), float(rng.uniform(1, 10)))
        except Exception:  # a degenerate draw (zero area)
            continue
        centre = verts.mean(axis=0)
        for _ in range(100):
            a = np.r_[centre + rng.normal(0, 12, 2), rng.uniform(-25, 25)]
            b = a + rng.normal(0, 3, 3) * rng.choice([1.0, 0.0], p=[0.9, 0.1])
            p, q = tuple(map(float, a)), tuple(map(float, b))
            assert bits(ob.segment_distance(p, q)) == bits(ref_prism_segment_distance(ob, p, q))
            assert bits(ob.sdf(p)) == bits(ref_prism_sdf(ob, p))
