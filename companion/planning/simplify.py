"""Path shortcutting, kept apart from the planner (as OMPL's ``PathSimplifier``).

Greedy shortcutting: from each waypoint, join the farthest later waypoint that can be reached by
a free straight edge when that lowers the cost (paper eq. 3) and keeps every corner within the
heading limit of :class:`~companion.planning.settings.GartSettings` (so the G2 smoother can still
honour K_max). Exact collision checks; no random choices.
"""

from __future__ import annotations

import math

import numpy as np

from companion.planning.cost import EdgeCost
from companion.planning.settings import G2_CORNER_COEFF, GartSettings
from companion.world import World
from companion.world.segments import segment_test, segments_free_from

__all__ = ["CornerRule", "shortcut_path"]


class CornerRule:
    """The heading-change limit at a corner between two edges (see ``GartSettings``).

    With ``kappa_max_1_m`` set and a ``world`` given, the G2 corner must also be clear: its two
    spirals lie inside the triangle of the tangent points ``W - d u_in``, ``W + d u_out`` and the
    corner ``W`` (convex hull of their control points), so the chord between the tangent points
    and the segment from ``W`` to the chord's midpoint must be free (the two legs are parts of
    the path's own, already free, edges).
    """

    def __init__(self, settings: GartSettings, world: World | None = None):
        self.cos_max = math.cos(settings.max_heading_change_rad)
        self.kappa = settings.kappa_max_1_m
        self.fraction = settings.corner_fraction
        self.world = world if settings.kappa_max_1_m is not None else None
        self.segment_free = segment_test(world) if self.world is not None else None

    def ok(self, u_in: tuple | None, len_in: float, u_out: tuple, len_out: float, corner: tuple | None = None) -> bool:
        """True when the corner from unit direction ``u_in`` to ``u_out`` (at ``corner``) is allowed."""
        if u_in is None:
            return True
        c = 0.0
        for a, b in zip(u_in, u_out):
            c += a * b
        if c < self.cos_max:
            return False
        if self.kappa is None or c >= 1.0 - 1e-12:
            return True
        sin_beta = math.sqrt(0.5 * (1.0 - c))
        cos2_beta = 0.5 * (1.0 + c)
        need = G2_CORNER_COEFF * sin_beta / (self.kappa * cos2_beta)
        if need > self.fraction * (len_in if len_in < len_out else len_out):
            return False
        free = self.segment_free  # None exactly when self.world is None
        if corner is None or free is None:
            return True
        b0 = tuple(w - need * u for w, u in zip(corner, u_in))
        e0 = tuple(w + need * u for w, u in zip(corner, u_out))
        mid = tuple(0.5 * (x + y) for x, y in zip(b0, e0))
        return free(b0, e0) and free(corner, mid)


def _edge(a: tuple, b: tuple) -> tuple[tuple, float]:
    length = math.dist(a, b)
    return tuple((y - x) / length for x, y in zip(a, b)), length


def _section_cost(points: list, ec: EdgeCost, u_before: tuple | None) -> float:
    """Cost of the polyline ``points`` including corners, the first against ``u_before``."""
    total = 0.0
    u_prev = u_before
    for a, b in zip(points[:-1], points[1:]):
        u, length = _edge(a, b)
        total += ec.edge(a, b, length) + ec.corner(u_prev, u)
        u_prev = u
    return total


class _Edges:
    """Directions, lengths and cost terms of the edges of ``pts`` (recomputed after a change).

    ``terms[k]`` is edge k's cost plus the corner at its start (0 at the first waypoint), so
    the cost of the section from waypoint ``i`` to ``j`` is ``sum(terms[i:j])``, accumulated in
    the order :func:`_section_cost` uses.
    """

    def __init__(self, pts: list, ec: EdgeCost):
        self.u, self.length, self.terms = [], [], []
        u_prev = None
        for a, b in zip(pts[:-1], pts[1:]):
            u, length = _edge(a, b)
            self.u.append(u)
            self.length.append(length)
            self.terms.append(ec.edge(a, b, length) + ec.corner(u_prev, u))
            u_prev = u

    def section_cost(self, i: int, j: int) -> float:
        """Cost of waypoints ``i .. j`` (edges i to j-1), the first corner included."""
        total = 0.0
        for term in self.terms[i:j]:
            total += term
        return total


def shortcut_path(world: World, path, settings: GartSettings | None = None) -> np.ndarray:
    """Shortcut ``path`` (M, d) in ``world``; returns a new (M', d) path, M' <= M.

    The result is collision-free when the input is, never costs more, and keeps the first
    and last waypoints. From each waypoint the later waypoints are tried farthest first; their
    straight edges are tested together (:func:`~companion.world.segments.segments_free_from`).
    """
    settings = settings or GartSettings()
    rule = CornerRule(settings, world)
    ec = EdgeCost(world, settings.cost)
    pts = [tuple(float(v) for v in row) for row in np.asarray(path, dtype=float)]
    pts = [p for k, p in enumerate(pts) if k == 0 or math.dist(p, pts[k - 1]) > 1e-9]
    for _ in range(settings.simplify.max_rounds):
        changed = False
        i = 0
        edges = _Edges(pts, ec)
        while i < len(pts) - 2:
            j = _farthest_shortcut(world, rule, ec, pts, edges, i)
            if j > 0:
                pts = pts[: i + 1] + pts[j:]
                edges = _Edges(pts, ec)
                changed = True
            i += 1
        if not changed:
            break
    return np.array(pts, dtype=float)


def _farthest_shortcut(world: World, rule: CornerRule, ec: EdgeCost, pts: list, edges: _Edges, i: int) -> int:
    """The farthest waypoint ``j > i + 1`` that a free, cheaper, corner-respecting edge joins, or -1."""
    u_before, len_before = (None, 0.0) if i == 0 else (edges.u[i - 1], edges.length[i - 1])
    last = len(pts) - 1
    free = None
    for j in range(last, i + 1, -1):
        u_new, len_new = _edge(pts[i], pts[j])
        if not rule.ok(u_before, len_before, u_new, len_new, pts[i]):
            continue
        new = ec.edge(pts[i], pts[j], len_new) + ec.corner(u_before, u_new)
        if j < last:
            u_after, len_after = edges.u[j], edges.length[j]
            if not rule.ok(u_new, len_new, u_after, len_after, pts[j]):
                continue
            old = edges.section_cost(i, j + 1)
            new += ec.edge(pts[j], pts[j + 1], len_after) + ec.corner(u_new, u_after)
        else:
            old = edges.section_cost(i, j)
        if not new < old - 1e-9:
            continue
        if free is None:  # the edges from i to every later waypoint, tested at once
            free = segments_free_from(world, pts[i], pts[i + 2 : j + 1])
        if free[j - i - 2]:
            return j
    return -1
