"""GART's tree and one iteration of Algorithm 1 (paper section 3.1), steps 3 to 6.

Steps 1 and 2 (``sample``, ``attract``) live in :mod:`~companion.planning.sampling` and
:mod:`~companion.planning.guidance`; this module grows the tree:

3. ``steer``: from the nearest tree node, at most ``step_m`` along the combined direction
   towards the guided sample;
4. ``choose_parent``: among the nodes within the shrinking RRT* radius
   ``min(gamma* (log n / n)^(1/d), r_max)`` (``r_max`` default ``2 * step_m``) the parent of
   least cost-to-come whose edge is free and whose corner respects the heading limit and, with
   K_max, leaves room for a collision-free G2 corner (:class:`~companion.planning.simplify.CornerRule`);
5. ``rewire``: neighbours that become cheaper through the new node change parent, provided every
   corner touched (at the new node, at the neighbour towards each of its children) stays within
   the heading limit; costs are propagated to the descendants;
6. ``connect_goal``: a node within ``goal_radius_m`` tries a straight edge to the goal.

Cost-to-come includes the corner (tracking) term at the parent, so it depends on the tree path;
rewiring compares the neighbour's own cost (the standard RRT* rule), which with a tracking weight
may leave descendants' corner costs slightly suboptimal. The tree is kept in plain lists of
floats and tuples: at the sizes of a first path (tens to hundreds of nodes) Python's scalar
operations cost less than numpy's per-call overhead. The loops over all nodes or all obstacles
(nearest and radius queries, exact segment tests, guidance) are compiled with numba. For the
common case (length and climb cost, a world of balls, cylinders and prisms) GART and M-GART run
the whole iteration compiled instead (:mod:`~companion.planning.compiled_search`), with the same result;
this class is the reference and serves every other case.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np

from companion.planning.corner_kernel import rule_of
from companion.planning.cost import EdgeCost
from companion.planning.guidance import Guidance
from companion.planning.nearest import NodeGrid, listed_within
from companion.planning.parent_choice import ParentArrays, extend, rewire_candidates
from companion.planning.result import Tree
from companion.planning.sampling import RandomStream, Sampler
from companion.planning.settings import GartSettings
from companion.planning.simplify import CornerRule
from companion.world import World
from companion.world.obstacle_kernels import space_of
from companion.world.segments import compiled_for, segment_test

__all__ = ["GartSearch", "rrt_star_gamma", "simple_cost"]


def rrt_star_gamma(lo: list, hi: list, rewire_factor: float) -> float:
    """RRT*'s gamma for the box ``[lo, hi]`` (d = 2 or 3): radius = gamma (log n / n)^(1/d)."""
    d = len(lo)
    volume = 1.0
    for l, h in zip(lo, hi):
        volume *= h - l
    unit_ball = math.pi if d == 2 else 4.0 / 3.0 * math.pi
    return rewire_factor * 2.0 * (1.0 + 1.0 / d) ** (1.0 / d) * (volume / unit_ball) ** (1.0 / d)


def simple_cost(ec: EdgeCost) -> bool:
    """True when the cost is energy weight x length (no threat, climb or tracking term)."""
    return not (ec.uses_threat or ec.uses_climb or ec.uses_tracking)


