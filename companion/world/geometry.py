"""Exact scalar geometry kernels used by the obstacle queries (plain Python floats).

The planner calls these in its inner loop, so they take and return plain floats and tuples:
per ``ANCHORS.md`` a plain-Python check costs a fraction of a numpy call on small arrays.
Reference: C. Ericson, *Real-Time Collision Detection* (2005), sections 5.1.2 (point-segment),
5.1.9 (segment-segment) and 5.4.1 (point in polygon).
"""

from __future__ import annotations

import math

from heli_common.geometry import point_in_polygon

_EPS = 1e-12


def point_segment_dist2(p: tuple, a: tuple, b: tuple) -> float:
    """Squared distance from point ``p`` to segment ``ab`` (any dimension, same length)."""
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


def segment_segment_dist2(p1: tuple, q1: tuple, p2: tuple, q2: tuple) -> float:
    """Squared distance between segments ``p1q1`` and ``p2q2`` (2D or 3D), exact.

    Closest-point parameters by Ericson's clamped solution of the 2x2 normal equations.
    """
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


def segments_cross_2d(a: tuple, b: tuple, c: tuple, d: tuple) -> bool:
    """True when 2D segments ``ab`` and ``cd`` share at least one point (touching counts)."""

    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    o1 = orient(a, b, c)
    o2 = orient(a, b, d)
    o3 = orient(c, d, a)
    o4 = orient(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and ((o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)):
        return True
    # Collinear or touching cases: fall back to a distance test.
    return segment_segment_dist2(a, b, c, d) <= _EPS


def polygon_boundary_dist2(x: float, y: float, vertices: tuple) -> float:
    """Squared distance from (x, y) to the polygon's boundary edges."""
    best = math.inf
    n = len(vertices)
    prev = vertices[n - 1]
    p = (x, y)
    for i in range(n):
        cur = vertices[i]
        d2 = point_segment_dist2(p, prev, cur)
        if d2 < best:
            best = d2
        prev = cur
    return best


def polygon_sdf(x: float, y: float, vertices: tuple) -> float:
    """Signed distance from (x, y) to a simple polygon (negative inside)."""
    d = math.sqrt(polygon_boundary_dist2(x, y, vertices))
    return -d if point_in_polygon((x, y), vertices) else d


def segment_polygon_dist_2d(a: tuple, b: tuple, vertices: tuple) -> float:
    """Exact distance between 2D segment ``ab`` and a filled simple polygon (0 if they meet)."""
    if point_in_polygon(a, vertices) or point_in_polygon(b, vertices):
        return 0.0
    best = math.inf
    n = len(vertices)
    prev = vertices[n - 1]
    for i in range(n):
        cur = vertices[i]
        if segments_cross_2d(a, b, prev, cur):
            return 0.0
        d2 = segment_segment_dist2(a, b, prev, cur)
        if d2 < best:
            best = d2
        prev = cur
    return math.sqrt(best)


def golden_min(f, lo: float, hi: float, iterations: int = 90) -> float:
    """Minimum value of a convex (unimodal) scalar function on ``[lo, hi]``.

    Golden-section search; 90 iterations shrink the bracket by 0.618**90 (about 1e-19), so the
    result is exact to floating-point precision for the distance functions used here.
    """
    inv_phi = (math.sqrt(5.0) - 1.0) / 2.0
    x1 = hi - inv_phi * (hi - lo)
    x2 = lo + inv_phi * (hi - lo)
    f1 = f(x1)
    f2 = f(x2)
    best = min(f(lo), f(hi), f1, f2)
    for _ in range(iterations):
        if hi - lo <= 1e-15:
            break
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - inv_phi * (hi - lo)
            f1 = f(x1)
            if f1 < best:
                best = f1
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + inv_phi * (hi - lo)
            f2 = f(x2)
            if f2 < best:
                best = f2
    return best
