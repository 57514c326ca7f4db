"""M-GART's goal portals: the final approach of each path found, open to the later branches.

A goal in a pocket (3d_dense seed 8: two spheres below the goal leave a quarter of its 20 m
ball in view) is reached only by a branch that enters the pocket, and the tree's only way to
the goal is a straight edge of at most ``goal_radius_m`` from a new node. Forbidding a branch
removes the nodes that had entered, so before this each further path waited for a new entry by
chance (one new node within 20 m of the goal every 300 to 600 iterations on that seed, while
the growing tree made each iteration slower).

Portals keep the approach: the waypoints of every path kept that lie within ``zone_m`` of the
goal (not the goal itself). A new node within ``goal_radius_m`` of a portal that joins it by a
free straight edge, with both corners allowed by the heading rule, forms a path: the node's
branch, the edge, then the kept path from the portal to the goal. Distinctness is still tested
on the whole path, so a joined path counts only if its branch differs.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["GoalPortals"]


class GoalPortals:
    """Portals towards the goal of ``search`` (a :class:`~companion.planning.search.GartSearch`).

    Parameters
    ----------
    search : GartSearch
    zone_m : float
        Waypoints of kept paths within this distance of the goal become portals.
    """

    def __init__(self, search, zone_m: float):
        self.search = search
        self.zone = zone_m
        # (point, tail (m, d) from the point to the goal, direction and length of its first
        # edge, length of the tail)
        self.items: list[tuple[tuple, np.ndarray, tuple, float, float]] = []

    def add_path(self, path: np.ndarray) -> None:
        """Open portals at the interior waypoints of ``path`` (M, d) near the goal."""
        goal = self.search.goal
        for k in range(1, path.shape[0] - 1):
            p = tuple(path[k].tolist())
            if math.dist(p, goal) > self.zone:
                continue
            nxt = tuple(path[k + 1].tolist())
            length = math.dist(p, nxt)
            if length < 1e-9:
                continue
            u = tuple((b - a) / length for a, b in zip(p, nxt))
            tail = path[k:]
            self.items.append((p, tail, u, length, float(np.linalg.norm(np.diff(tail, axis=0), axis=1).sum())))

    def join(self, node: int) -> np.ndarray | None:
        """Path (M, d) root -> ``node`` -> cheapest reachable portal -> goal, or None."""
        if not self.items:
            return None
        s = self.search
        x = s.pts[node]
        reach = s.goal_radius
        cands = []
        for k, (p, _, _, _, tail_m) in enumerate(self.items):
            dist = math.dist(x, p)
            if 1e-9 < dist <= reach:
                cands.append((dist + tail_m, k, dist))
        cands.sort()
        ok = s.rule.ok
        for _, k, dist in cands:
            p, tail, u_next, len_next, _ = self.items[k]
            u = tuple((b - a) / dist for a, b in zip(x, p))
            if not (ok(s.u_in[node], s.len_in[node], u, dist) and ok(u, dist, u_next, len_next)):
                continue
            if not s.world.segment_free(x, p):
                continue
            if not (ok(s.u_in[node], s.len_in[node], u, dist, x) and ok(u, dist, u_next, len_next, p)):
                continue
            head = np.array([s.pts[i] for i in s.branch(node)], dtype=float)
            return np.vstack([head, tail])
        return None
