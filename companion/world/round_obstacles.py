"""Round obstacles: ``Disc`` (2D), ``Sphere`` (3D, also the shape of a threat) and the vertical
``Cylinder`` (a geofence circle or a tower), each with an exact signed distance and segment
distance (see ``companion.world.obstacles`` for the conventions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from companion.errors import WorldError
from companion.world import geometry as geo
from companion.world.obstacles import Obstacle, down_limits, finite_vector, lerp, positive_length, slab_interval

__all__ = ["Disc", "Sphere", "Cylinder"]


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
        object.__setattr__(self, "center_m", finite_vector(self.center_m, "Disc.center_m", 2))
        object.__setattr__(self, "radius_m", positive_length(self.radius_m, "Disc.radius_m"))

    def check_dim(self, dim: int) -> None:
        if dim != 2:
            raise WorldError("Disc: only allowed in a 2D world (use Sphere or Cylinder in 3D)")

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        (cx, cy), r = self.center_m, self.radius_m
        return (cx - r, cy - r), (cx + r, cy + r)

    def sdf(self, p: Sequence[float]) -> float:
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
        object.__setattr__(self, "center_m", finite_vector(self.center_m, "Sphere.center_m", 3))
        object.__setattr__(self, "radius_m", positive_length(self.radius_m, "Sphere.radius_m"))

    def check_dim(self, dim: int) -> None:
        if dim != 3:
            raise WorldError("Sphere: only allowed in a 3D world (use Disc in 2D)")

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        r = self.radius_m
        return tuple(c - r for c in self.center_m), tuple(c + r for c in self.center_m)

    def sdf(self, p: Sequence[float]) -> float:
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
        object.__setattr__(self, "center_ne_m", finite_vector(self.center_ne_m, "Cylinder.center_ne_m", 2))
        object.__setattr__(self, "radius_m", positive_length(self.radius_m, "Cylinder.radius_m"))
        lo, hi = down_limits(self.down_min_m, self.down_max_m, "Cylinder")
        object.__setattr__(self, "down_min_m", lo)
        object.__setattr__(self, "down_max_m", hi)

    def aabb(self, dim: int) -> tuple[tuple, tuple]:
        (cx, cy), r = self.center_ne_m, self.radius_m
        if dim == 2:
            return (cx - r, cy - r), (cx + r, cy + r)
        return (cx - r, cy - r, self.down_min_m), (cx + r, cy + r, self.down_max_m)

    def _radial(self, p: Sequence[float]) -> float:
        return math.hypot(p[0] - self.center_ne_m[0], p[1] - self.center_ne_m[1]) - self.radius_m

    def _dz(self, z: float) -> float:
        return max(self.down_min_m - z, z - self.down_max_m)

    def sdf(self, p: Sequence[float]) -> float:
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
        slab = slab_interval(a[2], b[2], self.down_min_m, self.down_max_m)
        if slab is not None:
            pa, pb = lerp(a, b, slab[0]), lerp(a, b, slab[1])
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
            return max(self.sdf(lerp(a, b, t)), 0.0)

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
