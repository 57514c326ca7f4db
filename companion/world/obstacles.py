"""Obstacle shapes of the planning world: Disc, Sphere, vertical Cylinder, Box and Prism.

Coordinates are local NED metres: ``(north, east)`` in 2D, ``(north, east, down)`` in 3D. Each
shape is an immutable value with an exact signed distance function (negative inside) and an
exact segment distance; the :class:`~companion.world.World` inflates every shape by its safety
margin by comparing these distances against the margin (a Minkowski sum with a ball, the paper's
"vehicle radius plus margin", section 3.1).

Dimensions: ``Disc`` is 2D only and ``Sphere`` 3D only. ``Cylinder`` and ``Prism`` are vertical
(axis along *down*); in a 2D world only their north-east footprint (circle, polygon) is used.
``Box`` is axis-aligned with 2 or 3 dimensions and must match the world's dimension.

Exactness: point, segment and clearance queries are closed form (point-segment, segment-segment,
slab breakpoints) except for the caps of a finite ``Cylinder``, where the convex distance along
the segment is minimised by golden-section search to floating-point precision; nothing is
sampled. References: C. Ericson, *Real-Time Collision Detection*, ch. 5; I. Quilez, "distance
functions" (box and extrusion SDFs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from companion.errors import WorldError
from companion.world import geometry as geo

__all__ = ["Obstacle", "Disc", "Sphere", "Cylinder", "Box", "Prism"]


def _finite_vector(value, name: str, length: int | None) -> tuple:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise WorldError(f"{name}: expected a list of numbers, got {value!r}") from None
    if arr.ndim != 1 or (length is not None and arr.shape[0] != length):
        want = f"{length} numbers" if length is not None else "a flat list of numbers"
        raise WorldError(f"{name}: expected {want}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise WorldError(f"{name}: coordinates must be finite, got {arr.tolist()}")
    return tuple(float(x) for x in arr)


def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise WorldError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise WorldError(f"{name}: must be a positive finite number, got {value!r}")
    return v


def _down_limits(lo, hi, cls: str) -> tuple[float, float]:
    try:
        lo_f, hi_f = float(lo), float(hi)
    except (TypeError, ValueError):
        raise WorldError(f"{cls}.down_min_m/down_max_m: expected numbers, got {lo!r}, {hi!r}") from None
    if math.isnan(lo_f) or math.isnan(hi_f):
        raise WorldError(f"{cls}.down_min_m/down_max_m: NaN is not allowed")
    if lo_f == math.inf or hi_f == -math.inf:
        raise WorldError(f"{cls}.down_min_m/down_max_m: limits point the wrong way ({lo_f}, {hi_f})")
    if not lo_f < hi_f:
        raise WorldError(f"{cls}.down_min_m: must be below down_max_m, got {lo_f} >= {hi_f}")
    return lo_f, hi_f


def _slab_interval(a_z: float, b_z: float, lo: float, hi: float) -> tuple[float, float] | None:
    """Parameter interval ``[t0, t1]`` of segment ``a + t (b - a)`` with ``lo <= z <= hi``."""
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


def _lerp(a: tuple, b: tuple, t: float) -> tuple:
    return tuple(x + t * (y - x) for x, y in zip(a, b))


class Obstacle:
    """Common interface of all shapes (see the module docstring for conventions)."""

    kind: ClassVar[str] = "obstacle"

    def check_dim(self, dim: int) -> None:
        """Raise :class:`WorldError` if the shape cannot live in a ``dim``-D world."""

    def aabb(self, dim: int) -> tuple[tuple, tuple]:  # pragma: no cover - abstract
        """Axis-aligned bounding box ``(lo, hi)`` of the (un-inflated) shape in ``dim`` D."""
        raise NotImplementedError

    def sdf(self, p: tuple) -> float:  # pragma: no cover - abstract
        """Signed distance (m) from point ``p`` (tuple of d floats) to the surface."""
        raise NotImplementedError

    def segment_distance(self, a: tuple, b: tuple) -> float:  # pragma: no cover - abstract
        """Exact distance (m) between segment ``ab`` and the shape, 0 when they meet."""
        raise NotImplementedError

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """Vectorised :meth:`sdf`: ``points`` (K, d) -> (K,)."""
        raise NotImplementedError

    def gradient(self, p: tuple) -> tuple:
        """Unit outward direction of the SDF at ``p`` (central differences, 1 mm)."""
        h = 1e-3
        g = []
        for i in range(len(p)):
            hi = list(p)
            lo = list(p)
            hi[i] += h
            lo[i] -= h
            g.append((self.sdf(tuple(hi)) - self.sdf(tuple(lo))) / (2 * h))
        n = math.sqrt(sum(x * x for x in g))
        if n < 1e-12:
            return tuple(1.0 if i == 0 else 0.0 for i in range(len(p)))
        return tuple(x / n for x in g)

    def to_dict(self) -> dict:  # pragma: no cover - abstract
        """Plain mapping in the world-file format (see :mod:`companion.world.io`)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Disc(Obstacle):
    """Circular obstacle of a 2D world.

    Parameters
    ----------
    center_m : (2,) north, east (m)
    radius_m : float, > 0
    """

    center_m: tuple
    radius_m: float
    kind: ClassVar[str] = "disc"

    def __post_init__(self):
        object.__setattr__(self, "center_m", _finite_vector(self.center_m, "Disc.center_m", 2))
        object.__setattr__(self, "radius_m", _positive(self.radius_m, "Disc.radius_m"))

    def check_dim(self, dim: int) -> None:
        if dim != 2:
            raise WorldError("Disc: only allowed in a 2D world (use Sphere or Cylinder in 3D)")

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        (cx, cy), r = self.center_m, self.radius_m
        return (cx - r, cy - r), (cx + r, cy + r)

    def sdf(self, p: tuple) -> float:
        return math.hypot(p[0] - self.center_m[0], p[1] - self.center_m[1]) - self.radius_m

    def gradient(self, p: tuple) -> tuple:
        dx, dy = p[0] - self.center_m[0], p[1] - self.center_m[1]
        n = math.hypot(dx, dy)
        return (dx / n, dy / n) if n > 1e-12 else (1.0, 0.0)

    def segment_distance(self, a: tuple, b: tuple) -> float:
        d = math.sqrt(geo.point_segment_dist2(self.center_m, a, b)) - self.radius_m
        return d if d > 0.0 else 0.0

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:
        return np.hypot(points[:, 0] - self.center_m[0], points[:, 1] - self.center_m[1]) - self.radius_m

    def to_dict(self) -> dict:
        return {"type": "disc", "center": list(self.center_m), "radius": self.radius_m}


