"""Incremental nearest-neighbour structure for the planner tree: a bucket grid.

RRT* asks for the nearest node and for the nodes within a radius on every iteration while the
tree grows by one node; rebuilding a KD-tree each time costs more than the whole iteration
(``ANCHORS.md``: cKDTree build 88 us for 1k nodes, query 10-15 us). Buckets of node ids keyed
by flat integer cell indices are updated in O(1) and searched ring by ring (Chebyshev rings of
cells around the query); a small tree is scanned linearly. From ``_VECTOR_FROM`` nodes (by
default always) one compiled pass over all nodes
(:class:`~companion.planning.node_arrays.NodeArrays`, numba) answers the same queries in the same
order; the bucket walk stays as the reference the tests compare it with.
"""

from __future__ import annotations

import math

from companion.planning.node_arrays import NodeArrays

__all__ = ["NodeGrid", "listed_within", "grid_shape", "bucket_key"]

_LINEAR_SCAN_BELOW = 40
_VECTOR_FROM = 0  # compiled queries from this many nodes (the bucket walk is the reference)


def grid_shape(lo: tuple, hi: tuple, inv_cell: float) -> tuple:
    """Buckets per axis over ``[lo, hi]`` for buckets of edge ``1 / inv_cell``."""
    return tuple(max(1, int(math.ceil((h - l) * inv_cell))) for l, h in zip(lo, hi))


def bucket_key(p: tuple, lo: tuple, inv_cell: float, shape: tuple) -> int:
    """Flat bucket key of point ``p`` (:meth:`NodeGrid._flat` of :meth:`NodeGrid._index`)."""
    key = 0
    for x, l, n in zip(p, lo, shape):
        i = int((x - l) * inv_cell)
        key = key * n + (0 if i < 0 else (n - 1 if i >= n else i))
    return key


