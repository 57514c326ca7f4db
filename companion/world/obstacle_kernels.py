"""Compiled (numba) point and segment tests against every obstacle of a world of balls, vertical
cylinders and prisms, with the booleans of :meth:`~companion.world.world.World.point_free` and
:meth:`~companion.world.world.World.segment_free`.

The world's scalar tests walk its index grid and compare each obstacle's exact distance with
the margin: the ball formula inline, ``Cylinder``/``Prism`` by their ``sdf`` and
``segment_distance``. The grid's cell lists are closed (padded bounding boxes), so an obstacle
the grid leaves out of a query is one whose distance exceeds the margin; testing every
obstacle with the same arithmetic therefore gives the same answer. The kernels here do so in one
compiled call:

- balls: the closest point clamped to the segment, as ``World.segment_free`` writes it;
- cylinders: ``Cylinder.sdf`` and ``Cylinder.segment_distance`` step by step (``math.hypot`` as
  CPython computes it, Python's ``min``/``max``, ``slab_interval``, ``lerp`` and, for the part of
  a segment above or below a finite cylinder, the same golden-section search,
  ``geometry.golden_min``, with the same 90 steps);
- prisms: the kernels of :mod:`companion.world.polyhedral_kernels`, which ``Prism`` itself runs.

A world's obstacles are handed over as the tuple :func:`space_of` builds, ``space``:
``(lo (d,), hi (d,), centres (N, d), r2 (N,), kinds (M,), params (M, 5), vstart (M + 1,),
verts (V, 2), margin, boxes (M, 4), slack)``: the bounds, the inflated balls, and the other
obstacles in the world's order, ``kinds`` 0 (cylinder, ``params`` row ``cx, cy, r, down_min,
down_max``) or 1 (prism, ``params`` row ``0, 0, 0, down_min, down_max``, vertices
``verts[vstart[j]:vstart[j + 1]]``), with their north-east boxes ``n_min, e_min, n_max, e_max``.

A cylinder or prism whose box lies farther than ``margin + slack`` from a query's box (in north
or east) is skipped without computing its distance: every distance the Python methods compute
there exceeds the margin, since their rounding errors (a few units in the last place of the
coordinates) are far below ``slack`` = 1e-9 x (1 + the largest coordinate of the world), so the
answers do not change.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numba import njit

from companion.world.polyhedral_kernels import (
    _point_segment_dist2_2d,
    _py_max,
    _py_min,
    _python_hypot,
    _slab_interval,
    polygon_sdf,
    prism_sdf_3d,
    prism_segment_distance,
    segment_polygon_dist_2d,
)
from companion.world.polyhedral_obstacles import Prism
from companion.world.round_obstacles import Cylinder

__all__ = [
    "ball_arrays",
    "ball_table",
    "space_of",
    "supported",
    "segment_clear",
    "point_clear",
    "other_sdf",
    "box_gap",
    "CYLINDER",
    "PRISM",
]

CYLINDER, PRISM = 0, 1
_GOLDEN_ITERATIONS = 90  # geometry.golden_min's default
_MEMO_KEY = ("obstacle_kernels", "space")


def supported(world) -> bool:
    """True when every obstacle that is not a ball is a ``Cylinder`` or a ``Prism``."""
    return all(isinstance(ob, (Cylinder, Prism)) for ob in world.non_ball_obstacles)


_BALLS_KEY = ("segments_free_from", "balls")
_TABLE_KEY = ("segments", "ball_table")


def ball_arrays(world) -> tuple[np.ndarray, np.ndarray]:
    """``(centres (N, d), r_inflated^2 (N,))`` of the world's discs/spheres, memoised per world."""
    found = world._memo.get(_BALLS_KEY)
    if found is None:
        d = world.dim
        rows = ball_table(world)
        found = (np.ascontiguousarray(rows[:, :d]), np.ascontiguousarray(rows[:, d]))
        world._memo[_BALLS_KEY] = found
    return found


def ball_table(world) -> np.ndarray:
    """The world's inflated discs/spheres as rows ``(centre..., r^2, r)``, (N, d + 2), memoised (read it only)."""
    found = world._memo.get(_TABLE_KEY)
    if found is None:
        balls = world.inflated_balls
        flat = np.fromiter(itertools.chain.from_iterable(balls), dtype=float, count=len(balls) * (world.dim + 2))
        found = flat.reshape(-1, world.dim + 2)
        world._memo[_TABLE_KEY] = found
    return found


