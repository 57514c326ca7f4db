"""GART: the paper's guided, RRT*-based planner (section 3.1, Algorithm 1, Fig. 6a).

Each iteration

1. ``sample``: the goal with probability ``goal_bias``; otherwise a uniform point of the bounds,
   or, once a path exists and ``informed`` is on, a point of the prolate hyperspheroid that can
   still shorten it (Gammell et al., Informed RRT*);
2. ``attract``: the sample feels the paper's bidirectional potential. Inside an inflated obstacle
   it is repelled to just outside the surface; outside, each obstacle within ``influence_m``
   attracts it towards its surface with a force ``k / c`` inversely proportional to the clearance
   ``c`` (capped at ``c / 2`` so it never crosses the surface); the goal always attracts it by
   ``goal_gain_m``. The total displacement is capped at ``max_guidance_m`` (below 128 obstacles
   every obstacle is scanned with plain floats; with more, only those listed for the sample's
   grid cell);
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
may leave descendants' corner costs slightly suboptimal. The final path is shortcut by
:mod:`companion.planning.simplify` (optional, separate module). Everything random comes from
``rng``: a fixed seed gives the same path.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from companion.errors import PlanningError
from companion.planning.cost import EdgeCost, path_cost, path_length_m
from companion.planning.nearest import NodeGrid
from companion.planning.result import PlanResult, Tree
from companion.planning.settings import GartSettings
from companion.planning.simplify import CornerRule, shortcut_path
from companion.world import World

__all__ = ["gart", "GartSearch", "validate_problem"]

log = logging.getLogger(__name__)

_RANDOM_BATCH = 8192
_SCAN_ALL_OBSTACLES_BELOW = 128  # guidance scans every obstacle below this count, else grid cells


def validate_problem(world, start, goal, rng, max_time_s, max_iterations) -> tuple[tuple, tuple]:
    """Check the planner arguments; return start and goal as tuples of floats.

    Raises
    ------
    PlanningError
        Naming the argument: wrong type or dimension, NaN/inf, outside the bounds, bad budget.
    """
    if not isinstance(world, World):
        raise PlanningError(f"world: expected a companion.world.World, got {type(world).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise PlanningError(f"rng: expected numpy.random.Generator, got {type(rng).__name__}")
    points = []
    for name, value in (("start", start), ("goal", goal)):
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise PlanningError(f"{name}: expected {world.dim} numbers, got {value!r}") from None
        if arr.shape != (world.dim,):
            raise PlanningError(f"{name}: expected shape ({world.dim},) for a {world.dim}D world, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise PlanningError(f"{name}: coordinates must be finite, got {arr.tolist()}")
        p = tuple(float(x) for x in arr)
        if not world.in_bounds(p):
            raise PlanningError(f"{name}: {list(p)} is outside the world bounds "
                                f"{world.bounds_min.tolist()}..{world.bounds_max.tolist()}")
        points.append(p)
    if max_time_s is not None:
        if isinstance(max_time_s, bool) or not isinstance(max_time_s, (int, float)) \
                or not math.isfinite(max_time_s) or max_time_s <= 0:
            raise PlanningError(f"max_time_s: must be a positive number of seconds, got {max_time_s!r}")
    if max_iterations is not None:
        if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations <= 0:
            raise PlanningError(f"max_iterations: must be a positive integer, got {max_iterations!r}")
    return points[0], points[1]


class GartSearch:
    """The growing GART tree and one iteration of the algorithm (see the module docstring).

    Used by :func:`gart` and, with branches forbidden, by :func:`companion.planning.mgart`.
    """

    def __init__(self, world: World, start: tuple, goal: tuple, settings: GartSettings,
                 rng: np.random.Generator):
        self.world = world
        self.start = start
        self.goal = goal
        self.s = settings
        self.rng = rng
        self.dim = d = world.dim
        self.lo = tuple(world.bounds_min.tolist())
        self.hi = tuple(world.bounds_max.tolist())
        self.span = tuple(h - l for l, h in zip(self.lo, self.hi))
        self.margin = world.margin_m
        self.rule = CornerRule(settings, world)
        self.ec = EdgeCost(world, settings.cost)
        # cost = energy weight * length: the inner loop skips the general cost terms
        n_obstacles = len(world.obstacles)
        self._guide_all = n_obstacles <= _SCAN_ALL_OBSTACLES_BELOW
        self._balls = world.inflated_balls
        self._others = world.non_ball_obstacles
        self.simple_cost = not (self.ec.uses_threat or self.ec.uses_climb or self.ec.uses_tracking)
        self.step = settings.step_m
        self.goal_radius = settings.goal_radius_m or settings.step_m
        self.r_max = settings.max_rewire_radius_m or 2.0 * settings.step_m
        volume = 1.0
        for s in self.span:
            volume *= s
        unit_ball = math.pi if d == 2 else 4.0 / 3.0 * math.pi
        self.gamma = settings.rewire_factor * 2.0 * (1.0 + 1.0 / d) ** (1.0 / d) * (volume / unit_ball) ** (1.0 / d)
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
        self.nn = NodeGrid(self.lo, self.hi, max(self.r_max, 1e-3), self.pts)
        self.nn.add(0)
        # goal links: node -> (edge cost, u, length)
        self.goal_links: dict[int, tuple[float, tuple, float]] = {}
        self.best_node = -1
        self.best_cost = math.inf
        self.iterations = 0
        self._rand: list[float] = []
        self._rand_i = 0
        self._ellipse = self._ellipse_frame()

    # ------------------------------------------------------------------ sampling
    def _u(self) -> float:
        if self._rand_i >= len(self._rand):
            self._rand = self.rng.random(_RANDOM_BATCH).tolist()
            self._rand_i = 0
        v = self._rand[self._rand_i]
        self._rand_i += 1
        return v

    def _ellipse_frame(self):
        a = [g - s for s, g in zip(self.start, self.goal)]
        c_min = math.sqrt(sum(x * x for x in a))
        if c_min < 1e-9:
            return None
        a1 = [x / c_min for x in a]
        basis = [a1]
        for e in range(self.dim):
            v = [1.0 if k == e else 0.0 for k in range(self.dim)]
            for b in basis:
                dot = sum(x * y for x, y in zip(v, b))
                v = [x - dot * y for x, y in zip(v, b)]
            n = math.sqrt(sum(x * x for x in v))
            if n > 1e-6:
                basis.append([x / n for x in v])
            if len(basis) == self.dim:
                break
        centre = tuple(0.5 * (s + g) for s, g in zip(self.start, self.goal))
        return c_min, basis, centre

    def sample_uniform(self) -> tuple:
        """A uniform point of the bounds."""
        u = self._u
        return tuple(l + u() * s for l, s in zip(self.lo, self.span))

    def sample_informed(self, c_best_m: float) -> tuple | None:
        """A uniform point of the prolate hyperspheroid with foci start/goal, diameter ``c_best_m``."""
        if self._ellipse is None:
            return None
        c_min, basis, centre = self._ellipse
        if c_best_m <= c_min:
            return None
        r_major = 0.5 * c_best_m
        r_minor = 0.5 * math.sqrt(c_best_m * c_best_m - c_min * c_min)
        u = self._u
        for _ in range(20):
            while True:
                x = [2.0 * u() - 1.0 for _ in range(self.dim)]
                if sum(v * v for v in x) <= 1.0:
                    break
            p = list(centre)
            for k, b in enumerate(basis):
                scale = (r_major if k == 0 else r_minor) * x[k]
                for m in range(self.dim):
                    p[m] += scale * b[m]
            p = tuple(p)
            if self.world.in_bounds(p):
                return p
        return None

    def sample(self) -> tuple[tuple, bool]:
        """Random sample and whether it is the goal itself."""
        if self._u() < self.s.goal_bias:
            return self.goal, True
        if self.s.informed and self.best_cost < math.inf:
            p = self.sample_informed(self.best_cost / self.s.cost.energy)
            if p is not None:
                return p, False
        return self.sample_uniform(), False

    def attract(self, p: tuple) -> tuple:
        """Apply the bidirectional potential (obstacles and goal) to sample ``p``."""
        s = self.s
        force = [0.0] * self.dim
        margin = self.margin
        influence = s.influence_m
        gain = s.obstacle_gain_m2
        repel = s.repel_offset_m
        dim = self.dim
        if self._guide_all:
            balls, others = self._balls, self._others   # few obstacles: a plain scan is cheapest
        else:
            balls, others = (), self.world.obstacles_acting_on_cell(self.world.cell_of(p), influence + margin)
        if balls:
            self._attract_balls(p, balls, force)
        for ob in others:
            c = ob.sdf(p) - margin
            if c >= influence:
                continue
            g = ob.gradient(p)
            # inside: repel out of the inflated obstacle; outside: attract towards its surface
            mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
            for i in range(dim):
                force[i] += mag * g[i]
        to_goal = [g - x for g, x in zip(self.goal, p)]
        dist_goal = math.sqrt(sum(v * v for v in to_goal))
        if dist_goal > 1e-9:
            k = min(s.goal_gain_m, dist_goal) / dist_goal
            for i in range(self.dim):
                force[i] += k * to_goal[i]
        norm = math.sqrt(sum(f * f for f in force))
        if norm > s.max_guidance_m:
            scale = s.max_guidance_m / norm
            force = [f * scale for f in force]
        return tuple(min(max(x + f, l), h) for x, f, l, h in zip(p, force, self.lo, self.hi))

    def _attract_balls(self, p: tuple, balls: tuple, force: list) -> None:
        """Add the potential of the discs/spheres ``balls`` (world records) at ``p`` to ``force``."""
        s = self.s
        influence, gain, repel = s.influence_m, s.obstacle_gain_m2, s.repel_offset_m
        if self.dim == 2:
            x, y = p
            for cx, cy, _, r in balls:
                dx, dy = x - cx, y - cy
                reach = r + influence
                if dx * dx + dy * dy >= reach * reach:
                    continue
                n = math.sqrt(dx * dx + dy * dy)
                c = n - r
                mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
                if n > 1e-12:
                    force[0] += mag * dx / n
                    force[1] += mag * dy / n
                else:
                    force[0] += mag
            return
        x, y, z = p
        for cx, cy, cz, _, r in balls:
            dx, dy, dz = x - cx, y - cy, z - cz
            reach = r + influence
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= reach * reach:
                continue
            n = math.sqrt(d2)
            c = n - r
            mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
            if n > 1e-12:
                force[0] += mag * dx / n
                force[1] += mag * dy / n
                force[2] += mag * dz / n
            else:
                force[0] += mag

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
        cands = []
        for i, dist in neighbours:
            if dist < 1e-9:
                continue
            if simple:
                cands.append((cost[i] + energy * dist, i, dist))
            else:
                p = pts[i]
                u = tuple((b - a) / dist for a, b in zip(p, x_new))
                cands.append((cost[i] + ec.edge(p, x_new, dist, dens[i], dens_new) + ec.corner(u_in[i], u), i, dist))
        cands.sort()
        ok = self.rule.ok
        free = self.world.segment_free
        for c, i, dist in cands:
            p = pts[i]
            u = tuple((b - a) / dist for a, b in zip(p, x_new))
            if ok(u_in[i], len_in[i], u, dist) and free(p, x_new) and ok(u_in[i], len_in[i], u, dist, p):
                e = energy * dist if simple else ec.edge(p, x_new, dist, dens[i], dens_new)
                return i, c, e, u, dist
        return None

    def add_node(self, x_new: tuple, parent: int, cost: float, edge: float, u: tuple, length: float,
                 dens_new: float) -> int:
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
        return node

    def rewire(self, node: int, neighbours: list) -> bool:
        """Re-parent neighbours that get cheaper through ``node``; True if any changed."""
        pts, cost, u_in, len_in = self.pts, self.cost, self.u_in, self.len_in
        x_new = pts[node]
        c_new = cost[node]
        u_node, len_node = u_in[node], len_in[node]
        ec, ok = self.ec, self.rule.ok
        free = self.world.segment_free
        changed = False
        for i, dist in neighbours:
            if i == 0 or i == self.parent[node] or dist < 1e-9:
                continue
            p = pts[i]
            if c_new + dist * self.s.cost.energy >= cost[i]:
                continue  # cannot improve even on length alone
            u = tuple((b - a) / dist for a, b in zip(x_new, p))
            e = ec.edge(x_new, p, dist, self.dens[node], self.dens[i])
            c = c_new + e + ec.corner(u_node, u)
            if c >= cost[i] - 1e-9:
                continue
            if not ok(u_node, len_node, u, dist):
                continue
            if any(not ok(u, dist, u_in[ch], len_in[ch]) for ch in self.children[i]):
                continue
            link = self.goal_links.get(i)
            if link is not None and not ok(u, dist, link[1], link[2]):
                continue
            if not free(x_new, p):
                continue
            if self.rule.world is not None and not (
                    ok(u_node, len_node, u, dist, x_new)
                    and all(ok(u, dist, u_in[ch], len_in[ch], p) for ch in self.children[i])
                    and (link is None or ok(u, dist, link[1], link[2], p))):
                continue
            self.children[self.parent[i]].remove(i)
            self.parent[i] = node
            self.children[node].append(i)
            self.edge_in[i], self.u_in[i], self.len_in[i], cost[i] = e, u, dist, c
            self.propagate(i)
            changed = True
        return changed

    def propagate(self, root: int) -> None:
        """Recompute cost-to-come below ``root`` after it changed parent."""
        cost, u_in, edge_in, children = self.cost, self.u_in, self.edge_in, self.children
        corner = self.ec.corner
        stack = [root]
        while stack:
            n = stack.pop()
            for ch in children[n]:
                cost[ch] = cost[n] + edge_in[ch] + corner(u_in[n], u_in[ch])
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
        if not self.world.segment_free(p, self.goal):
            return False
        if not self.rule.ok(self.u_in[node], self.len_in[node], u, dist, p):
            return False
        dens_goal = self.ec.threat_density(self.goal) if self.ec.uses_threat else 0.0
        self.goal_links[node] = (self.ec.edge(p, self.goal, dist, self.dens[node], dens_goal), u, dist)
        return True

    def goal_cost(self, node: int) -> float:
        """Cost of reaching the goal through the goal link of ``node``."""
        e, u, _ = self.goal_links[node]
        return self.cost[node] + e + (self.ec.corner(self.u_in[node], u) if e > 0.0 else 0.0)

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
        x_rand, is_goal = self.sample()
        if not is_goal and self.s.guidance:
            x_rand = self.attract(x_rand)
        near = self.nn.nearest(x_rand)
        if near < 0:
            return -1
        x_new = self.steer(self.pts[near], x_rand)
        if x_new is None or not self.world.point_free(x_new):
            return -1
        neighbours = self.nn.within(x_new, self.radius())
        if all(i != near for i, _ in neighbours):
            neighbours.append((near, math.dist(self.pts[near], x_new)))
        dens_new = self.ec.threat_density(x_new) if self.ec.uses_threat else 0.0
        chosen = self.choose_parent(x_new, neighbours, dens_new)
        if chosen is None:
            return -1
        parent, c, e, u, dist = chosen
        node = self.add_node(x_new, parent, c, e, u, dist, dens_new)
        self.rewire(node, neighbours)
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
        return Tree(nodes=np.array(self.pts, dtype=float).reshape(-1, self.dim),
                    parents=np.array(self.parent, dtype=np.int64),
                    forbidden=np.array(self.forbidden, dtype=bool))


def _failed(status: str, t0: float) -> PlanResult:
    return PlanResult(status=status, path=None, cost=math.inf, length_m=math.inf, iterations=0,
                      elapsed_s=time.perf_counter() - t0, time_to_first_s=None, tree=None)


def finish_path(world: World, path: np.ndarray, settings: GartSettings) -> tuple[np.ndarray, float, float]:
    """Shortcut (if enabled) and cost a found path: (path, cost, length_m)."""
    if settings.simplify.enabled and path.shape[0] > 2:
        path = shortcut_path(world, path, settings)
    return path, path_cost(world, path, settings.cost), path_length_m(path)


def gart(world: World, start, goal, *, rng: np.random.Generator, max_time_s: float | None = None,
         max_iterations: int | None = None, stop_at_first: bool = False,
         settings: GartSettings | None = None) -> PlanResult:
    """Plan from ``start`` to ``goal`` with GART (paper section 3.1).

    Parameters
    ----------
    world : World
    start, goal : (d,) array_like
        Local NED metres, inside the bounds.
    rng : numpy.random.Generator
        The only source of randomness (a fixed seed gives the same path).
    max_time_s, max_iterations : optional
        Budgets; with neither, ``settings.time_budget_s`` applies. The search stops at the first
        budget reached (or at the first path with ``stop_at_first``).
    stop_at_first : bool
        Return as soon as a path exists (no anytime improvement).
    settings : GartSettings, optional

    Returns
    -------
    PlanResult
        ``status`` 'exact' with a collision-free ``path`` (M, d); 'timeout' without a path;
        'invalid_start' / 'invalid_goal' when an end lies in an inflated obstacle.

    Raises
    ------
    PlanningError
        Bad arguments (naming them): wrong dimension, NaN/inf, end outside the bounds, bad budget.
    """
    t0 = time.perf_counter()
    settings = settings or GartSettings()
    if not isinstance(settings, GartSettings):
        raise PlanningError(f"settings: expected GartSettings, got {type(settings).__name__}")
    start_t, goal_t = validate_problem(world, start, goal, rng, max_time_s, max_iterations)
    if not world.point_free(start_t):
        return _failed("invalid_start", t0)
    if not world.point_free(goal_t):
        return _failed("invalid_goal", t0)
    if max_time_s is None and max_iterations is None:
        max_time_s = settings.time_budget_s
    deadline = t0 + max_time_s if max_time_s is not None else math.inf
    iter_limit = max_iterations if max_iterations is not None else math.inf
    search = GartSearch(world, start_t, goal_t, settings, rng)
    history: list[tuple[float, float]] = []
    first_s = None
    clock = time.perf_counter
    if world.segment_free(start_t, goal_t):  # trivial problem: the straight line
        search.goal_links[0] = (search.ec.edge(start_t, goal_t, math.dist(start_t, goal_t)),
                                None, math.dist(start_t, goal_t))
        search.update_best()
        first_s = clock() - t0
        history.append((first_s, search.best_cost))
    while first_s is None or not stop_at_first:
        if search.iterations >= iter_limit or clock() >= deadline:
            break
        node = search.iterate()
        if node < 0:
            continue
        if search.goal_links and search.update_best():
            now = clock() - t0
            if first_s is None:
                first_s = now
                log.debug("gart: first path after %d iterations, %.1f ms, cost %.2f",
                          search.iterations, 1e3 * now, search.best_cost)
            history.append((now, search.best_cost))
    tree = search.tree()
    if search.best_node < 0:
        return PlanResult(status="timeout", path=None, cost=math.inf, length_m=math.inf,
                          iterations=search.iterations, elapsed_s=clock() - t0, time_to_first_s=None,
                          tree=tree, cost_history=())
    path, cost, length = finish_path(world, search.path_to_goal(search.best_node), settings)
    return PlanResult(status="exact", path=path, cost=cost, length_m=length, iterations=search.iterations,
                      elapsed_s=clock() - t0, time_to_first_s=first_s, tree=tree,
                      cost_history=tuple(history))
