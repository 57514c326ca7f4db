"""Path cost of the paper (section 3.1, eq. 3): energy + threat + tracking.

``J = w_e * sum_edges (L + c_climb * max(0, -delta_down))            energy: length, climb penalty
    + w_t * sum_edges integral_0^L (1 - c(s)/R)_+^2 ds                 threat: proximity via clearance
    + w_k * sum_corners |heading change|                               tracking: turning``

The threat integral is evaluated with Simpson's rule on each edge (ends and midpoint), the same
rule in the planner and in :func:`path_cost`, so a reported cost equals the cost the planner
minimised. The paper's figures are not lengths in metres, so benchmarks compare costs as a
percentage above the best known; ``CostWeights.length_only()`` makes the cost the length.
"""

from __future__ import annotations

import math

import numpy as np

from companion.planning.settings import CostWeights
from companion.world import World

__all__ = ["EdgeCost", "path_cost", "path_length_m", "heading_change_rad"]


def heading_change_rad(u_in: tuple, u_out: tuple) -> float:
    """Angle (rad) between unit direction vectors ``u_in`` and ``u_out``."""
    c = sum(a * b for a, b in zip(u_in, u_out))
    return math.acos(1.0 if c > 1.0 else (-1.0 if c < -1.0 else c))


class EdgeCost:
    """Scalar cost terms for the planner's inner loop (plain floats).

    Parameters
    ----------
    world : World
        Supplies the clearance for the threat term.
    weights : CostWeights
    """

    def __init__(self, world: World, weights: CostWeights):
        self.world = world
        self.w = weights
        self.dim = world.dim
        self.uses_threat = weights.threat > 0.0
        self.uses_climb = weights.climb_penalty > 0.0 and world.dim == 3
        self.uses_tracking = weights.tracking_m_per_rad > 0.0

    def threat_density(self, p: tuple) -> float:
        """``(1 - c / R)_+^2`` at point ``p`` for clearance ``c`` and range ``R``."""
        r = self.w.threat_range_m
        c = self.world.clearance_at(p, r)
        if c >= r:
            return 0.0
        x = 1.0 - c / r if c > 0.0 else 1.0
        return x * x

    def edge(self, a: tuple, b: tuple, length_m: float, dens_a: float = -1.0, dens_b: float = -1.0) -> float:
        """Energy plus threat cost of edge ``ab`` of length ``length_m`` (no corner term).

        ``dens_a``/``dens_b`` are cached threat densities of the ends (negative: compute).
        """
        w = self.w
        cost = length_m
        if self.uses_climb:
            climb = a[2] - b[2]
            if climb > 0.0:
                cost += w.climb_penalty * climb
        cost *= w.energy
        if self.uses_threat:
            if dens_a < 0.0:
                dens_a = self.threat_density(a)
            if dens_b < 0.0:
                dens_b = self.threat_density(b)
            mid = tuple(0.5 * (x + y) for x, y in zip(a, b))
            cost += w.threat * length_m * (dens_a + 4.0 * self.threat_density(mid) + dens_b) / 6.0
        return cost

    def corner(self, u_in: tuple | None, u_out: tuple) -> float:
        """Tracking cost of the heading change between unit directions (0 without ``u_in``)."""
        if u_in is None or not self.uses_tracking:
            return 0.0
        return self.w.tracking_m_per_rad * heading_change_rad(u_in, u_out)


def path_length_m(path) -> float:
    """Length (m) of the polyline ``path`` (M, d)."""
    p = np.asarray(path, dtype=float)
    if p.shape[0] < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def path_cost(world: World, path, weights: CostWeights | None = None) -> float:
    """Cost (paper eq. 3) of the polyline ``path`` (M, d) with ``weights`` (default weights)."""
    ec = EdgeCost(world, weights or CostWeights())
    pts = [tuple(float(v) for v in row) for row in np.asarray(path, dtype=float)]
    total = 0.0
    u_prev = None
    for a, b in zip(pts[:-1], pts[1:]):
        length = math.dist(a, b)
        if length <= 0.0:
            continue
        u = tuple((y - x) / length for x, y in zip(a, b))
        total += ec.edge(a, b, length) + ec.corner(u_prev, u)
        u_prev = u
    return total
