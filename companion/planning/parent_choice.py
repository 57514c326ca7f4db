"""GART step 4, ``choose_parent``, compiled (numba) for the length and climb cost among balls,
cylinders and prisms.

With cost = energy weight x (length + climb penalty), choosing a parent is: order the neighbours
by cost through them (then by id), and take the first whose corner respects the heading limit
(with K_max: leaves room for a G2 corner), whose edge is free and (with K_max) whose corner is
clear. :class:`ParentArrays` mirrors the
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

from companion.planning.corner_kernel import corner_clear, corner_fits, edge_cost
from companion.planning.node_arrays import within_kernel
from companion.world import obstacle_kernels as okern

__all__ = ["ParentArrays", "first_valid_parent", "rewire_candidates", "extend"]

_FIRST_CAPACITY = 1024


class ParentArrays:
    """Cost-to-come (n,), incoming unit direction (n, d), whether it exists (n,) and incoming
    edge length (n,), per node.

    Parameters
    ----------
    dim : int
    """

    def __init__(self, dim: int):
        self.dim = dim
        self.cost = np.empty(_FIRST_CAPACITY)
        self.u = np.zeros((_FIRST_CAPACITY, dim))
        self.has_u = np.zeros(_FIRST_CAPACITY, dtype=np.bool_)
        self.length = np.zeros(_FIRST_CAPACITY)

    def set(self, node: int, cost: float, u: tuple | None, length_m: float = 0.0) -> None:
        """Write ``node``'s cost, incoming direction (None at the root) and edge length, growing the arrays."""
        cap = self.cost.shape[0]
        if node >= cap:
            extra = max(node + 1, 2 * cap) - cap
            self.cost = np.concatenate([self.cost, np.empty(extra)])
            self.u = np.concatenate([self.u, np.zeros((extra, self.dim))])
            self.has_u = np.concatenate([self.has_u, np.zeros(extra, dtype=np.bool_)])
            self.length = np.concatenate([self.length, np.zeros(extra)])
        self.cost[node] = cost
        self.length[node] = length_m
        if u is not None:
            self.u[node] = u
        self.has_u[node] = u is not None


@njit(cache=True)
def first_valid_parent(
    ids: np.ndarray,
    dists: np.ndarray,
    cost: np.ndarray,
    u_in: np.ndarray,
    has_u: np.ndarray,
    len_in: np.ndarray,
    coords: np.ndarray,
    x_new,
    energy: float,
    climb_penalty: float,
    rule,
    space,
) -> int:
    """Position in ``ids`` of the chosen parent of ``x_new``, or -1.

    Parameters
    ----------
    ids, dists : (m,) int64, (m,) float
        Neighbours and their distances (m).
    cost, u_in, has_u, len_in : (n,), (n, d), (n,), (n,)
        Tree arrays: cost-to-come, incoming unit direction (and whether it exists), incoming
        edge length (read with K_max only).
    coords : (n, d)
        Node positions.
    x_new : (d,) array
    energy, climb_penalty : float
        Length weight and climb penalty (0: none) of the edge cost.
    rule, space : tuples
        The corner rule (:func:`~companion.planning.corner_kernel.rule_of`) and the world's
        obstacles (:func:`~companion.world.obstacle_kernels.space_of`).
    """
    m = ids.shape[0]
    d = coords.shape[1]
    order = np.empty(m, dtype=np.int64)
    cs = np.empty(m)
    k = 0
    for a in range(m):
        if dists[a] >= 1e-9:
            c = cost[ids[a]] + edge_cost(coords[ids[a]], x_new, dists[a], energy, climb_penalty)
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
    with_corner = rule[1] > 0.0
    for s in range(k):
        a = order[s]
        i = ids[a]
        dist = dists[a]
        for j in range(d):
            u[j] = (x_new[j] - coords[i, j]) / dist
        if has_u[i] and not corner_fits(u_in[i], len_in[i], u, dist, rule):
            continue
        if not okern.segment_clear(coords[i], x_new, space):
            continue
        if has_u[i] and with_corner and not corner_clear(u_in[i], len_in[i], u, dist, coords[i], rule, space):
            continue
        return a
    return -1


@njit(cache=True)
def rewire_candidates(
    ids: np.ndarray, dists: np.ndarray, cost: np.ndarray, c_new: float, energy: float, skip: int
) -> np.ndarray:
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
def extend(
    x_new,
    near: int,
    near_dist: float,
    radius_m: float,
    coords: np.ndarray,
    keys: np.ndarray,
    active: np.ndarray,
    n: int,
    cost: np.ndarray,
    u_in: np.ndarray,
    has_u: np.ndarray,
    len_in: np.ndarray,
    energy: float,
    climb_penalty: float,
    rule,
    space,
):
    """Point test, neighbours and parent of the steered point ``x_new`` in one call.

    Returns ``(free, pos, ids, dists)``: whether ``x_new`` is free, the position in ``ids`` of
    its parent (-1: none), and the neighbours within ``radius_m`` (m) by bucket then id, the
    nearest node ``near`` (at ``near_dist``) appended when the radius leaves it out. The other
    arguments are :func:`first_valid_parent`'s.
    """
    if not okern.point_clear(x_new, space):
        return False, -1, np.empty(0, dtype=np.int64), np.empty(0)
    rr = radius_m * radius_m
    ids, dists = within_kernel(coords, keys, active, n, x_new, rr)
    dx = coords[near, 0] - x_new[0]
    d2 = dx * dx
    for k in range(1, coords.shape[1]):
        dk = coords[near, k] - x_new[k]
        d2 += dk * dk
    if not d2 <= rr:  # listed_within(pts[near], x_new, radius_m)
        ids = np.append(ids, near)
        dists = np.append(dists, near_dist)
    pos = first_valid_parent(ids, dists, cost, u_in, has_u, len_in, coords, x_new, energy, climb_penalty, rule, space)
    return True, pos, ids, dists
