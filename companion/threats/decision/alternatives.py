"""Alternatives: pre-planned M-GART paths to switch to (paper section 3.3, Fig. 5 and 7).

``plan_alternatives`` runs the trajectory pipeline's M-GART planner (*Extending Forbidden*:
paths on different sides of the obstacles and of the threats known when it runs) from a point just ahead of the vehicle to the
leg's goal, in the leg's airspace widened to include the start's altitude (a leg that climbs
has alternatives too), and adds the cheapest path shifted up and down by ``vertical_offsets_m``
where the airspace allows (alternatives above and below). ``switch_candidates`` lists the entry
nodes within the switching range, cheapest first and diverse. A switch to an alternative is a
join (``join.join_trajectory``): smoothed, timed and checked by the same pipeline.

Pure: no I/O; randomness from ``rng``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.errors import CompanionError
from companion.flight.pipeline import PlanBudget, PlanningProblem, TrajectoryPipeline
from companion.world import World

__all__ = ["Alternative", "AlternativeError", "plan_alternatives", "switch_candidates", "airspace_for"]


class AlternativeError(CompanionError, ValueError):
    """A malformed alternative path (naming it)."""

    limit_m: float


@dataclass(frozen=True)
class Alternative:
    """One pre-planned M-GART path to the goal, a switching target.

    Any point of the path is a possible entry node: the path is sampled every ``spacing_m``
    (the *entries*); a switch flies to an entry, then on along the path's own nodes.

    Attributes
    ----------
    path_id : str
    path_ned_m : ndarray, shape (M, d)
        The path's nodes (as planned: its corners fit the G2 smoothing).
    entry_pos_ned_m : ndarray, shape (E, d)
        Entry points along the path.
    entry_next : ndarray of int, shape (E,)
        Index of the path node that follows each entry.
    entry_remaining_m : ndarray, shape (E,)
        Length of the path from each entry to its end (the entry's remaining cost).
    """

    path_id: str
    path_ned_m: np.ndarray
    entry_pos_ned_m: np.ndarray
    entry_next: np.ndarray
    entry_remaining_m: np.ndarray

    @classmethod
    def from_path(cls, path_id: str, path_ned_m, spacing_m: float = 2.0) -> Alternative:
        """Build from a polyline (M, d), M >= 2, with entries at most ``spacing_m`` apart."""
        path = np.asarray(path_ned_m, dtype=float)
        if path.ndim != 2 or path.shape[0] < 2 or path.shape[1] not in (2, 3) or not np.all(np.isfinite(path)):
            raise AlternativeError(
                f"alternative {path_id!r}: path_ned_m must be a finite (M, 2|3) "
                f"array with M >= 2, got shape {path.shape}"
            )
        if not (math.isfinite(spacing_m) and spacing_m > 0):
            raise AlternativeError(f"spacing_m: must be a finite number > 0, got {spacing_m!r}")
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        tail = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])  # from node i to the end
        pos, nxt, rem = [], [], []
        for i, (a, b) in enumerate(zip(path[:-1], path[1:])):
            n = max(1, int(math.ceil(seg[i] / spacing_m)))
            f = np.arange(0, n)[:, None] / n
            pos.append(a[None, :] + f * (b - a)[None, :])
            nxt.append(np.full(n, i + 1))
            rem.append(tail[i + 1] + (1.0 - f[:, 0]) * seg[i])
        return cls(str(path_id), path, np.vstack(pos), np.concatenate(nxt), np.concatenate(rem))

    def nodes_from(self, entry: int) -> np.ndarray:
        """The polyline (K, d) flown after switching at ``entry``: the entries from it on, the last
        node (collinear points are dropped before smoothing, so the corners keep their room)."""
        return np.vstack([self.entry_pos_ned_m[entry:], self.path_ned_m[-1:]])


def airspace_for(world: World, points, room_m: float = 0.0, floor_down_m: float | None = None) -> World:
    """``world`` with its down bounds widened to contain every point (a climb's start), plus
    ``room_m`` above and below, never lower than ``floor_down_m`` (3D worlds; 2D unchanged)."""
    if world.dim != 3:
        return world
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    lo, hi = world.bounds_min, world.bounds_max
    new_lo = min(lo[2], float(pts[:, 2].min()) - 0.5) - room_m
    new_hi = max(hi[2], float(pts[:, 2].max()) + 0.5) + room_m
    if floor_down_m is not None:
        new_hi = max(min(new_hi, floor_down_m), hi[2])
    if new_lo == lo[2] and new_hi == hi[2]:
        return world
    lo[2], hi[2] = new_lo, new_hi
    return World(world.obstacles, lo, hi, world.margin_m)


def vertical_variants(path: np.ndarray, world: World, offsets_m) -> list[np.ndarray]:
    """``path`` shifted up and down by each offset (m) where it stays free (3D worlds only)."""
    if world.dim != 3:
        return []
    out = []
    for dz in offsets_m:
        for sign in (-1.0, 1.0):
            shifted = path.copy()
            shifted[1:-1, 2] += sign * dz  # the ends stay: start and goal are fixed
            mid = np.vstack(
                [
                    path[:1],
                    path[:1] + [0.0, 0.0, sign * dz],
                    shifted[1:-1],
                    path[-1:] + [0.0, 0.0, sign * dz],
                    path[-1:],
                ]
            )
            if world.path_free(mid):
                out.append(mid)
    return out


def plan_alternatives(
    world: World,
    start,
    goal,
    k: int,
    *,
    pipeline: TrajectoryPipeline,
    rng: np.random.Generator,
    max_time_s: float,
    spacing_m: float,
    vertical_offsets_m=(),
    airspace=None,
    tag: str = "",
) -> list:
    """M-GART alternatives from ``start`` to ``goal`` (cheapest first) plus vertical variants.

    Parameters
    ----------
    world : World
        The airspace with the threats to keep away from as obstacles.
    start, goal : array_like, shape (d,)
    k : int
        Paths asked of M-GART.
    pipeline : TrajectoryPipeline
        Its ``alternatives_planner`` (M-GART) plans them.
    vertical_offsets_m : sequence of float
        Offsets of the cheapest path's above/below variants (3D only).
    airspace : World, optional
        Where the vertical variants must stay free (default ``world``): the leg's slab is
        thin, the airspace around it is not.

    Returns
    -------
    list of Alternative
        Ids ``alt<i><tag>``; empty when M-GART finds nothing.
    """
    start = np.asarray(start, dtype=float)
    world = airspace_for(world, [start])
    results = pipeline.alternatives(PlanningProblem(world, start, goal), PlanBudget(max_time_s), k, rng=rng)
    paths = [r.path for r in results if r.status == "exact" and r.path is not None]
    if paths:
        paths += vertical_variants(paths[0], airspace_for(airspace or world, [start]), vertical_offsets_m)
    return [Alternative.from_path(f"alt{i}{tag}", p, spacing_m) for i, p in enumerate(paths)]


def switch_candidates(alternatives, pos_ned_m, switch_range_m: float, spacing_m: float) -> list:
    """Entry nodes within the switching range, cheapest remaining cost first, diverse.

    Entries of one alternative closer than 2.5 entry spacings to a cheaper one are left out
    (they would give nearly the same trajectory); the order is round robin over the
    alternatives (the cheapest entry of each, cheapest first, then the second ...): a threat
    that blocks one alternative usually blocks all its entries, so diversity comes first.

    Returns
    -------
    list of (cost_m, Alternative, entry index)
        cost = distance to the entry + the alternative's length from it to the goal.
    """
    pos = np.asarray(pos_ned_m, dtype=float)
    out = []
    for alt in alternatives:
        dist = np.linalg.norm(alt.entry_pos_ned_m - pos[None, :], axis=1)
        for e in np.flatnonzero(dist <= switch_range_m):
            out.append((float(dist[e] + alt.entry_remaining_m[e]), alt, int(e)))
    out.sort(key=lambda c: (c[0], -c[2]))
    per_alt: dict[str, list] = {}
    for cand in out:
        mine = per_alt.setdefault(cand[1].path_id, [])
        p = cand[1].entry_pos_ned_m[cand[2]]
        if all(np.linalg.norm(q[1].entry_pos_ned_m[q[2]] - p) >= 2.5 * spacing_m for q in mine):
            mine.append(cand)
    rounds = max((len(v) for v in per_alt.values()), default=0)
    picked = []
    for r in range(rounds):
        picked += sorted((v[r] for v in per_alt.values() if len(v) > r), key=lambda c: c[0])
    return picked
