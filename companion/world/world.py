"""The planning world: bounds, obstacles inflated by a safety margin, and exact queries.

Paper section 3.1: the vehicle is a point moving among obstacles inflated by the vehicle radius
plus a safety margin. A point ``p`` is free when it lies inside the bounds (inclusive) and its
signed distance to every obstacle exceeds ``margin_m``; a segment is free when its exact distance
to every obstacle exceeds ``margin_m`` and both ends are inside the (convex) bounds.

Two families of queries share one geometry:

* fast scalar paths for the planner's inner loop (:meth:`World.point_free`,
  :meth:`World.segment_free`, :meth:`World.clearance_at`, :meth:`World.obstacles_near`): plain
  floats and tuples, obstacles looked up in a uniform grid (:mod:`companion.world.index`);
* vectorised batch paths for the API (:meth:`World.is_free`, :meth:`World.clearance_m`,
  :meth:`World.contains`) taking ``(K, d)`` arrays.

Worlds are immutable; :meth:`World.with_threats` returns a new world with extra obstacles.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from companion.errors import WorldError
from companion.world.ball_clearance import ball_clearance_kdtree
from companion.world.index import UniformGrid
from companion.world.obstacles import Obstacle
from companion.world.round_obstacles import Disc, Sphere

__all__ = ["World"]

_BATCH_ROWS = 4096
_KDTREE_FROM = 64  # balls: above this count clearance_m uses a KD-tree of the centres


def _bounds_vector(value, name: str) -> tuple:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise WorldError(f"{name}: expected 2 or 3 numbers, got {value!r}") from None
    if arr.ndim != 1 or arr.shape[0] not in (2, 3):
        raise WorldError(f"{name}: expected 2 or 3 numbers, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise WorldError(f"{name}: must be finite, got {arr.tolist()}")
    return tuple(float(x) for x in arr)


class World:
    """Obstacles inside axis-aligned bounds, inflated by a safety margin.

    Parameters
    ----------
    obstacles : iterable of Obstacle
        ``Disc``/``Box``(2D)/``Cylinder``/``Prism`` in 2D; ``Sphere``/``Box``(3D)/``Cylinder``/
        ``Prism`` in 3D (see :mod:`companion.world.obstacles`).
    bounds_min, bounds_max : (d,) array_like
        Corners of the flyable box in local NED metres, d = 2 (north, east) or 3 (north, east,
        down). ``bounds_min < bounds_max`` on every axis.
    margin_m : float, optional
        Safety margin (vehicle radius plus margin), >= 0: every obstacle is inflated by it.

    Raises
    ------
    WorldError
        Bounds empty, of the wrong size or not finite; margin negative; an obstacle of the wrong
        dimension. The message names the argument.

    Notes
    -----
    ``point_free(p) -> bool`` is the planner's scalar point test (``p`` a tuple of d floats;
    bound to a 2D or 3D specialisation at construction). A World caches derived lookups
    (a KD-tree of sphere centres, the obstacles acting within a distance of each grid cell);
    the caches never change the answers, and the obstacles, bounds and margin cannot change.
    """

    __slots__ = (
        "_dim",
        "_lo",
        "_hi",
        "_margin",
        "_obstacles",
        "_grid",
        "_balls",
        "_other_ids",
        "_cell_balls",
        "_cell_others",
        "_frozen",
        "point_free",
        "_memo",
    )

    def __init__(self, obstacles: Iterable[Obstacle], bounds_min, bounds_max, margin_m: float = 0.0):
        lo = _bounds_vector(bounds_min, "bounds_min")
        hi = _bounds_vector(bounds_max, "bounds_max")
        if len(lo) != len(hi):
            raise WorldError(f"bounds_max: has {len(hi)} values but bounds_min has {len(lo)}")
        if not all(a < b for a, b in zip(lo, hi)):
            raise WorldError(f"bounds_max: must exceed bounds_min on every axis (empty bounds {lo}..{hi})")
        try:
            margin = float(margin_m)
        except (TypeError, ValueError):
            raise WorldError(f"margin_m: expected a number, got {margin_m!r}") from None
        if not math.isfinite(margin) or margin < 0.0:
            raise WorldError(f"margin_m: must be a finite number >= 0, got {margin_m!r}")
        dim = len(lo)
        obs = tuple(obstacles)
        for i, ob in enumerate(obs):
            if not isinstance(ob, Obstacle):
                raise WorldError(f"obstacles[{i}]: expected an Obstacle, got {type(ob).__name__}")
            try:
                ob.check_dim(dim)
            except WorldError as exc:
                raise WorldError(f"obstacles[{i}]: {exc}") from None
        self._dim = dim
        self._lo = lo
        self._hi = hi
        self._margin = margin
        self._obstacles = obs
        self._build_index()
        self._memo: dict = {}  # memoised derived lookups (obstacles_acting_on_cell, KD-tree)
        self.point_free = self._point_free_2d if dim == 2 else self._point_free_3d
        self._frozen = True

    def __setattr__(self, name, value):
        if getattr(self, "_frozen", False):
            raise AttributeError("World is immutable; use with_threats() to add obstacles")
        object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ construction helpers
    @classmethod
    def from_spheres(cls, centers, radii, bounds_min, bounds_max, margin_m: float = 0.0) -> World:
        """World of discs (d = 2) or spheres (d = 3).

        Parameters
        ----------
        centers : (N, d) array_like
        radii : (N,) array_like, each > 0
        """
        c = np.asarray(centers, dtype=float)
        r = np.asarray(radii, dtype=float)
        d = len(_bounds_vector(bounds_min, "bounds_min"))
        if c.size == 0:
            c = c.reshape(0, d)
        if c.ndim != 2 or c.shape[1] != d:
            raise WorldError(f"centers: expected shape (N, {d}), got {c.shape}")
        if r.shape != (c.shape[0],):
            raise WorldError(f"radii: expected shape ({c.shape[0]},), got {r.shape}")
        shape = Disc if d == 2 else Sphere
        obs = []
        for i in range(c.shape[0]):
            try:
                obs.append(shape(c[i], r[i]))
            except WorldError as exc:
                raise WorldError(f"centers/radii[{i}]: {exc}") from None
        return cls(obs, bounds_min, bounds_max, margin_m)

    def with_threats(self, threats: Iterable[Obstacle]) -> World:
        """New world with the extra obstacles ``threats`` (this world is unchanged).

        A ``Sphere`` given to a 2D world becomes the ``Disc`` of its north-east footprint.
        """
        extra = []
        for ob in threats:
            if self._dim == 2 and isinstance(ob, Sphere):
                ob = Disc(ob.center_m[:2], ob.radius_m)
            extra.append(ob)
        return World(self._obstacles + tuple(extra), self._lo, self._hi, self._margin)

    def _build_index(self) -> None:
        m = self._margin
        dim = self._dim
        boxes = []
        sizes = []
        for ob in self._obstacles:
            blo, bhi = ob.aabb(dim)
            blo = tuple(x - m for x in blo)
            bhi = tuple(x + m for x in bhi)
            boxes.append((blo, bhi))
            finite = [h - l for l, h in zip(blo, bhi) if math.isfinite(h - l)]
            if finite:
                sizes.append(max(finite))
        extent = max(h - l for l, h in zip(self._lo, self._hi))
        max_cells = 64 if dim == 2 else 24
        cell = 0.5 * float(np.median(sizes)) if sizes else extent
        cell = min(max(cell, extent / max_cells), extent)
        grid = UniformGrid(self._lo, self._hi, cell, boxes)
        balls: list[tuple[float, ...]] = []  # centre, then r * r and r (r inflated by the margin)
        ball_ids = {}
        other_ids = {}
        for i, ob in enumerate(self._obstacles):
            if isinstance(ob, (Disc, Sphere)):
                r = ob.radius_m + m
                ball_ids[i] = len(balls)
                balls.append(tuple(ob.center_m) + (r * r, r))
            else:
                other_ids[i] = ob
        self._grid = grid
        self._balls = tuple(balls)
        self._other_ids = other_ids
        self._cell_balls = tuple(
            tuple(balls[ball_ids[i]] for i in cell_items if i in ball_ids) for cell_items in grid.cells
        )
        self._cell_others = tuple(
            tuple(other_ids[i] for i in cell_items if i in other_ids) for cell_items in grid.cells
        )

    # ------------------------------------------------------------------ properties
    @property
    def dim(self) -> int:
        """Dimension d (2 or 3)."""
        return self._dim

    @property
    def obstacles(self) -> tuple:
        """The obstacles (un-inflated), in the order given."""
        return self._obstacles

    @property
    def bounds_min(self) -> np.ndarray:
        """(d,) lower corner of the bounds (a copy)."""
        return np.array(self._lo)

    @property
    def bounds_max(self) -> np.ndarray:
        """(d,) upper corner of the bounds (a copy)."""
        return np.array(self._hi)

    @property
    def inflated_balls(self) -> tuple:
        """Discs/spheres as plain tuples ``(c_0, .., c_{d-1}, r_inflated^2, r_inflated)`` (m)."""
        return self._balls

    @property
    def non_ball_obstacles(self) -> tuple:
        """The obstacles that are neither Disc nor Sphere (Cylinder, Box, Prism)."""
        return tuple(self._other_ids.values())

    @property
    def margin_m(self) -> float:
        """Safety margin (m) by which every obstacle is inflated."""
        return self._margin

    def __repr__(self) -> str:
        return (
            f"World(dim={self._dim}, obstacles={len(self._obstacles)}, bounds_min={list(self._lo)}, "
            f"bounds_max={list(self._hi)}, margin_m={self._margin})"
        )

    # ------------------------------------------------------------------ fast scalar queries
    def in_bounds(self, p: Sequence[float]) -> bool:
        """True when point ``p`` (d floats) lies inside the bounds (inclusive; NaN -> False)."""
        for x, lo, hi in zip(p, self._lo, self._hi):
            if not lo <= x <= hi:
                return False
        return True

    def _point_free_2d(self, p: Sequence[float]) -> bool:
        x, y = p[0], p[1]
        lo, hi = self._lo, self._hi
        if not (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]):
            return False
        g = self._grid
        i = int((x - lo[0]) * g.inv_cell)
        j = int((y - lo[1]) * g.inv_cell)
        n0, n1 = g.shape
        flat = (i if i < n0 else n0 - 1) * n1 + (j if j < n1 else n1 - 1)
        for cx, cy, r2, _ in self._cell_balls[flat]:
            dx = x - cx
            dy = y - cy
            if dx * dx + dy * dy <= r2:
                return False
        m = self._margin
        for ob in self._cell_others[flat]:
            if ob.sdf(p) <= m:
                return False
        return True

    def _point_free_3d(self, p: Sequence[float]) -> bool:
        x, y, z = p[0], p[1], p[2]
        lo, hi = self._lo, self._hi
        if not (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1] and lo[2] <= z <= hi[2]):
            return False
        g = self._grid
        i = int((x - lo[0]) * g.inv_cell)
        j = int((y - lo[1]) * g.inv_cell)
        k = int((z - lo[2]) * g.inv_cell)
        n0, n1, n2 = g.shape
        flat = ((i if i < n0 else n0 - 1) * n1 + (j if j < n1 else n1 - 1)) * n2 + (k if k < n2 else n2 - 1)
        for cx, cy, cz, r2, _ in self._cell_balls[flat]:
            dx = x - cx
            dy = y - cy
            dz = z - cz
            if dx * dx + dy * dy + dz * dz <= r2:
                return False
        m = self._margin
        for ob in self._cell_others[flat]:
            if ob.sdf(p) <= m:
                return False
        return True

    def segment_free(self, a: Sequence[float], b: Sequence[float]) -> bool:
        """Exact test that segment ``ab`` stays inside the bounds and clear of every obstacle.

        Parameters
        ----------
        a, b : (d,) array_like or tuple of floats
            End points (m). NaN or out-of-bounds ends give ``False``.

        Returns
        -------
        bool
            ``True`` when the distance from the whole segment to every obstacle exceeds
            ``margin_m`` (computed in closed form, not by sampling).
        """
        if type(a) is not tuple:
            a = tuple(float(v) for v in a)
        if type(b) is not tuple:
            b = tuple(float(v) for v in b)
        if len(a) != self._dim or len(b) != self._dim:
            raise WorldError(f"segment_free: expected points of {self._dim} coordinates, got {len(a)} and {len(b)}")
        if not (self.in_bounds(a) and self.in_bounds(b)):
            return False
        g = self._grid
        cell_balls = self._cell_balls
        cell_others = self._cell_others
        others: set = set()
        if self._dim == 2:
            ax, ay = a
            bx, by = b
            dx, dy = bx - ax, by - ay
            l2 = dx * dx + dy * dy
            for flat in g.traverse(a, b):
                for cx, cy, r2, _ in cell_balls[flat]:
                    t = ((cx - ax) * dx + (cy - ay) * dy) / l2 if l2 > 0.0 else 0.0
                    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                    qx = ax + t * dx - cx
                    qy = ay + t * dy - cy
                    if qx * qx + qy * qy <= r2:
                        return False
                if cell_others[flat]:
                    others.update(cell_others[flat])
        else:
            ax, ay, az = a
            bx, by, bz = b
            dx, dy, dz = bx - ax, by - ay, bz - az
            l2 = dx * dx + dy * dy + dz * dz
            for flat in g.traverse(a, b):
                for cx, cy, cz, r2, _ in cell_balls[flat]:
                    t = ((cx - ax) * dx + (cy - ay) * dy + (cz - az) * dz) / l2 if l2 > 0.0 else 0.0
                    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                    qx = ax + t * dx - cx
                    qy = ay + t * dy - cy
                    qz = az + t * dz - cz
                    if qx * qx + qy * qy + qz * qz <= r2:
                        return False
                if cell_others[flat]:
                    others.update(cell_others[flat])
        m = self._margin
        for ob in others:
            if ob.segment_distance(a, b) <= m:
                return False
        return True

    def path_free(self, path) -> bool:
        """True when every segment of the polyline ``path`` (M, d) is free (exact)."""
        pts = [tuple(float(v) for v in row) for row in np.asarray(path, dtype=float)]
        if len(pts) == 1:
            return self.point_free(pts[0])
        return all(self.segment_free(p, q) for p, q in zip(pts[:-1], pts[1:]))

    def obstacles_near(self, p: Sequence[float], radius_m: float) -> list:
        """Obstacles whose inflated bounding box comes within ``radius_m`` of ``p`` (box test)."""
        lo = tuple(x - radius_m for x in p)
        hi = tuple(x + radius_m for x in p)
        ids = self._grid.items_in_box(lo, hi)
        return [self._obstacles[i] for i in sorted(ids)]

    def cell_of(self, p: Sequence[float]) -> int:
        """Flat index of the index-grid cell containing ``p`` (clamped to the bounds)."""
        return self._grid.cell_of(p)

    def obstacles_acting_on_cell(self, flat: int, reach_m: float) -> tuple:
        """Obstacles whose inflated surface may come within ``reach_m`` of grid cell ``flat``.

        A superset (bounding boxes, whole cells), memoised per cell and distance: the planner's
        guidance asks for the obstacles acting on a sample (``flat`` from :meth:`cell_of`).
        """
        key = (flat, reach_m)
        found = self._memo.get(key)
        if found is None:
            g = self._grid
            rings = int(math.ceil(reach_m * g.inv_cell))
            ranges = []
            for axis in range(self._dim):
                i = g._cell_lo_index(flat, axis)
                ranges.append(range(max(0, i - rings), min(g.shape[axis], i + rings + 1)))
            ids: set[int] = set()
            cells = g.cells
            if self._dim == 2:
                n1 = g.shape[1]
                for i in ranges[0]:
                    for j in ranges[1]:
                        ids.update(cells[i * n1 + j])
            else:
                n1, n2 = g.shape[1], g.shape[2]
                for i in ranges[0]:
                    for j in ranges[1]:
                        base = (i * n1 + j) * n2
                        for k in ranges[2]:
                            ids.update(cells[base + k])
            cell_lo = [g.lo[a] + g._cell_lo_index(flat, a) * g.cell_m for a in range(self._dim)]
            keep = []
            for i in sorted(ids):  # exact box-to-box gap against the cell
                blo, bhi = self._obstacles[i].aabb(self._dim)
                gap2 = 0.0
                for a in range(self._dim):
                    lo_a, hi_a = cell_lo[a], cell_lo[a] + g.cell_m
                    d = max(blo[a] - self._margin - hi_a, lo_a - bhi[a] - self._margin, 0.0)
                    gap2 += d * d
                if gap2 <= reach_m * reach_m:
                    keep.append(self._obstacles[i])
            found = tuple(keep)
            self._memo[key] = found
        return found

    def clearance_at(self, p: Sequence[float], max_range_m: float = math.inf) -> float:
        """Signed clearance (m) of point ``p`` from the nearest inflated obstacle surface.

        Only obstacles within ``max_range_m`` are examined, so the result is
        ``min(true clearance, max_range_m)``; ``inf`` with no obstacle at all. Bounds are not
        obstacles here.
        """
        if type(p) is not tuple:
            p = tuple(float(v) for v in p)
        m = self._margin
        obs: Sequence[Obstacle]
        if math.isinf(max_range_m):
            obs = self._obstacles
        else:
            obs = self.obstacles_near(p, max_range_m)
        best = max_range_m
        for ob in obs:
            c = ob.sdf(p) - m
            if c < best:
                best = c
        return best

    # ------------------------------------------------------------------ vectorised queries
    def _points(self, points, name: str = "points") -> np.ndarray:
        arr = np.asarray(points, dtype=float)
        if arr.ndim == 1 and arr.shape[0] == self._dim:
            arr = arr.reshape(1, self._dim)
        if arr.ndim != 2 or arr.shape[1] != self._dim:
            raise WorldError(f"{name}: expected shape (K, {self._dim}), got {arr.shape}")
        return arr

    def contains(self, points) -> np.ndarray:
        """Inside the bounds (inclusive): ``points`` (K, d) -> bool (K,)."""
        arr = self._points(points)
        return np.all((arr >= np.asarray(self._lo)) & (arr <= np.asarray(self._hi)), axis=1)

    def is_free(self, points) -> np.ndarray:
        """Free-space test: ``points`` (K, d) -> bool (K,); NaN or out of bounds -> False."""
        arr = self._points(points)
        free = self.point_free
        return np.fromiter((free(row) for row in arr.tolist()), dtype=bool, count=arr.shape[0])

    def clearance_m(self, points) -> np.ndarray:
        """Signed distance (m) to the nearest *inflated* obstacle surface: (K, d) -> (K,).

        Negative inside an inflated obstacle, ``inf`` when the world has no obstacle. A point
        inside the bounds is free exactly when its clearance is positive.
        """
        arr = self._points(points)
        out = np.full(arr.shape[0], np.inf)
        if not self._obstacles:
            return out
        balls = np.asarray(self._balls, dtype=float).reshape(-1, self._dim + 2)
        centers, radii = balls[:, : self._dim], balls[:, -1]
        others = list(self._other_ids.values())
        for start in range(0, arr.shape[0], _BATCH_ROWS):
            chunk = arr[start : start + _BATCH_ROWS]
            best = np.full(chunk.shape[0], np.inf)
            if len(radii) > _KDTREE_FROM:
                best = ball_clearance_kdtree(chunk, centers, radii, self._memo)
            elif len(radii):
                dist = np.linalg.norm(chunk[:, None, :] - centers[None, :, :], axis=2) - radii[None, :]
                best = np.minimum(best, dist.min(axis=1))
            for ob in others:
                best = np.minimum(best, ob.sdf_batch(chunk) - self._margin)
            out[start : start + _BATCH_ROWS] = best
        return out