def space_of(world) -> tuple:
    """The kernels' ``space`` tuple of ``world`` (module docstring), memoised per world.

    Raises
    ------
    ValueError
        The world has an obstacle other than a disc, sphere, cylinder or prism (a ``Box``).
    """
    found = world._memo.get(_MEMO_KEY)
    if found is None:
        if not supported(world):
            raise ValueError("space_of: the world has an obstacle the kernels do not know (Box)")
        centres, r2 = ball_arrays(world)
        others = world.non_ball_obstacles
        kinds = np.empty(len(others), dtype=np.int64)
        params = np.zeros((len(others), 5))
        vstart = np.zeros(len(others) + 1, dtype=np.int64)
        rows = []
        for j, ob in enumerate(others):
            if isinstance(ob, Cylinder):
                kinds[j] = CYLINDER
                params[j] = (ob.center_ne_m[0], ob.center_ne_m[1], ob.radius_m, ob.down_min_m, ob.down_max_m)
            else:
                kinds[j] = PRISM
                params[j, 3:] = (ob.down_min_m, ob.down_max_m)
                rows.append(ob._vertices_array)
            vstart[j + 1] = vstart[j] + (0 if kinds[j] == CYLINDER else ob._vertices_array.shape[0])
        verts = np.ascontiguousarray(np.vstack(rows) if rows else np.zeros((0, 2)))
        boxes = np.array([ob.aabb(2)[0] + ob.aabb(2)[1] for ob in others], dtype=float).reshape(-1, 4)
        lo, hi = world.bounds_min, world.bounds_max
        largest = max(float(np.abs(lo).max()), float(np.abs(hi).max()), float(np.abs(boxes).max(initial=0.0)))
        found = (
            lo,
            hi,
            centres,
            r2,
            kinds,
            params,
            vstart,
            verts,
            float(world.margin_m),
            boxes,
            1e-9 * (1.0 + largest),
        )
        world._memo[_MEMO_KEY] = found
    return found


# ---------------------------------------------------------------------------- cylinders
@njit(cache=True)
def _cylinder_sdf_3d(
    x: float, y: float, z: float, cx: float, cy: float, r: float, down_min: float, down_max: float
) -> float:
    """``Cylinder.sdf`` of a 3D point."""
    dr = _python_hypot(x - cx, y - cy) - r
    dz = _py_max(down_min - z, z - down_max)
    if dr <= 0.0 and dz <= 0.0:
        return _py_max(dr, dz)
    return _python_hypot(_py_max(dr, 0.0), _py_max(dz, 0.0))


@njit(cache=True)
def _cylinder_dist_at(t: float, a, b, cx: float, cy: float, r: float, down_min: float, down_max: float) -> float:
    """``max(sdf(lerp(a, b, t)), 0.0)``: the function the golden-section search minimises."""
    x = a[0] + t * (b[0] - a[0])
    y = a[1] + t * (b[1] - a[1])
    z = a[2] + t * (b[2] - a[2])
    return _py_max(_cylinder_sdf_3d(x, y, z, cx, cy, r, down_min, down_max), 0.0)


@njit(cache=True)
def _cylinder_golden_min(
    a, b, cx: float, cy: float, r: float, down_min: float, down_max: float, lo: float, hi: float
) -> float:
    """``geometry.golden_min(dist_at, lo, hi)`` of ``Cylinder.segment_distance``."""
    inv_phi = (math.sqrt(5.0) - 1.0) / 2.0
    x1 = hi - inv_phi * (hi - lo)
    x2 = lo + inv_phi * (hi - lo)
    f1 = _cylinder_dist_at(x1, a, b, cx, cy, r, down_min, down_max)
    f2 = _cylinder_dist_at(x2, a, b, cx, cy, r, down_min, down_max)
    best = _cylinder_dist_at(lo, a, b, cx, cy, r, down_min, down_max)  # min(f(lo), f(hi), f1, f2)
    best = _py_min(best, _cylinder_dist_at(hi, a, b, cx, cy, r, down_min, down_max))
    best = _py_min(_py_min(best, f1), f2)
    for _ in range(_GOLDEN_ITERATIONS):
        if hi - lo <= 1e-15:
            break
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - inv_phi * (hi - lo)
            f1 = _cylinder_dist_at(x1, a, b, cx, cy, r, down_min, down_max)
            if f1 < best:
                best = f1
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + inv_phi * (hi - lo)
            f2 = _cylinder_dist_at(x2, a, b, cx, cy, r, down_min, down_max)
            if f2 < best:
                best = f2
    return best


@njit(cache=True)
def cylinder_segment_distance(a, b, cx: float, cy: float, r: float, down_min: float, down_max: float) -> float:
    """``Cylinder.segment_distance(a, b)`` (2 or 3 coordinates each): exact distance (m), 0 when they meet."""
    if len(a) == 2:
        d = math.sqrt(_point_segment_dist2_2d(cx, cy, a[0], a[1], b[0], b[1])) - r
        return d if d > 0.0 else 0.0
    best = math.inf
    found, t0, t1 = _slab_interval(a[2], b[2], down_min, down_max)
    if found:
        pax, pay = a[0] + t0 * (b[0] - a[0]), a[1] + t0 * (b[1] - a[1])
        pbx, pby = a[0] + t1 * (b[0] - a[0]), a[1] + t1 * (b[1] - a[1])
        d = math.sqrt(_point_segment_dist2_2d(cx, cy, pax, pay, pbx, pby)) - r
        best = d if d > 0.0 else 0.0
        if best == 0.0:
            return 0.0
        if t0 > 0.0:
            best = _py_min(best, _cylinder_golden_min(a, b, cx, cy, r, down_min, down_max, 0.0, t0))
        if t1 < 1.0:
            best = _py_min(best, _cylinder_golden_min(a, b, cx, cy, r, down_min, down_max, t1, 1.0))
        return best
    return _py_min(best, _cylinder_golden_min(a, b, cx, cy, r, down_min, down_max, 0.0, 1.0))