class NodeGrid:
    """Points in buckets of edge ``cell_m`` over the box ``[lo, hi]`` (2D or 3D).

    Parameters
    ----------
    lo, hi : tuple of d floats
        Region of the points (positions outside are clamped into the border buckets).
    cell_m : float
        Bucket edge (m); about the neighbour radius works best.
    points : list of tuple
        Shared list of node positions, indexed by node id (the planner appends to it).
    """

    def __init__(self, lo: tuple, hi: tuple, cell_m: float, points: list):
        self.dim = len(lo)
        self.lo = tuple(lo)
        self.cell_m = cell_m
        self.inv = 1.0 / cell_m
        self.shape = grid_shape(lo, hi, self.inv)
        self.points = points
        self.buckets: dict[int, list[int]] = {}
        self.active: list[int] = []  # ids in the structure, for linear scans
        self.where: dict[int, int] = {}  # id -> position in active
        self._rings: list[list[tuple]] = [[(0,) * self.dim]]
        self.arrays = NodeArrays(self.lo, self.inv, self.shape)

    # ------------------------------------------------------------------ cells
    def _index(self, p: tuple) -> tuple:
        out = []
        for x, l, n in zip(p, self.lo, self.shape):
            i = int((x - l) * self.inv)
            out.append(0 if i < 0 else (n - 1 if i >= n else i))
        return tuple(out)

    def _flat(self, idx: tuple) -> int:
        if self.dim == 2:
            return idx[0] * self.shape[1] + idx[1]
        return (idx[0] * self.shape[1] + idx[1]) * self.shape[2] + idx[2]

    def _ring_offsets(self, ring: int) -> list[tuple]:
        while len(self._rings) <= ring:
            k = len(self._rings)
            rng = range(-k, k + 1)
            offs: list[tuple]
            if self.dim == 2:
                offs = [(a, b) for a in rng for b in rng if max(abs(a), abs(b)) == k]
            else:
                offs = [(a, b, c) for a in rng for b in rng for c in rng if max(abs(a), abs(b), abs(c)) == k]
            self._rings.append(offs)
        return self._rings[ring]

    def __len__(self) -> int:
        return len(self.active)

    # ------------------------------------------------------------------ updates
    def add(self, node: int) -> None:
        """Insert node ``node`` (its position is ``points[node]``)."""
        key = self.arrays.append(node, self.points[node])  # = self._flat(self._index(p))
        bucket = self.buckets.get(key)
        if bucket is None:
            self.buckets[key] = [node]
        else:
            bucket.append(node)
        self.where[node] = len(self.active)
        self.active.append(node)

    def remove(self, node: int) -> None:
        """Remove ``node`` (no-op when absent)."""
        pos = self.where.pop(node, None)
        if pos is None:
            return
        last = self.active.pop()
        if last != node:
            self.active[pos] = last
            self.where[last] = pos
        self.buckets[self._flat(self._index(self.points[node]))].remove(node)
        self.arrays.set_active(node, False)

    # ------------------------------------------------------------------ queries
    def _scan(self, p: tuple, ids) -> tuple[int, float]:
        pts = self.points
        best, best_d2 = -1, math.inf
        if self.dim == 2:
            x, y = p
            for i in ids:
                q = pts[i]
                dx = q[0] - x
                dy = q[1] - y
                d2 = dx * dx + dy * dy
                if d2 < best_d2:
                    best, best_d2 = i, d2
        else:
            x, y, z = p
            for i in ids:
                q = pts[i]
                dx = q[0] - x
                dy = q[1] - y
                dz = q[2] - z
                d2 = dx * dx + dy * dy + dz * dz
                if d2 < best_d2:
                    best, best_d2 = i, d2
        return best, best_d2

    def nearest(self, p: tuple) -> int:
        """Id of the point nearest to ``p`` (-1 when empty)."""
        if len(self.active) >= _VECTOR_FROM:
            return self.arrays.nearest(p, self.arrays.sync(self.where))
        if len(self.active) < _LINEAR_SCAN_BELOW:
            return self._scan(p, self.active)[0]
        idx = self._index(p)
        shape = self.shape
        buckets = self.buckets
        best, best_d2 = -1, math.inf
        n_buckets = len(buckets)
        for ring in range(max(shape) + 1):
            offsets = self._ring_offsets(ring)
            if best < 0 and len(offsets) > 2 * n_buckets:
                # far from every node: cheaper to scan all occupied buckets
                return self._scan(p, self.active)[0]
            for off in offsets:
                if self.dim == 2:
                    i, j = idx[0] + off[0], idx[1] + off[1]
                    if i < 0 or j < 0 or i >= shape[0] or j >= shape[1]:
                        continue
                    ids = buckets.get(i * shape[1] + j)
                else:
                    i, j, k = idx[0] + off[0], idx[1] + off[1], idx[2] + off[2]
                    if i < 0 or j < 0 or k < 0 or i >= shape[0] or j >= shape[1] or k >= shape[2]:
                        continue
                    ids = buckets.get((i * shape[1] + j) * shape[2] + k)
                if ids:
                    b, d2 = self._scan(p, ids)
                    if d2 < best_d2:
                        best, best_d2 = b, d2
            reach = ring * self.cell_m
            if best >= 0 and best_d2 <= reach * reach:
                return best
        return best

    def within(self, p: tuple, radius_m: float) -> list[tuple[int, float]]:
        """``(id, distance)`` of every point within ``radius_m`` of ``p``."""
        if len(self.active) >= _VECTOR_FROM:
            return self.arrays.within(p, radius_m, self.arrays.sync(self.where))
        r2 = radius_m * radius_m
        pts = self.points
        out = []
        lo_idx = self._index(tuple(x - radius_m for x in p))
        hi_idx = self._index(tuple(x + radius_m for x in p))
        buckets = self.buckets
        shape = self.shape
        sqrt = math.sqrt
        if self.dim == 2:
            x, y = p
            for i in range(lo_idx[0], hi_idx[0] + 1):
                base = i * shape[1]
                for j in range(lo_idx[1], hi_idx[1] + 1):
                    ids = buckets.get(base + j)
                    if not ids:
                        continue
                    for n in ids:
                        q = pts[n]
                        dx = q[0] - x
                        dy = q[1] - y
                        d2 = dx * dx + dy * dy
                        if d2 <= r2:
                            out.append((n, sqrt(d2)))
            return out
        x, y, z = p
        for i in range(lo_idx[0], hi_idx[0] + 1):
            for j in range(lo_idx[1], hi_idx[1] + 1):
                base = (i * shape[1] + j) * shape[2]
                for k in range(lo_idx[2], hi_idx[2] + 1):
                    ids = buckets.get(base + k)
                    if not ids:
                        continue
                    for n in ids:
                        q = pts[n]
                        dx = q[0] - x
                        dy = q[1] - y
                        dz = q[2] - z
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 <= r2:
                            out.append((n, sqrt(d2)))
        return out


def listed_within(q: tuple, p: tuple, radius_m: float) -> bool:
    """True when the nearest-neighbour query ``within(p, radius_m)`` lists the node at ``q``.

    The same arithmetic as :meth:`NodeGrid.within` (node minus query), without a query.
    """
    d2 = 0.0
    for a, b in zip(q, p):
        d = a - b
        d2 += d * d
    return d2 <= radius_m * radius_m