@dataclass(frozen=True)
class Sphere(Obstacle):
    """Spherical obstacle of a 3D world (also the shape of a threat).

    Parameters
    ----------
    center_m : (3,) north, east, down (m)
    radius_m : float, > 0
    """

    center_m: tuple
    radius_m: float
    kind: ClassVar[str] = "sphere"

    def __post_init__(self):
        object.__setattr__(self, "center_m", _finite_vector(self.center_m, "Sphere.center_m", 3))
        object.__setattr__(self, "radius_m", _positive(self.radius_m, "Sphere.radius_m"))

    def check_dim(self, dim: int) -> None:
        if dim != 3:
            raise WorldError("Sphere: only allowed in a 3D world (use Disc in 2D)")

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        r = self.radius_m
        return tuple(c - r for c in self.center_m), tuple(c + r for c in self.center_m)

    def sdf(self, p: tuple) -> float:
        c = self.center_m
        return math.sqrt((p[0] - c[0]) ** 2 + (p[1] - c[1]) ** 2 + (p[2] - c[2]) ** 2) - self.radius_m

    def gradient(self, p: tuple) -> tuple:
        d = [p[i] - self.center_m[i] for i in range(3)]
        n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        return (d[0] / n, d[1] / n, d[2] / n) if n > 1e-12 else (1.0, 0.0, 0.0)

    def segment_distance(self, a: tuple, b: tuple) -> float:
        d = math.sqrt(geo.point_segment_dist2(self.center_m, a, b)) - self.radius_m
        return d if d > 0.0 else 0.0

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points - np.asarray(self.center_m), axis=1) - self.radius_m

    def to_dict(self) -> dict:
        return {"type": "sphere", "center": list(self.center_m), "radius": self.radius_m}


