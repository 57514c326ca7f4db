"""Compiled (numba) segment and point queries of the vertical ``Prism``, bit-identical to Python.

:meth:`~companion.world.polyhedral_obstacles.Prism.segment_distance` in plain Python calls
:func:`companion.world.geometry.segment_segment_dist2` a dozen times or more per query (every
wall and cap edge), which made it a fifth of the planner's CPU in a fenced world. The kernels
here do a whole query in one compiled call with the same arithmetic, in the same order, as the
Python code (``geometry``, ``obstacles.slab_interval`` and ``lerp``,
``heli_common.geometry.point_in_polygon``), so the results agree to the last bit:

- no ``fastmath``: LLVM neither reassociates nor contracts to fused multiply-adds;
- Python's ``sum`` of a generator adds left to right from 0, and so do the kernels;
- ``min``/``max``, ``x ** 2`` and ``math.hypot`` as Python computes them
  (``heli_common.pyfloat``).

Vertices are passed as a C-contiguous ``(P, 2)`` float64 array (north, east) in the polygon's
order, the last vertex joining the first. The kernels compile at their first call (or at
:func:`warm_up`) and are cached on disk (``cache=True``); importing this module compiles nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from heli_common.pyfloat import py_hypot as _python_hypot
from heli_common.pyfloat import py_max as _py_max
from heli_common.pyfloat import py_min as _py_min
from heli_common.pyfloat import py_square as _py_square

__all__ = ["segment_polygon_dist_2d", "polygon_sdf", "prism_sdf_3d", "prism_segment_distance", "warm_up"]

_EPS = 1e-12  # geometry._EPS
_SLAB_EPS = 1e-15  # obstacles.slab_interval's threshold on the segment's dz


@njit(cache=True)
def _clamp01(x: float) -> float:
    """``min(max(x, 0.0), 1.0)`` with Python's rules."""
    return _py_min(_py_max(x, 0.0), 1.0)


@njit(cache=True)
def _seg_seg_params(a: float, e: float, f: float, c: float, b: float) -> tuple[float, float]:
    """Closest-point parameters ``(s, t)`` of ``geometry.segment_segment_dist2`` (a, e > eps)."""
    denom = a * e - b * b
    s = _clamp01((b * f - c * e) / denom) if denom > _EPS * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = _clamp01(-c / a)
    elif t > 1.0:
        t = 1.0
        s = _clamp01((b - c) / a)
    return s, t


@njit(cache=True)
def _seg_seg_dist2_2d(
    p1x: float, p1y: float, q1x: float, q1y: float, p2x: float, p2y: float, q2x: float, q2y: float
) -> float:
    """``geometry.segment_segment_dist2`` for 2D points given coordinate by coordinate."""
    d1x, d1y = q1x - p1x, q1y - p1y
    d2x, d2y = q2x - p2x, q2y - p2y
    rx, ry = p1x - p2x, p1y - p2y
    a = 0.0 + d1x * d1x + d1y * d1y
    e = 0.0 + d2x * d2x + d2y * d2y
    f = 0.0 + d2x * rx + d2y * ry
    if a <= _EPS and e <= _EPS:
        return 0.0 + rx * rx + ry * ry
    if a <= _EPS:
        s = 0.0
        t = _clamp01(f / e)
    else:
        c = 0.0 + d1x * rx + d1y * ry
        if e <= _EPS:
            t = 0.0
            s = _clamp01(-c / a)
        else:
            s, t = _seg_seg_params(a, e, f, c, 0.0 + d1x * d2x + d1y * d2y)
    qx = (p1x + s * d1x) - (p2x + t * d2x)
    qy = (p1y + s * d1y) - (p2y + t * d2y)
    return 0.0 + qx * qx + qy * qy


@njit(cache=True)
def _seg_seg_dist2_3d(
    p1x: float,
    p1y: float,
    p1z: float,
    q1x: float,
    q1y: float,
    q1z: float,
    p2x: float,
    p2y: float,
    p2z: float,
    q2x: float,
    q2y: float,
    q2z: float,
) -> float:
    """``geometry.segment_segment_dist2`` for 3D points given coordinate by coordinate."""
    d1x, d1y, d1z = q1x - p1x, q1y - p1y, q1z - p1z
    d2x, d2y, d2z = q2x - p2x, q2y - p2y, q2z - p2z
    rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
    a = 0.0 + d1x * d1x + d1y * d1y + d1z * d1z
    e = 0.0 + d2x * d2x + d2y * d2y + d2z * d2z
    f = 0.0 + d2x * rx + d2y * ry + d2z * rz
    if a <= _EPS and e <= _EPS:
        return 0.0 + rx * rx + ry * ry + rz * rz
    if a <= _EPS:
        s = 0.0
        t = _clamp01(f / e)
    else:
        c = 0.0 + d1x * rx + d1y * ry + d1z * rz
        if e <= _EPS:
            t = 0.0
            s = _clamp01(-c / a)
        else:
            s, t = _seg_seg_params(a, e, f, c, 0.0 + d1x * d2x + d1y * d2y + d1z * d2z)
    qx = (p1x + s * d1x) - (p2x + t * d2x)
    qy = (p1y + s * d1y) - (p2y + t * d2y)
    qz = (p1z + s * d1z) - (p2z + t * d2z)
    return 0.0 + qx * qx + qy * qy + qz * qz


