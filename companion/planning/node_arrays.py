"""Vectorised nearest and radius queries over a large planner tree (numpy mirror of the nodes).

The bucket grid of :mod:`companion.planning.nearest` has cells as wide as the largest RRT*
radius, so that its answers come in a fixed order (bucket, then node id). With the neighbour
radius a quarter of the world's width, a query on a tree of thousands of nodes touches most
buckets and costs milliseconds of Python. Above a few hundred nodes one numpy pass over all
coordinates is cheaper. This mirror is synchronised lazily (the nodes appended since the last
query are copied in one batch), computes squared distances with the same floating-point
operations as the scalar code (``dx*dx + dy*dy (+ dz*dz)``, node minus query), and returns the
neighbours in the grid's order, so the planner takes the same decisions with either path.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["NodeArrays"]

_FIRST_CAPACITY = 1024


class NodeArrays:
    """Coordinates, bucket keys and active flags of the nodes, as numpy arrays.

    Parameters
    ----------
    points : list of tuple
        The planner's node positions, indexed by node id (appended to by the planner).
    lo : tuple of d floats
        Lower corner of the bucket grid.
    inv_cell : float
        1 / bucket edge (1/m).
    shape : tuple of d ints
        Buckets per axis.
    """

    def __init__(self, points: list, lo: tuple, inv_cell: float, shape: tuple):
        self.points = points
        self.dim = len(lo)
        self.lo = np.asarray(lo, dtype=float)
        self.inv_cell = inv_cell
        self.shape = np.asarray(shape, dtype=np.int64)
        self.synced = 0
        self.coords = np.empty((self.dim, _FIRST_CAPACITY))
        self.keys = np.empty(_FIRST_CAPACITY, dtype=np.int64)
        self.active = np.zeros(_FIRST_CAPACITY, dtype=bool)

    # ------------------------------------------------------------------ updates
    def set_active(self, node: int, value: bool) -> None:
        """Mark ``node`` as in (True) or out of (False) the structure."""
        if node < self.synced:
            self.active[node] = value

    def sync(self, members) -> int:
        """Copy the nodes appended since the last call; returns the node count.

        ``members`` (a container of ids) tells which of the new nodes are in the structure.
        """
        n = len(self.points)
        if n == self.synced:
            return n
        if n > self.keys.shape[0]:
            cap = max(n, 2 * self.keys.shape[0])
            coords = np.empty((self.dim, cap))
            coords[:, :self.synced] = self.coords[:, :self.synced]
            keys = np.empty(cap, dtype=np.int64)
            keys[:self.synced] = self.keys[:self.synced]
            active = np.zeros(cap, dtype=bool)
            active[:self.synced] = self.active[:self.synced]
            self.coords, self.keys, self.active = coords, keys, active
        new = np.asarray(self.points[self.synced:n], dtype=float).reshape(-1, self.dim)
        self.coords[:, self.synced:n] = new.T
        # bucket index as NodeGrid._index: truncation of (x - lo) / cell, clamped to the grid
        idx = np.floor((new - self.lo) * self.inv_cell).astype(np.int64)
        idx = np.minimum(np.maximum(idx, 0), self.shape - 1)
        key = idx[:, 0] * self.shape[1] + idx[:, 1]
        if self.dim == 3:
            key = key * self.shape[2] + idx[:, 2]
        self.keys[self.synced:n] = key
        self.active[self.synced:n] = [i in members for i in range(self.synced, n)]
        self.synced = n
        return n

    # ------------------------------------------------------------------ queries
    def _dist2(self, p: tuple, n: int) -> np.ndarray:
        c = self.coords
        dx = c[0, :n] - p[0]
        d2 = dx * dx
        for k in range(1, self.dim):
            dk = c[k, :n] - p[k]
            d2 += dk * dk
        return d2

    def nearest(self, p: tuple, n: int) -> int:
        """Id of the active node nearest to ``p`` (-1 when none); ``n`` from :meth:`sync`."""
        d2 = self._dist2(p, n)
        d2[~self.active[:n]] = math.inf
        i = int(np.argmin(d2))
        return i if d2[i] < math.inf else -1

    def within(self, p: tuple, radius_m: float, n: int) -> list[tuple[int, float]]:
        """``(id, distance)`` of the active nodes within ``radius_m`` of ``p``, by bucket then id."""
        d2 = self._dist2(p, n)
        ids = np.flatnonzero((d2 <= radius_m * radius_m) & self.active[:n])
        ids = ids[np.argsort(self.keys[ids], kind="stable")]
        return list(zip(ids.tolist(), np.sqrt(d2[ids]).tolist()))