@dataclass(frozen=True)
class Cylinder(Obstacle):
    """Vertical cylinder (a geofence circle or a tower): circle in north-east, limits in down.

    Parameters
    ----------
    center_ne_m : (2,) north, east of the axis (m)
    radius_m : float, > 0
    down_min_m, down_max_m : float
        Extent along *down* (top is ``down_min_m``, i.e. altitude ``-down_min_m``); infinite
        limits are allowed (default: unbounded). Ignored in a 2D world.
    """

    center_ne_m: tuple
    radius_m: float
    down_min_m: float = -math.inf
    down_max_m: float = math.inf
    kind: ClassVar[str] = "cylinder"

    def __post_init__(self):
        object.__setattr__(self, "center_ne_m", _finite_vector(self.center_ne_m, "Cylinder.center_ne_m", 2))
        object.__setattr__(self, "radius_m", _positive(self.radius_m, "Cylinder.radius_m"))
        lo, hi = _down_limits(self.down_min_m, self.down_max_m, "Cylinder")
        object.__setattr__(self, "down_min_m", lo)
        object.__setattr__(self, "down_max_m", hi)

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        (cx, cy), r = self.center_ne_m, self.radius_m
        if dim == 2:
            return (cx - r, cy - r), (cx + r, cy + r)
        return (cx - r, cy - r, self.down_min_m), (cx + r, cy + r, self.down_max_m)

    def _radial(self, p: tuple) -> float:
        return math.hypot(p[0] - self.center_ne_m[0], p[1] - self.center_ne_m[1]) - self.radius_m

    def _dz(self, z: float) -> float:
        return max(self.down_min_m - z, z - self.down_max_m)

    def sdf(self, p: tuple) -> float:
        dr = self._radial(p)
        if len(p) == 2:
            return dr
        dz = self._dz(p[2])
        if dr <= 0.0 and dz <= 0.0:
            return max(dr, dz)
        return math.hypot(max(dr, 0.0), max(dz, 0.0))

    def segment_distance(self, a: tuple, b: tuple) -> float:
        c = self.center_ne_m
        if len(a) == 2:
            d = math.sqrt(geo.point_segment_dist2(c, a, b)) - self.radius_m
            return d if d > 0.0 else 0.0
        best = math.inf
        slab = _slab_interval(a[2], b[2], self.down_min_m, self.down_max_m)
        if slab is not None:
            pa, pb = _lerp(a, b, slab[0]), _lerp(a, b, slab[1])
            d = math.sqrt(geo.point_segment_dist2(c, pa[:2], pb[:2])) - self.radius_m
            best = d if d > 0.0 else 0.0
            if best == 0.0:
                return 0.0
        pieces = []
        if slab is None:
            pieces.append((0.0, 1.0))
        else:
            if slab[0] > 0.0:
                pieces.append((0.0, slab[0]))
            if slab[1] < 1.0:
                pieces.append((slab[1], 1.0))

        def dist_at(t: float) -> float:
            return max(self.sdf(_lerp(a, b, t)), 0.0)

        for lo, hi in pieces:
            best = min(best, geo.golden_min(dist_at, lo, hi))
        return best

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:
        dr = np.hypot(points[:, 0] - self.center_ne_m[0], points[:, 1] - self.center_ne_m[1]) - self.radius_m
        if points.shape[1] == 2:
            return dr
        with np.errstate(invalid="ignore"):
            dz = np.maximum(self.down_min_m - points[:, 2], points[:, 2] - self.down_max_m)
        inside = np.minimum(np.maximum(dr, dz), 0.0)
        return np.hypot(np.maximum(dr, 0.0), np.maximum(dz, 0.0)) + inside

    def to_dict(self) -> dict:
        out = {"type": "cylinder", "center": list(self.center_ne_m), "radius": self.radius_m}
        if math.isfinite(self.down_min_m):
            out["down_min"] = self.down_min_m
        if math.isfinite(self.down_max_m):
            out["down_max"] = self.down_max_m
        return out


