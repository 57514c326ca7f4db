"""Flat-faced obstacles: the axis-aligned ``Box`` and the vertical ``Prism`` (a polygon extruded
along *down*, a fence exclusion zone), each with an exact signed distance and segment distance
(see ``companion.world.obstacles`` for the conventions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from companion.errors import WorldError
from companion.world.obstacles import Obstacle, down_limits, finite_vector

__all__ = ["Box", "Prism"]

_KERNELS = None  # companion.world.polyhedral_kernels, imported at the first Prism query


def _load_kernels():
    """The Prism's compiled kernels; imported on demand so that ``import companion.world``
    does not import numba (about 0.3 s)."""
    global _KERNELS
    from companion.world import polyhedral_kernels

    _KERNELS = polyhedral_kernels
    return polyhedral_kernels


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
        lo = finite_vector(self.min_m, "Box.min_m", None)
        hi = finite_vector(self.max_m, "Box.max_m", None)
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

    def sdf(self, p: Sequence[float]) -> float:
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

    Notes
    -----
    :meth:`sdf` and :meth:`segment_distance` run the compiled kernels of
    :mod:`companion.world.polyhedral_kernels` on the vertices kept as a (P, 2) float64 array
    (``_vertices_array``, not a field); they return, bit for bit, what the plain-Python
    ``companion.world.geometry`` functions give.
    """

    vertices_ne_m: tuple
    down_min_m: float = -math.inf
    down_max_m: float = math.inf
    kind: ClassVar[str] = "prism"
    if TYPE_CHECKING:
        # set by __post_init__, not a field at run time; to the type checker an attribute
        # outside __init__ (a class-level annotation would make it a dataclass field)
        _vertices_array: np.ndarray = field(init=False, repr=False, compare=False)

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
        object.__setattr__(self, "_vertices_array", np.ascontiguousarray(arr, dtype=np.float64))
        lo, hi = down_limits(self.down_min_m, self.down_max_m, "Prism")
        object.__setattr__(self, "down_min_m", lo)
        object.__setattr__(self, "down_max_m", hi)

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        xs = [v[0] for v in self.vertices_ne_m]
        ys = [v[1] for v in self.vertices_ne_m]
        if dim == 2:
            return (min(xs), min(ys)), (max(xs), max(ys))
        return (min(xs), min(ys), self.down_min_m), (max(xs), max(ys), self.down_max_m)

    def sdf(self, p: Sequence[float]) -> float:
        kern = _KERNELS or _load_kernels()
        if len(p) == 2:
            return kern.polygon_sdf(float(p[0]), float(p[1]), self._vertices_array)
        return kern.prism_sdf_3d(
            float(p[0]), float(p[1]), float(p[2]), self._vertices_array, self.down_min_m, self.down_max_m
        )

    def segment_distance(self, a: tuple, b: tuple) -> float:
        """Exact: intersection test, else endpoint-to-prism and segment-to-edge distances.

        Infinite limits are clamped just beyond the segment: the closest point of a vertical
        extrusion to any point lies at that point's (clamped) height, so this is exact.
        """
        kern = _KERNELS or _load_kernels()
        if len(a) == 2:
            return kern.segment_polygon_dist_2d(
                float(a[0]), float(a[1]), float(b[0]), float(b[1]), self._vertices_array
            )
        return kern.prism_segment_distance(
            float(a[0]),
            float(a[1]),
            float(a[2]),
            float(b[0]),
            float(b[1]),
            float(b[2]),
            self._vertices_array,
            self.down_min_m,
            self.down_max_m,
        )

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
        out: dict[str, Any] = {"type": "prism", "vertices": [list(v) for v in self.vertices_ne_m]}
        if math.isfinite(self.down_min_m):
            out["down_min"] = self.down_min_m
        if math.isfinite(self.down_max_m):
            out["down_max"] = self.down_max_m
        return out
