"""Uniform grid (spatial hash) over the world bounds, for point, segment and range queries.

Each cell lists the items (obstacles) whose inflated bounding box overlaps it, so a query only
looks at the few obstacles near it: with 1000 obstacles a point query touches about as many as
with 30. Lookups use plain integers and tuples (no numpy) because the planner calls them in its
inner loop (``ANCHORS.md``: point vs 30 discs with a 5 m grid costs 0.2-0.3 us in plain Python).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["UniformGrid"]


class UniformGrid:
    """Axis-aligned uniform grid over ``[lo, hi]`` holding item ids per cell.

    Parameters
    ----------
    lo, hi : tuple of d floats
        Grid extent (the world bounds). Queries outside are clamped to the border cells.
    cell_m : float
        Cell edge length (m), > 0.
    boxes : sequence of (lo, hi) tuples
        Bounding box of each item; item ``i`` is listed in every cell its box overlaps.
    """

    def __init__(self, lo: tuple, hi: tuple, cell_m: float, boxes) -> None:
        self.dim = len(lo)
        self.lo = tuple(float(x) for x in lo)
        self.cell_m = float(cell_m)
        self.inv_cell = 1.0 / self.cell_m
        self.shape = tuple(max(1, int(math.ceil((h - l) * self.inv_cell))) for l, h in zip(lo, hi))
        self.strides: tuple[int, ...]  # row-major: 2 in 2-D, 3 in 3-D
        if self.dim == 2:
            self.strides = (self.shape[1], 1)
        else:
            self.strides = (self.shape[1] * self.shape[2], self.shape[2], 1)
        n_cells = 1
        for s in self.shape:
            n_cells *= s
        cells: list[list[int]] = [[] for _ in range(n_cells)]
        pad = 1e-9 * max(1.0, max(abs(x) for x in self.lo + tuple(hi)))
        for item, (blo, bhi) in enumerate(boxes):
            # a hair of padding makes the lists closed: a box touching a cell face is listed
            # in both cells, so a segment traversal that visits either cell finds it
            blo = tuple(x - pad for x in blo)
            bhi = tuple(x + pad for x in bhi)
            if any(bh < l or bl > l + s * self.cell_m for bl, bh, l, s in zip(blo, bhi, self.lo, self.shape)):
                continue  # entirely outside the grid
            for flat in self.cells_overlapping(blo, bhi):
                cells[flat].append(item)
        self.cells: tuple[tuple[int, ...], ...] = tuple(tuple(c) for c in cells)

    def axis_index(self, axis: int, x: float) -> int:
        """Clamped cell index of coordinate ``x`` along ``axis``."""
        i = int((x - self.lo[axis]) * self.inv_cell) if math.isfinite(x) else (0 if x < 0 else self.shape[axis] - 1)
        n = self.shape[axis]
        return 0 if i < 0 else (n - 1 if i >= n else i)

    def cell_of(self, p: Sequence[float]) -> int:
        """Flat index of the cell containing point ``p`` (clamped to the grid)."""
        flat = 0
        for axis in range(self.dim):
            flat += self.axis_index(axis, p[axis]) * self.strides[axis]
        return flat

    def _cell_lo_index(self, flat: int, axis: int) -> int:
        """Index along ``axis`` of the cell with flat index ``flat``."""
        return (flat // self.strides[axis]) % self.shape[axis]

    def cells_overlapping(self, lo: tuple, hi: tuple) -> list[int]:
        """Flat indices of every cell that overlaps the box ``[lo, hi]`` (clamped)."""
        ranges = [range(self.axis_index(a, lo[a]), self.axis_index(a, hi[a]) + 1) for a in range(self.dim)]
        if self.dim == 2:
            s0 = self.strides[0]
            return [i * s0 + j for i in ranges[0] for j in ranges[1]]
        s0, s1 = self.strides[0], self.strides[1]
        return [i * s0 + j * s1 + k for i in ranges[0] for j in ranges[1] for k in ranges[2]]

    def traverse(self, a: tuple, b: tuple) -> list[int]:
        """Flat indices of the cells crossed by segment ``ab`` (3D-DDA, Amanatides and Woo).

        Both ends must be inside the grid. Together with closed cell lists this finds every
        item whose box the segment meets.
        """
        if self.dim == 2:
            return self._traverse_2d(a, b)
        return self._traverse_3d(a, b)

    def _axis_setup(self, k: int, ak: float, bk: float) -> tuple:
        """(start index, end index, step, t_max, t_delta) of the DDA along axis ``k``."""
        lo, n = self.lo[k], self.shape[k]
        i = int((ak - lo) * self.inv_cell)
        i = 0 if i < 0 else (n - 1 if i >= n else i)
        j = int((bk - lo) * self.inv_cell)
        j = 0 if j < 0 else (n - 1 if j >= n else j)
        if i == j:
            return i, j, 0, math.inf, math.inf
        d = bk - ak
        if d > 0.0:
            return i, j, 1, (lo + (i + 1) * self.cell_m - ak) / d, self.cell_m / d
        return i, j, -1, (lo + i * self.cell_m - ak) / d, -self.cell_m / d

    def _traverse_2d(self, a: tuple, b: tuple) -> list[int]:
        i, ei, si, ti, di = self._axis_setup(0, a[0], b[0])
        j, ej, sj, tj, dj = self._axis_setup(1, a[1], b[1])
        s0 = self.strides[0]
        out = [i * s0 + j]
        if si == 0 and sj == 0:
            return out
        n0, n1 = self.shape
        while i != ei or j != ej:
            if ti <= tj:
                i += si
                if not 0 <= i < n0 or ti > 1.0 + 1e-12:
                    break
                ti += di
            else:
                j += sj
                if not 0 <= j < n1 or tj > 1.0 + 1e-12:
                    break
                tj += dj
            out.append(i * s0 + j)
        end_flat = ei * s0 + ej
        if out[-1] != end_flat:  # rounding at the very end: the last cell is always crossed
            out.append(end_flat)
        return out

    def _traverse_3d(self, a: tuple, b: tuple) -> list[int]:
        i, ei, si, ti, di = self._axis_setup(0, a[0], b[0])
        j, ej, sj, tj, dj = self._axis_setup(1, a[1], b[1])
        k, ek, sk, tk, dk = self._axis_setup(2, a[2], b[2])
        s0, s1, _ = self.strides
        out = [i * s0 + j * s1 + k]
        if si == 0 and sj == 0 and sk == 0:
            return out
        n0, n1, n2 = self.shape
        while i != ei or j != ej or k != ek:
            if ti <= tj and ti <= tk:
                i += si
                if not 0 <= i < n0 or ti > 1.0 + 1e-12:
                    break
                ti += di
            elif tj <= tk:
                j += sj
                if not 0 <= j < n1 or tj > 1.0 + 1e-12:
                    break
                tj += dj
            else:
                k += sk
                if not 0 <= k < n2 or tk > 1.0 + 1e-12:
                    break
                tk += dk
            out.append(i * s0 + j * s1 + k)
        end_flat = ei * s0 + ej * s1 + ek
        if out[-1] != end_flat:  # rounding at the very end: the last cell is always crossed
            out.append(end_flat)
        return out

    def items_in_box(self, lo: tuple, hi: tuple) -> set[int]:
        """Ids of items listed in any cell overlapping ``[lo, hi]``."""
        out: set[int] = set()
        cells = self.cells
        for flat in self.cells_overlapping(lo, hi):
            out.update(cells[flat])
        return out