@dataclass(frozen=True)
class Box(Obstacle):
    """Axis-aligned box (2D rectangle or 3D box) between ``min_m`` and ``max_m``.

    Parameters
    ----------
    min_m, max_m : (d,) corners (m), ``min_m < max_m`` on every axis, finite.
    """

    min_m: tuple
    max_m: tuple
    kind: ClassVar[str] = "box"

    def __post_init__(self):
        lo = _finite_vector(self.min_m, "Box.min_m", None)
        hi = _finite_vector(self.max_m, "Box.max_m", None)
        if len(lo) not in (2, 3) or len(hi) != len(lo):
            raise WorldError(f"Box.min_m/max_m: expected 2 or 3 numbers each, got {len(lo)} and {len(hi)}")
        if not all(x < y for x, y in zip(lo, hi)):
            raise WorldError(f"Box.max_m: must exceed min_m on every axis, got {lo} and {hi}")
        object.__setattr__(self, "min_m", lo)
        object.__setattr__(self, "max_m", hi)

    def check_dim(self, dim: int) -> None:
        if len(self.min_m) != dim:
            raise WorldError(f"Box: has {len(self.min_m)} dimensions in a {dim}D world")

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        return self.min_m, self.max_m

    def sdf(self, p: tuple) -> float:
        out2 = 0.0
        inner = -math.inf
        for x, lo, hi in zip(p, self.min_m, self.max_m):
            q = lo - x if lo - x > x - hi else x - hi
            if q > 0.0:
                out2 += q * q
            if q > inner:
                inner = q
        return math.sqrt(out2) if out2 > 0.0 else min(inner, 0.0)

    def segment_distance(self, a: tuple, b: tuple) -> float:
        """Exact: the squared distance is a convex quadratic between slab breakpoints."""
        d = [y - x for x, y in zip(a, b)]
        cuts = [0.0, 1.0]
        for ai, di, lo, hi in zip(a, d, self.min_m, self.max_m):
            if abs(di) > 1e-15:
                for bound in (lo, hi):
                    t = (bound - ai) / di
                    if 0.0 < t < 1.0:
                        cuts.append(t)
        cuts.sort()
        best = math.inf
        for t0, t1 in zip(cuts[:-1], cuts[1:]):
            tm = 0.5 * (t0 + t1)
            qa = qb = qc = 0.0  # dist^2(t) = qa t^2 + qb t + qc on [t0, t1]
            for ai, di, lo, hi in zip(a, d, self.min_m, self.max_m):
                x = ai + tm * di
                if x < lo:
                    c0, c1 = lo - ai, -di
                elif x > hi:
                    c0, c1 = ai - hi, di
                else:
                    continue
                qa += c1 * c1
                qb += 2.0 * c0 * c1
                qc += c0 * c0
            if qa > 1e-18:
                t = min(max(-qb / (2.0 * qa), t0), t1)
            else:
                t = t0 if qb >= 0.0 else t1
            val = qa * t * t + qb * t + qc
            if val < best:
                best = val
            if best <= 0.0:
                return 0.0
        return math.sqrt(max(best, 0.0))

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(self.min_m), np.asarray(self.max_m)
        q = np.maximum(lo - points, points - hi)
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

    def to_dict(self) -> dict:
        return {"type": "box", "min": list(self.min_m), "max": list(self.max_m)}


