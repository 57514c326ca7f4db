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

The shapes are in ``round_obstacles`` (Disc, Sphere, Cylinder) and ``polyhedral_obstacles`` (Box,
Prism); this module holds their common interface and the argument checks and segment helpers
they share.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from companion.errors import WorldError

__all__ = ["Obstacle", "finite_vector", "positive_length", "down_limits", "slab_interval", "lerp"]


def finite_vector(value, name: str, length: int | None) -> tuple:
    """``value`` as a tuple of finite floats (``length`` of them, if given); ``WorldError`` naming
    ``name`` otherwise."""
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


def positive_length(value, name: str) -> float:
    """``value`` as a positive finite float; ``WorldError`` naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise WorldError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise WorldError(f"{name}: must be a positive finite number, got {value!r}")
    return v


def down_limits(lo, hi, cls: str) -> tuple[float, float]:
    """``(lo, hi)`` as floats with ``lo < hi`` (infinite allowed, pointing outwards); ``WorldError``
    naming the shape ``cls`` otherwise."""
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


def slab_interval(a_z: float, b_z: float, lo: float, hi: float) -> tuple[float, float] | None:
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


def lerp(a: tuple, b: tuple, t: float) -> tuple:
    """The point ``a + t (b - a)``."""
    return tuple(x + t * (y - x) for x, y in zip(a, b))


class Obstacle:
    """Common interface of all shapes (see the module docstring for conventions)."""

    kind: ClassVar[str] = "obstacle"

    def check_dim(self, dim: int) -> None:
        """Raise :class:`WorldError` if the shape cannot live in a ``dim``-D world."""

    def aabb(self, dim: int) -> tuple[tuple, tuple]:  # pragma: no cover - abstract
        """Axis-aligned bounding box ``(lo, hi)`` of the (un-inflated) shape in ``dim`` D."""
        raise NotImplementedError

    def sdf(self, p: Sequence[float]) -> float:  # pragma: no cover - abstract
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