class GartSearch:
    """The growing GART tree and one iteration of the algorithm (see the module docstring).

    Used by :func:`companion.planning.gart` and, with branches forbidden, by
    :func:`companion.planning.mgart`.

    Parameters
    ----------
    world : World
    start, goal : tuple of d floats
        Checked ends (see :func:`~companion.planning.problem.validate_problem`).
    settings : GartSettings
    rng : numpy.random.Generator
        The only source of randomness.
    """

    def __init__(self, world: World, start: tuple, goal: tuple, settings: GartSettings, rng: np.random.Generator):
        self.world = world
        self.start = start
        self.goal = goal
        self.s = settings
        self.dim = d = world.dim
        self.rule = CornerRule(settings, world)
        self.ec = EdgeCost(world, settings.cost)
        self.segment_free = segment_test(world)  # world.segment_free, compiled for worlds of balls
        self.sampler = Sampler(world, start, goal, settings.goal_bias, settings.informed, RandomStream(rng))
        self.guidance = Guidance(world, goal, settings) if settings.guidance else None
        # cost = energy weight * length: the inner loop skips the general cost terms
        self.simple_cost = simple_cost(self.ec)
        self.step = settings.step_m
        self.goal_radius = settings.goal_radius_m or settings.step_m
        self.r_max = settings.max_rewire_radius_m or 2.0 * settings.step_m
        lo, hi = world.bounds_min.tolist(), world.bounds_max.tolist()
        self.gamma = rrt_star_gamma(lo, hi, settings.rewire_factor)
        # tree
        self.pts: list[tuple] = [start]
        self.parent: list[int] = [-1]
        self.cost: list[float] = [0.0]
        self.edge_in: list[float] = [0.0]
        self.u_in: list[tuple | None] = [None]
        self.len_in: list[float] = [0.0]
        self.children: list[list[int]] = [[]]
        self.dens: list[float] = [self.ec.threat_density(start) if self.ec.uses_threat else 0.0]
        self.forbidden: list[bool] = [False]
        self.nn = NodeGrid(tuple(lo), tuple(hi), max(self.r_max, 1e-3), self.pts)
        self.nn.add(0)
        # step 4 compiled for the plain length cost without K_max among balls, cylinders and
        # prisms (else the Python loop)
        self.fast = None
        if self.simple_cost and self.rule.world is None and compiled_for(world):
            self.fast = ParentArrays(d)
            self.fast.set(0, 0.0, None)
            self.fast_world = (rule_of(settings), space_of(world))
        # goal links: node -> (edge cost, u, length); u is None only for the root's straight
        # line to the goal (gart.grow's trivial problem)
        self.goal_links: dict[int, tuple[float, tuple | None, float]] = {}
        self.best_node = -1
        self.best_cost = math.inf
        self.iterations = 0

    # ------------------------------------------------------------------ steps 1 and 2
    def sample(self) -> tuple[tuple, bool]:
        """Random sample and whether it is the goal itself (step 1)."""
        return self.sampler.sample(self.best_cost / self.s.cost.energy)

    def attract(self, p: tuple) -> tuple:
        """Sample ``p`` under the bidirectional potential (step 2)."""
        return (self.guidance or Guidance(self.world, self.goal, self.s)).attract(p)

    # ------------------------------------------------------------------ tree growth
    def steer(self, x_from: tuple, x_to: tuple) -> tuple | None:
        """At most ``step_m`` from ``x_from`` towards ``x_to`` (None when they coincide)."""
        dist = math.dist(x_from, x_to)
        if dist < 1e-9:
            return None
        if dist <= self.step:
            return x_to
        f = self.step / dist
        return tuple(a + f * (b - a) for a, b in zip(x_from, x_to))

    def radius(self) -> float:
        """Shrinking RRT* neighbour radius for the current tree size."""
        n = len(self.pts)
        if n < 2:
            return self.r_max
        r = self.gamma * (math.log(n) / n) ** (1.0 / self.dim)
        return r if r < self.r_max else self.r_max

    def choose_parent(self, x_new: tuple, neighbours: list, dens_new: float):
        """Cheapest valid parent among ``neighbours`` [(id, dist)]: (id, cost, edge, u, dist) or None."""
        pts, cost, u_in, len_in, dens = self.pts, self.cost, self.u_in, self.len_in, self.dens
        ec = self.ec
        simple = self.simple_cost
        energy = self.s.cost.energy
        if simple:
            cands = [(cost[i] + energy * dist, i, dist) for i, dist in neighbours if dist >= 1e-9]
        else:
            cands = []
            for i, dist in neighbours:
                if dist < 1e-9:
                    continue
                p = pts[i]
                u = tuple((b - a) / dist for a, b in zip(p, x_new))
                cands.append((cost[i] + ec.edge(p, x_new, dist, dens[i], dens_new) + ec.corner(u_in[i], u), i, dist))
        cands.sort()
        ok = self.rule.ok
        free = self.segment_free
        for c, i, dist in cands:
            p = pts[i]
            u = tuple((b - a) / dist for a, b in zip(p, x_new))
            if ok(u_in[i], len_in[i], u, dist) and free(p, x_new) and ok(u_in[i], len_in[i], u, dist, p):
                e = energy * dist if simple else ec.edge(p, x_new, dist, dens[i], dens_new)
                return i, c, e, u, dist
        return None

    def add_node(
        self, x_new: tuple, parent: int, cost: float, edge: float, u: tuple, length: float, dens_new: float
    ) -> int:
        """Append a node and link it to ``parent``."""
        node = len(self.pts)
        self.pts.append(x_new)
        self.parent.append(parent)
        self.cost.append(cost)
        self.edge_in.append(edge)
        self.u_in.append(u)
        self.len_in.append(length)
        self.children.append([])
        self.dens.append(dens_new)
        self.forbidden.append(False)
        self.children[parent].append(node)
        self.nn.add(node)
        if self.fast is not None:
            self.fast.set(node, cost, u, length)
        return node

    def rewire(self, node: int, neighbours: list) -> bool:
        """Re-parent neighbours that get cheaper through ``node``; True if any changed."""
        # only the root's u_in and goal link have no direction, and the root is never ``node``,
        # a neighbour rewired (i == 0 is skipped) nor anyone's child
        u_in = cast("list[tuple]", self.u_in)
        goal_links = cast("dict[int, tuple[float, tuple, float]]", self.goal_links)
        pts, cost, len_in = self.pts, self.cost, self.len_in
        x_new = pts[node]
        c_new = cost[node]
        u_node, len_node = u_in[node], len_in[node]
        ec, ok = self.ec, self.rule.ok
        free = self.segment_free
        energy = self.s.cost.energy
        skip = self.parent[node]
        changed = False
        for i, dist in neighbours:
            if c_new + dist * energy >= cost[i]:
                continue  # cannot improve even on length alone
            if i == 0 or i == skip or dist < 1e-9:
                continue
            p = pts[i]
            u = tuple((b - a) / dist for a, b in zip(x_new, p))
            e = ec.edge(x_new, p, dist, self.dens[node], self.dens[i])
            c = c_new + e + ec.corner(u_node, u)
            if c >= cost[i] - 1e-9:
                continue
            if not ok(u_node, len_node, u, dist):
                continue
            if any(not ok(u, dist, u_in[ch], len_in[ch]) for ch in self.children[i]):
                continue
            link = goal_links.get(i)
            if link is not None and not ok(u, dist, link[1], link[2]):
                continue
            if not free(x_new, p):
                continue
            if self.rule.world is not None and not (
                ok(u_node, len_node, u, dist, x_new)
                and all(ok(u, dist, u_in[ch], len_in[ch], p) for ch in self.children[i])
                and (link is None or ok(u, dist, link[1], link[2], p))
            ):
                continue
            self.children[self.parent[i]].remove(i)
            self.parent[i] = node
            self.children[node].append(i)
            self.edge_in[i], self.u_in[i], self.len_in[i], cost[i] = e, u, dist, c
            if self.fast is not None:
                self.fast.set(i, c, u, dist)
            self.propagate(i)
            changed = True
        return changed

    def propagate(self, root: int) -> None:
        """Recompute cost-to-come below ``root`` after it changed parent."""
        cost, edge_in, children = self.cost, self.edge_in, self.children
        u_in = cast("list[tuple]", self.u_in)  # a child's direction: only the root's is None
        corner = self.ec.corner
        mirror = self.fast.cost if self.fast is not None else None
        stack = [root]
        while stack:
            n = stack.pop()
            for ch in children[n]:
                cost[ch] = cost[n] + edge_in[ch] + corner(u_in[n], u_in[ch])
                if mirror is not None:
                    mirror[ch] = cost[ch]
                stack.append(ch)

    def connect_goal(self, node: int) -> bool:
        """Try a straight edge from ``node`` to the goal; record it as a goal link."""
        p = self.pts[node]
        dist = math.dist(p, self.goal)
        if dist > self.goal_radius:
            return False
        if dist < 1e-9:
            u = self.u_in[node] or tuple(1.0 if k == 0 else 0.0 for k in range(self.dim))
            self.goal_links[node] = (0.0, u, 0.0)
            return True
        u = tuple((b - a) / dist for a, b in zip(p, self.goal))
        if not self.rule.ok(self.u_in[node], self.len_in[node], u, dist):
            return False
        if not self.segment_free(p, self.goal):
            return False
        if not self.rule.ok(self.u_in[node], self.len_in[node], u, dist, p):
            return False
        dens_goal = self.ec.threat_density(self.goal) if self.ec.uses_threat else 0.0
        self.goal_links[node] = (self.ec.edge(p, self.goal, dist, self.dens[node], dens_goal), u, dist)
        return True

    def goal_cost(self, node: int) -> float:
        """Cost of reaching the goal through the goal link of ``node``."""
        e, u, _ = self.goal_links[node]
        # u is None only for the root's straight line, whose corner costs nothing (no u_in)
        return self.cost[node] + e + (self.ec.corner(self.u_in[node], u) if e > 0.0 and u is not None else 0.0)

    def update_best(self) -> bool:
        """Refresh the best goal link; True when the best cost went down."""
        best_node, best_cost = self.best_node, self.best_cost
        for node in self.goal_links:
            c = self.goal_cost(node)
            if c < best_cost - 1e-12:
                best_node, best_cost = node, c
        if best_node >= 0:
            best_cost = self.goal_cost(best_node)
        improved = best_cost < self.best_cost - 1e-12
        self.best_node, self.best_cost = best_node, best_cost
        return improved

    def iterate(self) -> int:
        """One GART iteration; returns the new node id or -1 when the sample was rejected."""
        self.iterations += 1
        x_rand, is_goal = self.sampler.sample(self.best_cost / self.s.cost.energy)
        if not is_goal and self.guidance is not None:
            x_rand = self.guidance.attract(x_rand)
        near = self.nn.nearest(x_rand)
        if near < 0:
            return -1
        x_new = self.steer(self.pts[near], x_rand)
        if x_new is None:
            return -1
        if self.fast is not None:
            return self.extend_compiled(near, x_new)
        if not self.world.point_free(x_new):
            return -1
        radius = self.radius()
        listed = listed_within(self.pts[near], x_new, radius)
        dens_new = self.ec.threat_density(x_new) if self.ec.uses_threat else 0.0
        neighbours = self.nn.within(x_new, radius)
        if not listed:
            neighbours.append((near, math.dist(self.pts[near], x_new)))
        chosen = self.choose_parent(x_new, neighbours, dens_new)
        if chosen is None:
            return -1
        parent, c, e, u, dist = chosen
        node = self.add_node(x_new, parent, c, e, u, dist, dens_new)
        self.rewire(node, neighbours)
        self.connect_goal(node)
        return node

    def extend_compiled(self, near: int, x_new: tuple) -> int:
        """Steps 4 to 6 from the steered ``x_new`` (plain length cost, no K_max, compiled obstacles)."""
        fast, arrays, energy = self.fast, self.nn.arrays, self.s.cost.energy
        assert fast is not None  # iterate calls this only with the compiled arrays
        free, pos, ids, dists = extend(
            np.array(x_new),
            near,
            math.dist(self.pts[near], x_new),
            self.radius(),
            arrays.coords,
            arrays.keys,
            arrays.active,
            arrays.count,
            fast.cost,
            fast.u,
            fast.has_u,
            fast.length,
            energy,
            0.0,
            *self.fast_world,
        )
        if pos < 0:
            return -1
        parent, dist = int(ids[pos]), float(dists[pos])
        u = tuple((b - a) / dist for a, b in zip(self.pts[parent], x_new))
        c = self.cost[parent] + energy * dist
        node = self.add_node(x_new, parent, c, energy * dist, u, dist, 0.0)
        cands = rewire_candidates(ids, dists, fast.cost, c, energy, parent).tolist()
        self.rewire(node, [(int(ids[k]), float(dists[k])) for k in cands])
        self.connect_goal(node)
        return node

    # ------------------------------------------------------------------ output
    def branch(self, node: int) -> list[int]:
        """Node ids from the root to ``node``."""
        ids = []
        while node >= 0:
            ids.append(node)
            node = self.parent[node]
        return ids[::-1]

    def path_to_goal(self, node: int) -> np.ndarray:
        """(M, d) path root -> ``node`` -> goal."""
        pts = [self.pts[i] for i in self.branch(node)]
        if len(pts) == 1 or math.dist(pts[-1], self.goal) > 1e-9:
            pts.append(self.goal)  # a path always has both ends, even when start == goal
        return np.array(pts, dtype=float)

    def tree(self) -> Tree:
        """Snapshot of the tree as arrays."""
        return Tree(
            nodes=np.array(self.pts, dtype=float).reshape(-1, self.dim),
            parents=np.array(self.parent, dtype=np.int64),
            forbidden=np.array(self.forbidden, dtype=bool),
        )