@dataclass(frozen=True)
class Prism(Obstacle):
    """Simple polygon in north-east extruded between two *down* limits (a fence exclusion zone).

    Parameters
    ----------
    vertices_ne_m : (P, 2) polygon vertices, P >= 3, not self-intersecting, either orientation.
    down_min_m, down_max_m : float
        Extent along *down*; altitudes ``h_lo < h_hi`` map to ``down_min_m = -h_hi``,
        ``down_max_m = -h_lo``. Infinite allowed (default). Ignored in a 2D world.
    """

    vertices_ne_m: tuple
    down_min_m: float = -math.inf
    down_max_m: float = math.inf
    kind: ClassVar[str] = "prism"

    def __post_init__(self):
        try:
            arr = np.asarray(self.vertices_ne_m, dtype=float)
        except (TypeError, ValueError):
            raise WorldError("Prism.vertices_ne_m: expected a list of [north, east] pairs") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
            raise WorldError(f"Prism.vertices_ne_m: expected at least 3 [north, east] pairs, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise WorldError("Prism.vertices_ne_m: coordinates must be finite")
        if np.allclose(arr[0], arr[-1]) and arr.shape[0] > 3:
            arr = arr[:-1]  # closed ring given: drop the repeated vertex
        area2 = float(np.sum(arr[:, 0] * np.roll(arr[:, 1], -1) - np.roll(arr[:, 0], -1) * arr[:, 1]))
        if abs(area2) < 1e-9:
            raise WorldError("Prism.vertices_ne_m: the polygon has zero area")
        object.__setattr__(self, "vertices_ne_m", tuple((float(x), float(y)) for x, y in arr))
        lo, hi = _down_limits(self.down_min_m, self.down_max_m, "Prism")
        object.__setattr__(self, "down_min_m", lo)
        object.__setattr__(self, "down_max_m", hi)

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        xs = [v[0] for v in self.vertices_ne_m]
        ys = [v[1] for v in self.vertices_ne_m]
        if dim == 2:
            return (min(xs), min(ys)), (max(xs), max(ys))
        return (min(xs), min(ys), self.down_min_m), (max(xs), max(ys), self.down_max_m)

    def sdf(self, p: tuple) -> float:
        dxy = geo.polygon_sdf(p[0], p[1], self.vertices_ne_m)
        if len(p) == 2:
            return dxy
        dz = max(self.down_min_m - p[2], p[2] - self.down_max_m)
        if dxy <= 0.0 and dz <= 0.0:
            return max(dxy, dz)
        return math.hypot(max(dxy, 0.0), max(dz, 0.0))

    def segment_distance(self, a: tuple, b: tuple) -> float:
        """Exact: intersection test, else endpoint-to-prism and segment-to-edge distances."""
        verts = self.vertices_ne_m
        if len(a) == 2:
            return geo.segment_polygon_dist_2d(a, b, verts)
        # Infinite limits are clamped just beyond the segment: the closest point of a vertical
        # extrusion to any point lies at that point's (clamped) height, so this is exact.
        seg_lo, seg_hi = min(a[2], b[2]), max(a[2], b[2])
        z_lo = self.down_min_m if math.isfinite(self.down_min_m) else min(seg_lo, self.down_max_m) - 1.0
        z_hi = self.down_max_m if math.isfinite(self.down_max_m) else max(seg_hi, z_lo) + 1.0
        slab = _slab_interval(a[2], b[2], z_lo, z_hi)
        if slab is not None:
            pa, pb = _lerp(a, b, slab[0]), _lerp(a, b, slab[1])
            if geo.segment_polygon_dist_2d(pa[:2], pb[:2], verts) <= 0.0:
                return 0.0
        best2 = min(max(self.sdf(a), 0.0), max(self.sdf(b), 0.0)) ** 2
        n = len(verts)
        prev = verts[n - 1]
        for i in range(n):
            cur = verts[i]
            for e0, e1 in (((prev[0], prev[1], z_lo), (cur[0], cur[1], z_lo)),
                           ((prev[0], prev[1], z_hi), (cur[0], cur[1], z_hi)),
                           ((cur[0], cur[1], z_lo), (cur[0], cur[1], z_hi))):
                d2 = geo.segment_segment_dist2(a, b, e0, e1)
                if d2 < best2:
                    best2 = d2
            prev = cur
        return math.sqrt(best2)

    def _polygon_sdf_batch(self, points: np.ndarray) -> np.ndarray:
        x, y = points[:, 0], points[:, 1]
        verts = np.asarray(self.vertices_ne_m)
        inside = np.zeros(len(points), dtype=bool)
        best2 = np.full(len(points), np.inf)
        for (xi, yi), (xj, yj) in zip(verts, np.roll(verts, 1, axis=0)):
            crosses = (yi > y) != (yj > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                x_cross = xi + (y - yi) * (xj - xi) / (yj - yi)
            inside ^= crosses & (x < x_cross)
            ex, ey = xj - xi, yj - yi
            l2 = ex * ex + ey * ey
            t = np.clip(((x - xi) * ex + (y - yi) * ey) / l2, 0.0, 1.0) if l2 > 0 else np.zeros_like(x)
            best2 = np.minimum(best2, (xi + t * ex - x) ** 2 + (yi + t * ey - y) ** 2)
        d = np.sqrt(best2)
        return np.where(inside, -d, d)

    def sdf_batch(self, points: np.ndarray) -> np.ndarray:
        dxy = self._polygon_sdf_batch(points)
        if points.shape[1] == 2:
            return dxy
        with np.errstate(invalid="ignore"):
            dz = np.maximum(self.down_min_m - points[:, 2], points[:, 2] - self.down_max_m)
        inside = np.minimum(np.maximum(dxy, dz), 0.0)
        return np.hypot(np.maximum(dxy, 0.0), np.maximum(dz, 0.0)) + inside

    def to_dict(self) -> dict:
        out = {"type": "prism", "vertices": [list(v) for v in self.vertices_ne_m]}
        if math.isfinite(self.down_min_m):
            out["down_min"] = self.down_min_m
        if math.isfinite(self.down_max_m):
            out["down_max"] = self.down_max_m
        return out
