"""Planner results: a status value, never an exception, for expected outcomes (DESIGN section 4).

OMPL's convention: ``solve`` returns a status (exact solution, timeout, invalid start or goal)
and the path is read from the problem; here both live in one immutable :class:`PlanResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

__all__ = ["PlanResult", "Tree", "Status"]

Status = Literal["exact", "timeout", "invalid_start", "invalid_goal"]


@dataclass(frozen=True)
class Tree:
    """The search tree, for plotting and statistics.

    Attributes
    ----------
    nodes : (N, d) float64
        Node positions (m); node 0 is the start.
    parents : (N,) int64
        Parent index of each node, -1 for the root.
    forbidden : (N,) bool
        Nodes excluded from extension by M-GART (all False for GART).
    """

    nodes: np.ndarray
    parents: np.ndarray
    forbidden: np.ndarray

    @property
    def size(self) -> int:
        """Number of nodes N."""
        return int(self.nodes.shape[0])

    def edges(self) -> np.ndarray:
        """(E, 2, d) segments from each non-root node to its parent."""
        child = np.nonzero(self.parents >= 0)[0]
        return np.stack([self.nodes[child], self.nodes[self.parents[child]]], axis=1)


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one plan.

    Attributes
    ----------
    status : {'exact', 'timeout', 'invalid_start', 'invalid_goal'}
        ``exact``: ``path`` reaches the goal. ``timeout``: budget spent without a path.
    path : (M, d) float64 or None
        Waypoints from start to goal (m), collision-free (exact check).
    cost : float
        Cost of ``path`` (paper eq. 3, see :mod:`companion.planning.cost`); inf without path.
    length_m : float
        Length of ``path`` (m); inf without path.
    iterations : int
        Sampling iterations run.
    elapsed_s : float
        Wall-clock time of the whole call (s).
    time_to_first_s : float or None
        Time (s) at which the first path was found, None if none.
    tree : Tree or None
        The search tree (None for invalid start or goal).
    cost_history : tuple of (t_s, cost)
        Best cost whenever it improved (before final shortcutting).
    """

    status: Status
    path: np.ndarray | None
    cost: float
    length_m: float
    iterations: int
    elapsed_s: float
    time_to_first_s: float | None
    tree: Tree | None
    cost_history: tuple = field(default=())

    @property
    def solved(self) -> bool:
        """True when ``status == 'exact'``."""
        return self.status == "exact"

    def summary(self) -> dict:
        """JSON-serialisable summary (path as a list of lists)."""
        return {
            "status": self.status,
            "cost": None if not np.isfinite(self.cost) else float(self.cost),
            "length_m": None if not np.isfinite(self.length_m) else float(self.length_m),
            "iterations": self.iterations,
            "elapsed_s": self.elapsed_s,
            "time_to_first_s": self.time_to_first_s,
            "tree_nodes": 0 if self.tree is None else self.tree.size,
            "path": None if self.path is None else self.path.tolist(),
        }
