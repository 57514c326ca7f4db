"""GART step 4, ``choose_parent``, compiled (numba) for the plain length cost in a world of balls.

With cost = energy weight x length, no K_max corner clearance and only discs/spheres, choosing
a parent is: order the neighbours by cost through them (then by id), and take the first whose
corner respects the heading limit and whose edge is free. :class:`ParentArrays` mirrors the
tree's cost-to-come and incoming unit directions as arrays (written wherever the planner
writes its lists), and :func:`first_valid_parent` runs that loop in one call, with the
arithmetic of :meth:`~companion.planning.search.GartSearch.choose_parent`,
:meth:`~companion.planning.simplify.CornerRule.ok` and the exact segment test, in the same
order, so it picks the same parent. :func:`rewire_candidates` applies step 5's first test (can
the new node shorten a neighbour at all?) to every neighbour at once; :func:`extend` runs the
point test, the radius query and step 4 for a steered point in one call. (numba's cache notices
edits of a kernel's own file only: after editing a kernel it calls, clear ``__pycache__``.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from companion.planning.node_arrays import within_kernel
from companion.world.segments import segment_clear_of_balls

__all__ = ["ParentArrays", "first_valid_parent", "rewire_candidates", "extend"]

_FIRST_CAPACITY = 1024


class ParentArrays:
    """Cost-to-come (n,), incoming unit direction (n, d) and whether it exists (n,), per node.

    Parameters
    ----------
    dim : int
    """

    def __init__(self, dim: int):
        self.dim = dim
        self.cost = np.empty(_FIRST_CAPACITY)
        self.u = np.zeros((_FIRST_CAPACITY, dim))
        self.has_u = np.zeros(_FIRST_CAPACITY, dtype=np.bool_)

    def set(self, node: int, cost: float, u: tuple | None) -> None:
        """Write ``node``'s cost and incoming direction (None at the root), growing the arrays."""
        cap = self.cost.shape[0]
        if node >= cap:
            extra = max(node + 1, 2 * cap) - cap
            self.cost = np.concatenate([self.cost, np.empty(extra)])
            self.u = np.concatenate([self.u, np.zeros((extra, self.dim))])
            self.has_u = np.concatenate([self.has_u, np.zeros(extra, dtype=np.bool_)])
        self.cost[node] = cost
        if u is not None:
            self.u[node] = u
        self.has_u[node] = u is not None


@njit(cache=True)
def first_valid_parent(ids: np.ndarray, dists: np.ndarray, cost: np.ndarray, u_in: np.ndarray,
                       has_u: np.ndarray, coords: np.ndarray, x_new, energy: float, cos_max: float,
                       lo, hi, centres: np.ndarray, r2: np.ndarray) -> int:
    """Position in ``ids`` of the chosen parent of ``x_new``, or -1.

    Parameters
    ----------
    ids, dists : (m,) int64, (m,) float
        Neighbours and their distances (m).
    cost, u_in, has_u : (n,), (n, d), (n,)
        Tree arrays (:class:`ParentArrays`).
    coords : (n, d)
        Node positions.
    x_new : d floats
    energy, cos_max : float
        Length weight; cosine of the largest heading change.
    lo, hi, centres, r2
        Bounds and inflated balls, as :func:`~companion.world.segments.segment_clear_of_balls`.
    """
    m = ids.shape[0]
    d = coords.shape[1]
    order = np.empty(m, dtype=np.int64)
    cs = np.empty(m)
    k = 0
    for a in range(m):
        if dists[a] >= 1e-9:
            c = cost[ids[a]] + energy * dists[a]
            # insertion by (cost, id): the order of sorting the tuples (cost, id, dist)
            b = k - 1
            while b >= 0 and (cs[b] > c or (cs[b] == c and ids[order[b]] > ids[a])):
                order[b + 1] = order[b]
                cs[b + 1] = cs[b]
                b -= 1
            order[b + 1] = a
            cs[b + 1] = c
            k += 1
    u = np.empty(d)
    for s in range(k):
        a = order[s]
        i = ids[a]
        dist = dists[a]
        for j in range(d):
            u[j] = (x_new[j] - coords[i, j]) / dist
        if has_u[i]:
            dot = 0.0
            for j in range(d):
                dot += u_in[i, j] * u[j]
            if dot < cos_max:
                continue
        if segment_clear_of_balls(coords[i], x_new, lo, hi, centres, r2):
            return a
    return -1


@njit(cache=True)
def rewire_candidates(ids: np.ndarray, dists: np.ndarray, cost: np.ndarray, c_new: float, energy: float,
                      skip: int) -> np.ndarray:
    """Positions in ``ids`` of the neighbours that the new node (cost ``c_new``) may shorten.

    Those with ``c_new + dist * energy < cost`` that are neither the root, nor ``skip`` (the new
    node's parent), nor at ``dist < 1e-9``, in the order given. Rewiring only lowers costs, so
    a neighbour left out here stays out while the others are rewired.
    """
    out = np.empty(ids.shape[0], dtype=np.int64)
    m = 0
    for a in range(ids.shape[0]):
        i = ids[a]
        if c_new + dists[a] * energy >= cost[i] or i == 0 or i == skip or dists[a] < 1e-9:
            continue
        out[m] = a
        m += 1
    return out[:m]


@njit(cache=True)
def point_clear_of_balls(x, lo, hi, centres: np.ndarray, r2: np.ndarray) -> bool:
    """``World.point_free`` for a world of balls: inside the bounds and outside every ball."""
    d = centres.shape[1]
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
    return True


@njit(cache=True)
def extend(x_new, near: int, near_dist: float, radius_m: float, coords: np.ndarray, keys: np.ndarray,
           active: np.ndarray, n: int, cost: np.ndarray, u_in: np.ndarray, has_u: np.ndarray, energy: float,
           cos_max: float, lo, hi, centres: np.ndarray, r2: np.ndarray):
    """Point test, neighbours and parent of the steered point ``x_new`` in one call.

    Returns ``(free, pos, ids, dists)``: whether ``x_new`` is free, the position in ``ids`` of
    its parent (-1: none), and the neighbours within ``radius_m`` (m) by bucket then id, the
    nearest node ``near`` (at ``near_dist``) appended when the radius leaves it out.
    """
    if not point_clear_of_balls(x_new, lo, hi, centres, r2):
        return False, -1, np.empty(0, dtype=np.int64), np.empty(0)
    rr = radius_m * radius_m
    ids, dists = within_kernel(coords, keys, active, n, x_new, rr)
    dx = coords[near, 0] - x_new[0]
    d2 = dx * dx
    for k in range(1, coords.shape[1]):
        dk = coords[near, k] - x_new[k]
        d2 += dk * dk
    if not d2 <= rr:   # listed_within(pts[near], x_new, radius_m)
        ids = np.append(ids, near)
        dists = np.append(dists, near_dist)
    pos = first_valid_parent(ids, dists, cost, u_in, has_u, coords, x_new, energy, cos_max, lo, hi, centres, r2)
    return True, pos, ids, dists
