"""M-GART on the compiled iteration: the arrays of :class:`CompiledGart` behind GartSearch's interface.

:func:`~companion.planning.mgart.mgart` forbids branches, opens goal portals and removes goal
links between iterations; :class:`CompiledMgartSearch` gives it the attributes it reads on a
:class:`~companion.planning.search.GartSearch` (``pts``, ``u_in``, ``len_in``, ``nn``,
``forbidden``, ``goal_links``, ``rule``, ``branch`` ...) as views of the arrays, and an
:meth:`~CompiledMgartSearch.iterate` that runs compiled iterations until the next node M-GART
must look at: one that got a goal link, or, once portals exist, any new node. M-GART never
updates a best cost, so the kernel runs in its M-GART modes (no best cost, sampling uniform),
and the tree, the paths and the generator's state are those of the Python iteration.
"""

from __future__ import annotations

import math
import time

import numpy as np

from companion.planning import iteration_kernel as kernel
from companion.planning.compiled_search import CompiledGart
from companion.planning.node_arrays import within_kernel
from companion.planning.result import Tree
from companion.planning.simplify import CornerRule

__all__ = ["CompiledMgartSearch"]

_FIRST_BATCH = 32
_MAX_BATCH = 4096
_SLICE_S = 1e-3


class _View:
    """A view of the search's arrays under one of GartSearch's attribute names."""

    def __init__(self, search: CompiledGart):
        self.s = search


class _Points(_View):
    """``search.pts[i]``: node i's position as a tuple of d floats."""

    def __getitem__(self, i: int) -> tuple:
        return tuple(self.s.coords[i].tolist())


class _Directions(_View):
    """``search.u_in[i]``: node i's incoming unit direction (None at the root)."""

    def __getitem__(self, i: int) -> tuple | None:
        return tuple(self.s.u[i].tolist()) if self.s.has_u[i] else None


class _Lengths(_View):
    """``search.len_in[i]``: node i's incoming edge length (m)."""

    def __getitem__(self, i: int) -> float:
        return float(self.s.length[i])


class _Forbidden(_View):
    """``search.forbidden[i]``: whether node i is forbidden (readable and writable)."""

    def __init__(self, search: CompiledGart):
        super().__init__(search)
        self.ids: set[int] = set()

    def __getitem__(self, i: int) -> bool:
        return i in self.ids

    def __setitem__(self, i: int, value: bool) -> None:
        (self.ids.add if value else self.ids.discard)(i)


class _Nodes(_Points):
    """``search.nn``: radius queries over the active nodes and removal (NodeGrid's interface)."""

    def within(self, p: tuple, radius_m: float) -> list[tuple[int, float]]:
        s = self.s
        ids, dist = within_kernel(s.coords, s.keys, s.active, s.n_nodes, np.array(p, dtype=float), radius_m * radius_m)
        return list(zip(ids.tolist(), dist.tolist()))

    def remove(self, node: int) -> None:
        self.s.active[node] = False


class _GoalLinks(_Points):
    """``search.goal_links``: membership and removal of a node's goal link (order kept)."""

    def __contains__(self, node: int) -> bool:
        return node < self.s.n_nodes and self.s.link_of[node] >= 0

    def pop(self, node: int, default=None):
        if node not in self:
            return default
        s = self.s
        link_of, gl_node, gl_e, gl_u, gl_len = s.links
        k, m = int(link_of[node]), int(s.counters[kernel.N_LINKS])
        for a in (gl_node, gl_e, gl_u, gl_len):
            a[k : m - 1] = a[k + 1 : m]
        link_of[gl_node[k : m - 1]] -= 1
        link_of[node] = -1
        s.counters[kernel.N_LINKS] = m - 1
        return None


class CompiledMgartSearch(CompiledGart):
    """:class:`CompiledGart` with the interface M-GART uses (see the module docstring)."""

    def __init__(self, world, start: tuple, goal: tuple, settings, rng: np.random.Generator):
        super().__init__(world, start, goal, settings, rng)
        self.pts, self.u_in, self.len_in = _Points(self), _Directions(self), _Lengths(self)
        self.nn, self.goal_links, self.forbidden = _Nodes(self), _GoalLinks(self), _Forbidden(self)
        self.rule = CornerRule(settings, world)
        self.goal_radius = self.params[2]
        self.batch = _FIRST_BATCH

    def iterate(self, every_node: bool = False, max_iterations: float = math.inf) -> int:
        """Compiled iterations up to the next node M-GART must see (-1: a time slice ended first).

        That node got a goal link, or, with ``every_node`` (portals are open), it is any new node.
        At most ``max_iterations`` (an iteration budget is met exactly, whatever the slices).
        """
        t_call = time.perf_counter()
        size = self.batch if max_iterations >= self.batch else max(1, int(max_iterations))
        status = self.run(size, kernel.MGART_NODES if every_node else kernel.MGART_LINKS)
        if status == kernel.NEW_NODE:
            return self.n_nodes - 1
        took = time.perf_counter() - t_call
        if took < 0.5 * _SLICE_S:
            self.batch = min(2 * self.batch, _MAX_BATCH)
        elif took > 2.0 * _SLICE_S and self.batch > 1:
            self.batch //= 2
        return -1

    def tree(self) -> Tree:
        """Snapshot of the tree as arrays, forbidden nodes marked."""
        snapshot = self.tree_snapshot()
        snapshot.forbidden[sorted(self.forbidden.ids)] = True
        return snapshot