@njit(cache=True)
def _point_segment_dist2_2d(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    """``geometry.point_segment_dist2`` for 2D points given coordinate by coordinate."""
    dx = bx - ax
    dy = by - ay
    ab2 = 0.0 + dx * dx + dy * dy
    ap_ab = 0.0 + (px - ax) * dx + (py - ay) * dy
    if ab2 <= _EPS or ap_ab <= 0.0:
        t = 0.0
    elif ap_ab >= ab2:
        t = 1.0
    else:
        t = ap_ab / ab2
    qx = ax + t * (bx - ax) - px
    qy = ay + t * (by - ay) - py
    return 0.0 + qx * qx + qy * qy


@njit(cache=True)
def _point_in_polygon(x: float, y: float, verts: np.ndarray) -> bool:
    """``heli_common.geometry.point_in_polygon`` (even-odd rule) on ``verts`` (P, 2)."""
    inside = False
    n = verts.shape[0]
    if n == 0:
        return False
    xj, yj = verts[n - 1, 0], verts[n - 1, 1]
    for i in range(n):
        xi, yi = verts[i, 0], verts[i, 1]
        if (yi > y) != (yj > y):
            x_cross = xi + (y - yi) * (xj - xi) / (yj - yi)
            if x < x_cross:
                inside = not inside
        xj, yj = xi, yi
    return inside


@njit(cache=True)
def polygon_sdf(x: float, y: float, verts: np.ndarray) -> float:
    """``geometry.polygon_sdf``: signed distance (m) from (x, y) to the polygon ``verts`` (P, 2)."""
    best = math.inf
    n = verts.shape[0]
    for i in range(n):
        j = n - 1 if i == 0 else i - 1
        d2 = _point_segment_dist2_2d(x, y, verts[j, 0], verts[j, 1], verts[i, 0], verts[i, 1])
        if d2 < best:
            best = d2
    d = math.sqrt(best)
    return -d if _point_in_polygon(x, y, verts) else d


@njit(cache=True)
def _orient(px: float, py: float, qx: float, qy: float, rx: float, ry: float) -> float:
    """``segments_cross_2d``'s orientation of ``r`` relative to ``pq``."""
    return (qx - px) * (ry - py) - (qy - py) * (rx - px)


@njit(cache=True)
def _cross_properly(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float) -> bool:
    """The strict straddle test that opens ``geometry.segments_cross_2d``."""
    o1 = _orient(ax, ay, bx, by, cx, cy)
    o2 = _orient(ax, ay, bx, by, dx, dy)
    o3 = _orient(cx, cy, dx, dy, ax, ay)
    o4 = _orient(cx, cy, dx, dy, bx, by)
    return ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and ((o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0))


@njit(cache=True)
def segment_polygon_dist_2d(ax: float, ay: float, bx: float, by: float, verts: np.ndarray) -> float:
    """``geometry.segment_polygon_dist_2d``: distance (m) from segment ``ab`` to the filled polygon.

    Parameters
    ----------
    ax, ay, bx, by : float
        End points (north, east) of the segment (m).
    verts : (P, 2) float64 array, C-contiguous
        Polygon vertices (m), P >= 1.

    Returns
    -------
    float
        0 when the segment meets the polygon (inside, crossing or touching an edge).
    """
    if _point_in_polygon(ax, ay, verts) or _point_in_polygon(bx, by, verts):
        return 0.0
    best = math.inf
    n = verts.shape[0]
    for i in range(n):
        j = n - 1 if i == 0 else i - 1
        cx, cy, dx, dy = verts[j, 0], verts[j, 1], verts[i, 0], verts[i, 1]
        if _cross_properly(ax, ay, bx, by, cx, cy, dx, dy):
            return 0.0
        d2 = _seg_seg_dist2_2d(ax, ay, bx, by, cx, cy, dx, dy)
        if d2 <= _EPS:  # segments_cross_2d's touching case
            return 0.0
        if d2 < best:
            best = d2
    return math.sqrt(best)


@njit(cache=True)
def prism_sdf_3d(x: float, y: float, z: float, verts: np.ndarray, down_min_m: float, down_max_m: float) -> float:
    """``Prism.sdf`` of a 3D point: signed distance (m), negative inside.

    Parameters
    ----------
    x, y, z : float
        The point (north, east, down) (m).
    verts : (P, 2) float64 array, C-contiguous
        The prism's polygon (m).
    down_min_m, down_max_m : float
        The prism's *down* limits (m), infinite allowed.
    """
    dxy = polygon_sdf(x, y, verts)
    dz = _py_max(down_min_m - z, z - down_max_m)
    if dxy <= 0.0 and dz <= 0.0:
        return _py_max(dxy, dz)
    return _python_hypot(_py_max(dxy, 0.0), _py_max(dz, 0.0))


@njit(cache=True)
def _slab_interval(a_z: float, b_z: float, lo: float, hi: float) -> tuple[bool, float, float]:
    """``obstacles.slab_interval`` as ``(found, t0, t1)``."""
    dz = b_z - a_z
    if abs(dz) < _SLAB_EPS:
        return lo <= a_z <= hi, 0.0, 1.0
    t_lo = (lo - a_z) / dz
    t_hi = (hi - a_z) / dz
    if t_lo > t_hi:
        t_lo, t_hi = t_hi, t_lo
    t0 = _py_max(t_lo, 0.0)
    t1 = _py_min(t_hi, 1.0)
    return t0 <= t1, t0, t1


@njit(cache=True)
def _edges_dist2(
    ax: float,
    ay: float,
    az: float,
    bx: float,
    by: float,
    bz: float,
    verts: np.ndarray,
    z_lo: float,
    z_hi: float,
    best2: float,
) -> float:
    """Smaller of ``best2`` and the squared distances from ``ab`` to the prism's cap and wall edges."""
    n = verts.shape[0]
    for i in range(n):
        j = n - 1 if i == 0 else i - 1
        px, py, cx, cy = verts[j, 0], verts[j, 1], verts[i, 0], verts[i, 1]
        d2 = _seg_seg_dist2_3d(ax, ay, az, bx, by, bz, px, py, z_lo, cx, cy, z_lo)
        if d2 < best2:
            best2 = d2
        d2 = _seg_seg_dist2_3d(ax, ay, az, bx, by, bz, px, py, z_hi, cx, cy, z_hi)
        if d2 < best2:
            best2 = d2
        d2 = _seg_seg_dist2_3d(ax, ay, az, bx, by, bz, cx, cy, z_lo, cx, cy, z_hi)
        if d2 < best2:
            best2 = d2
    return best2


@njit(cache=True)
def prism_segment_distance(
    ax: float,
    ay: float,
    az: float,
    bx: float,
    by: float,
    bz: float,
    verts: np.ndarray,
    down_min_m: float,
    down_max_m: float,
) -> float:
    """``Prism.segment_distance`` of a 3D segment: exact distance (m), 0 when they meet.

    Parameters
    ----------
    ax, ay, az, bx, by, bz : float
        End points (north, east, down) of the segment (m).
    verts : (P, 2) float64 array, C-contiguous
        The prism's polygon (m).
    down_min_m, down_max_m : float
        The prism's *down* limits (m), infinite allowed (clamped just beyond the segment).
    """
    seg_lo = _py_min(az, bz)
    seg_hi = _py_max(az, bz)
    z_lo = down_min_m if math.isfinite(down_min_m) else _py_min(seg_lo, down_max_m) - 1.0
    z_hi = down_max_m if math.isfinite(down_max_m) else _py_max(seg_hi, z_lo) + 1.0
    found, t0, t1 = _slab_interval(az, bz, z_lo, z_hi)
    if found:
        pax, pay = ax + t0 * (bx - ax), ay + t0 * (by - ay)
        pbx, pby = ax + t1 * (bx - ax), ay + t1 * (by - ay)
        if segment_polygon_dist_2d(pax, pay, pbx, pby, verts) <= 0.0:
            return 0.0
    sdf_a = _py_max(prism_sdf_3d(ax, ay, az, verts, down_min_m, down_max_m), 0.0)
    sdf_b = _py_max(prism_sdf_3d(bx, by, bz, verts, down_min_m, down_max_m), 0.0)
    best2 = _py_square(_py_min(sdf_a, sdf_b))
    return math.sqrt(_edges_dist2(ax, ay, az, bx, by, bz, verts, z_lo, z_hi, best2))


def warm_up() -> None:
    """Compile (or load from the disk cache) every public kernel for float64 arguments."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    segment_polygon_dist_2d(2.0, 2.0, 3.0, 3.0, square)
    polygon_sdf(2.0, 2.0, square)
    prism_sdf_3d(2.0, 2.0, 2.0, square, -math.inf, math.inf)
    prism_segment_distance(2.0, 2.0, 2.0, 3.0, 3.0, 3.0, square, -1.0, 1.0)
