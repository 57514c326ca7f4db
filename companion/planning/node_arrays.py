"""Nearest and radius queries over the planner tree, compiled with numba (node arrays + kernels).

The bucket grid of :mod:`companion.planning.nearest` has cells as wide as the largest RRT*
radius, so that its answers come in a fixed order (bucket, then node id). A Python walk over
those buckets costs tens of microseconds per query; one compiled pass over every node's
coordinates costs about a microsecond at first-path sizes and stays cheaper than the buckets up
to thousands of nodes. The arrays are written as nodes are added (one row per node). The kernels
compute squared distances with the same floating-point operations as the scalar code
(``dx*dx + dy*dy (+ dz*dz)``, node minus query, no fused multiply-add), return the nearest node
of least id among equals and the neighbours in the grid's order (bucket key, then id), so the
planner takes the same decisions with either path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["NodeArrays"]

_FIRST_CAPACITY = 1024


@njit(cache=True)
def _dist2(coords: np.ndarray, i: int, p) -> float:
    """Squared distance of node ``i`` (row of ``coords`` (cap, d)) to ``p`` (d floats)."""
    dx = coords[i, 0] - p[0]
    d2 = dx * dx
    for k in range(1, coords.shape[1]):
        dk = coords[i, k] - p[k]
        d2 += dk * dk
    return d2


@njit(cache=True)
def nearest_kernel(coords: np.ndarray, active: np.ndarray, n: int, p) -> int:
    """Least id of the active node nearest to ``p`` among the first ``n`` rows (-1 when none)."""
    best = -1
    best_d2 = np.inf
    for i in range(n):
        if active[i]:
            d2 = _dist2(coords, i, p)
            if d2 < best_d2:
                best = i
                best_d2 = d2
    return best


@njit(cache=True)
def within_kernel(coords: np.ndarray, keys: np.ndarray, active: np.ndarray, n: int, p, r2: float):
    """``(ids (m,), distances (m,))`` of the active nodes with squared distance <= ``r2``.

    Ordered by bucket key, then id (a stable insertion sort of the ids found in id order).
    """
    ids = np.empty(n, dtype=np.int64)
    d2s = np.empty(n)
    m = 0
    for i in range(n):
        if active[i]:
            d2 = _dist2(coords, i, p)
            if d2 <= r2:
                ids[m] = i
                d2s[m] = d2
                m += 1
    for a in range(1, m):
        node = ids[a]
        d2 = d2s[a]
        key = keys[node]
        b = a - 1
        while b >= 0 and keys[ids[b]] > key:
            ids[b + 1] = ids[b]
            d2s[b + 1] = d2s[b]
            b -= 1
        ids[b + 1] = node
        d2s[b + 1] = d2
    return ids[:m], np.sqrt(d2s[:m])


@njit(cache=True)
def append_kernel(
    coords: np.ndarray, keys: np.ndarray, active: np.ndarray, node: int, p, lo, inv_cell: float, shape
) -> int:
    """Write row ``node`` (position ``p``), mark it active; returns its bucket key.

    The key is that of :class:`~companion.planning.nearest.NodeGrid`: per axis the truncation
    of ``(x - lo) / cell`` clamped to the grid, flattened row-major.
    """
    key = 0
    for k in range(coords.shape[1]):
        coords[node, k] = p[k]
        i = int((p[k] - lo[k]) * inv_cell)
        i = 0 if i < 0 else (shape[k] - 1 if i >= shape[k] else i)
        key = key * shape[k] + i
    keys[node] = key
    active[node] = True
    return key


class NodeArrays:
    """Coordinates, bucket keys and active flags of the nodes, as numpy arrays.

    Parameters
    ----------
    lo : tuple of d floats
        Lower corner of the bucket grid.
    inv_cell : float
        1 / bucket edge (1/m).
    shape : tuple of d ints
        Buckets per axis.
    """

    def __init__(self, lo: tuple, inv_cell: float, shape: tuple):
        self.dim = dim = len(lo)
        self.lo = lo
        self.inv_cell = inv_cell
        self.shape = shape
        self.count = 0
        self.coords = np.empty((_FIRST_CAPACITY, dim))
        self.keys = np.empty(_FIRST_CAPACITY, dtype=np.int64)
        self.active = np.zeros(_FIRST_CAPACITY, dtype=np.bool_)

    # ------------------------------------------------------------------ updates
    def append(self, node: int, p: tuple) -> int:
        """Write node ``node`` (position ``p``) and mark it active; returns its bucket key."""
        cap = self.keys.shape[0]
        if node >= cap:
            cap = max(node + 1, 2 * cap)
            self.coords = np.concatenate([self.coords, np.empty((cap - self.coords.shape[0], self.dim))])
            self.keys = np.concatenate([self.keys, np.empty(cap - self.keys.shape[0], dtype=np.int64)])
            self.active = np.concatenate([self.active, np.zeros(cap - self.active.shape[0], dtype=np.bool_)])
        if node >= self.count:
            self.count = node + 1
        return append_kernel(self.coords, self.keys, self.active, node, p, self.lo, self.inv_cell, self.shape)

    def set_active(self, node: int, value: bool) -> None:
        """Mark ``node`` as in (True) or out of (False) the structure."""
        if node < self.count:
            self.active[node] = value

    def sync(self, members=None) -> int:
        """The number of rows to search (rows are written by :meth:`append`; kept for callers)."""
        return self.count

    # ------------------------------------------------------------------ queries
    def nearest(self, p: tuple, n: int) -> int:
        """Id of the active node nearest to ``p`` (-1 when none); ``n`` from :meth:`sync`."""
        return nearest_kernel(self.coords, self.active, n, p)

    def within_arrays(self, p: tuple, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`within` as arrays: ids (m,) int64 and distances (m,) in the same order."""
        return within_kernel(self.coords, self.keys, self.active, self.count, p, radius_m * radius_m)

    def within(self, p: tuple, radius_m: float, n: int) -> list[tuple[int, float]]:
        """``(id, distance)`` of the active nodes within ``radius_m`` of ``p``, by bucket then id."""
        ids, dist = within_kernel(self.coords, self.keys, self.active, n, p, radius_m * radius_m)
        return list(zip(ids.tolist(), dist.tolist()))