# ---------------------------------------------------------------------------- any obstacle
@njit(cache=True)
def box_gap(j: int, n_lo: float, e_lo: float, n_hi: float, e_hi: float, space) -> float:
    """Separation (m) in north or east between obstacle ``j``'s box and the box ``[n_lo, n_hi] x [e_lo, e_hi]``."""
    box = space[9]
    return max(box[j, 0] - n_hi, n_lo - box[j, 2], box[j, 1] - e_hi, e_lo - box[j, 3])


@njit(cache=True)
def other_sdf(j: int, p, space) -> float:
    """``sdf(p)`` of the world's ``j``-th obstacle that is not a ball (``p``: d floats)."""
    kinds, params, vstart, verts = space[4], space[5], space[6], space[7]
    if kinds[j] == CYLINDER:
        if len(p) == 2:
            return _python_hypot(p[0] - params[j, 0], p[1] - params[j, 1]) - params[j, 2]
        return _cylinder_sdf_3d(p[0], p[1], p[2], params[j, 0], params[j, 1], params[j, 2], params[j, 3], params[j, 4])
    poly = verts[vstart[j] : vstart[j + 1]]
    if len(p) == 2:
        return polygon_sdf(p[0], p[1], poly)
    return prism_sdf_3d(p[0], p[1], p[2], poly, params[j, 3], params[j, 4])


@njit(cache=True)
def _other_segment_distance(j: int, a, b, space) -> float:
    """``segment_distance(a, b)`` of the world's ``j``-th obstacle that is not a ball."""
    kinds, params, vstart, verts = space[4], space[5], space[6], space[7]
    if kinds[j] == CYLINDER:
        return cylinder_segment_distance(a, b, params[j, 0], params[j, 1], params[j, 2], params[j, 3], params[j, 4])
    poly = verts[vstart[j] : vstart[j + 1]]
    if len(a) == 2:
        return segment_polygon_dist_2d(a[0], a[1], b[0], b[1], poly)
    return prism_segment_distance(a[0], a[1], a[2], b[0], b[1], b[2], poly, params[j, 3], params[j, 4])


@njit(cache=True)
def segment_clear(a, b, space) -> bool:
    """``World.segment_free(a, b)`` for ``a``, ``b`` arrays of d floats (``space``: :func:`space_of`)."""
    lo, hi, centres, r2, kinds, margin = space[0], space[1], space[2], space[3], space[4], space[8]
    d = lo.shape[0]
    for k in range(d):
        if not (lo[k] <= a[k] and a[k] <= hi[k] and lo[k] <= b[k] and b[k] <= hi[k]):
            return False
    delta = np.empty(d)
    for k in range(d):
        delta[k] = b[k] - a[k]
    l2 = delta[0] * delta[0]
    for k in range(1, d):
        l2 += delta[k] * delta[k]
    for j in range(centres.shape[0]):
        t = 0.0
        if l2 > 0.0:
            num = (centres[j, 0] - a[0]) * delta[0]
            for k in range(1, d):
                num += (centres[j, k] - a[k]) * delta[k]
            t = num / l2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        q = a[0] + t * delta[0] - centres[j, 0]
        q2 = q * q
        for k in range(1, d):
            q = a[k] + t * delta[k] - centres[j, k]
            q2 += q * q
        if q2 <= r2[j]:
            return False
    reach = margin + space[10]
    n_lo, n_hi = min(a[0], b[0]), max(a[0], b[0])
    e_lo, e_hi = min(a[1], b[1]), max(a[1], b[1])
    for j in range(kinds.shape[0]):
        if box_gap(j, n_lo, e_lo, n_hi, e_hi, space) > reach:
            continue
        if _other_segment_distance(j, a, b, space) <= margin:
            return False
    return True


@njit(cache=True)
def point_clear(x, space) -> bool:
    """``World.point_free(x)`` for ``x`` an array of d floats (``space``: :func:`space_of`)."""
    lo, hi, centres, r2, kinds, margin = space[0], space[1], space[2], space[3], space[4], space[8]
    d = lo.shape[0]
    for k in range(d):
        if not (lo[k] <= x[k] and x[k] <= hi[k]):
            return False
    for j in range(centres.shape[0]):
        dx = x[0] - centres[j, 0]
        d2 = dx * dx
        for k in range(1, d):
            dk = x[k] - centres[j, k]
            d2 += dk * dk
        if d2 <= r2[j]:
            return False
    reach = margin + space[10]
    for j in range(kinds.shape[0]):
        if box_gap(j, x[0], x[1], x[0], x[1], space) > reach:
            continue
        if other_sdf(j, x, space) <= margin:
            return False
    return True
