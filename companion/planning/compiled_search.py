"""GART with the whole iteration compiled, for the common case; the tree lives in numpy arrays.

:func:`compiled_case` says whether a problem is the common case: the plain length cost
(energy weight x length), no K_max corner clearance, a world of at most 256 discs/spheres (at
most 128 with guidance, the guidance kernel's limit). :class:`CompiledGart` then holds the tree
in preallocated arrays (doubled when full) and :func:`grow_compiled` runs the iterations in
batches through :func:`~companion.planning.iteration_kernel.grow_batch`, returning to Python
when the best cost goes down, when the stream of uniform numbers needs its next batch, and
between batches to look at the clock. The uniform numbers are the batches of the planner's
:class:`~companion.planning.sampling.RandomStream` (same sizes, same order), so the tree, the
path and the generator's state after the call are those of
:class:`~companion.planning.search.GartSearch`'s Python iteration for the same seed. Everything
else (threat or tracking cost, boxes, many obstacles) keeps :class:`GartSearch`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from companion.planning import iteration_kernel as kernel
from companion.planning.corner_kernel import climb_penalty_of, edge_cost, rule_of
from companion.planning.cost import EdgeCost
from companion.planning.guidance import Guidance
from companion.planning.nearest import bucket_key, grid_shape
from companion.planning.result import Tree
from companion.planning.sampling import RandomStream, ellipse_frame
from companion.planning.search import rrt_star_gamma
from companion.planning.settings import GartSettings
from companion.world import World
from companion.world.obstacle_kernels import segment_clear, space_of
from companion.world.segments import compiled_for

__all__ = ["CompiledGart", "compiled_case", "grow_compiled"]

_FIRST_CAPACITY = 256
_FIRST_BATCH = 32  # iterations per call; adapted so that a call lasts about _SLICE_S
_MAX_BATCH = 4096
_SLICE_S = 1e-3


def compiled_case(world: World, settings: GartSettings) -> bool:
    """True when :class:`CompiledGart` applies (see the module docstring)."""
    if not compiled_for(world):
        return False
    ec = EdgeCost(world, settings.cost)
    if ec.uses_threat or ec.uses_tracking:
        return False
    return not settings.guidance or len(world.obstacles) <= Guidance.SCAN_ALL_BELOW


def _world_arrays(world: World, r_max: float, influence_m: float | None) -> tuple:
    """``(lo, hi, 1/bucket edge, bucket shape, arrays)`` of a world, memoised per world and radii.

    ``arrays``: bounds lo, hi, span (d,), the obstacles (``space``,
    :func:`~companion.world.obstacle_kernels.space_of`), guidance rows (N, d + 2) (none without
    guidance), bucket shape (d,).
    """
    key = ("compiled_gart", r_max, influence_m)
    found = world._memo.get(key)
    if found is None:
        d = world.dim
        lo, hi = world.bounds_min.tolist(), world.bounds_max.tolist()
        inv_cell = 1.0 / max(r_max, 1e-3)
        shape = grid_shape(lo, hi, inv_cell)
        guide = Guidance.ball_rows_of(world, influence_m) if influence_m is not None else np.zeros((0, d + 2))
        arrays = (
            np.array(lo),
            np.array(hi),
            np.array([h - l for l, h in zip(lo, hi)]),
            space_of(world),
            guide,
            np.array(shape, dtype=np.int64),
        )
        found = (lo, hi, inv_cell, shape, arrays)
        world._memo[key] = found
    return found


class CompiledGart:
    """The GART tree in arrays and the constants of the compiled iteration.

    Parameters
    ----------
    world : World
        A world of the compiled case (:func:`compiled_case`).
    start, goal : tuple of d floats
    settings : GartSettings
    rng : numpy.random.Generator
    """

    # the tree's and the goal links' arrays, (re)bound by _allocate
    tree_arrays: tuple[np.ndarray, ...]
    links: tuple[np.ndarray, ...]
    coords: np.ndarray
    keys: np.ndarray
    active: np.ndarray
    parent: np.ndarray
    cost: np.ndarray
    u: np.ndarray
    has_u: np.ndarray
    length: np.ndarray
    edge: np.ndarray
    first_child: np.ndarray
    next_sib: np.ndarray
    prev_sib: np.ndarray
    link_of: np.ndarray

    def __init__(self, world: World, start: tuple, goal: tuple, settings: GartSettings, rng: np.random.Generator):
        self.world, self.start, self.goal, self.s = world, start, goal, settings
        self.dim = d = world.dim
        self.stream = RandomStream(rng)
        self.rand = np.empty(0)
        step = settings.step_m
        r_max = settings.max_rewire_radius_m or 2.0 * step
        influence = settings.influence_m if settings.guidance else None
        lo, hi, inv_cell, shape, world_arrays = _world_arrays(world, r_max, influence)
        ellipse = ellipse_frame(start, goal)
        c_min, basis, centre = ellipse if ellipse is not None else (0.0, np.zeros((0, d)), start)
        goal_arr, self.start_arr = np.array(goal), np.array(start)
        self.problem = (
            (goal_arr,)
            + world_arrays[:5]
            + (
                np.array(basis, dtype=float).reshape(-1, d),
                np.array(centre),
                inv_cell,
                world_arrays[5],
                rule_of(settings),
            )
        )
        self.energy = settings.cost.energy
        self.climb = climb_penalty_of(settings, d)
        self.params = (
            float(settings.goal_bias),
            float(step),
            float(settings.goal_radius_m or step),
            float(r_max),
            rrt_star_gamma(lo, hi, settings.rewire_factor),
            float(self.energy),
            self.climb,
            float(c_min),
            float(settings.obstacle_gain_m2),
            float(settings.repel_offset_m),
            float(settings.goal_gain_m),
            float(settings.max_guidance_m),
            float(settings.influence_m),
            bool(settings.guidance),
            bool(settings.informed),
            ellipse is not None,
        )
        self.counters = np.array([0, 0, -1, 0, 0], dtype=np.int64)
        self.best = np.array([math.inf])
        self._allocate(_FIRST_CAPACITY)
        self.coords[0] = start  # the root, bucket key as NodeGrid's
        self.keys[0], self.active[0] = bucket_key(start, lo, inv_cell, shape), True
        self.parent[0], self.cost[0], self.first_child[0], self.link_of[0] = -1, 0.0, -1, -1
        self.counters[kernel.N_NODES] = 1

    def _allocate(self, cap: int) -> None:
        """(Re)allocate every array with room for ``cap`` nodes, keeping the rows written."""
        d, n = self.dim, self.n_nodes
        f, i, b = np.float64, np.int64, np.bool_
        shapes = (
            ((cap, d), f),
            ((cap,), i),
            ((cap,), b),
            ((cap,), i),
            ((cap,), f),
            ((cap, d), f),
            ((cap,), b),
            ((cap,), f),
            ((cap,), f),
            ((cap,), i),
            ((cap,), i),
            ((cap,), i),
        )
        link_shapes = ((cap,), i), ((cap,), i), ((cap,), f), ((cap, d), f), ((cap,), f)
        old = getattr(self, "tree_arrays", None)
        tree = tuple(np.zeros(shape, dtype) if dtype is b else np.empty(shape, dtype) for shape, dtype in shapes)
        links = tuple(np.empty(shape, dtype) for shape, dtype in link_shapes)
        if old is not None:
            for new, before in zip(tree + links, old + self.links):
                new[:n] = before[:n]
        self.tree_arrays, self.links = tree, links
        (
            self.coords,
            self.keys,
            self.active,
            self.parent,
            self.cost,
            self.u,
            self.has_u,
            self.length,
            self.edge,
            self.first_child,
            self.next_sib,
            self.prev_sib,
        ) = tree
        self.link_of = links[0]

    # ------------------------------------------------------------------ state read by gart()
    @property
    def iterations(self) -> int:
        return int(self.counters[kernel.ITERATIONS])

    @property
    def best_node(self) -> int:
        return int(self.counters[kernel.BEST_NODE])

    @property
    def best_cost(self) -> float:
        return float(self.best[0])

    @property
    def n_nodes(self) -> int:
        return int(self.counters[kernel.N_NODES])

    # ------------------------------------------------------------------ growth
    def link_straight_line(self) -> None:
        """The trivial problem: the start's straight edge to the goal as goal link (node 0)."""
        dist = math.dist(self.start, self.goal)
        _, gl_node, gl_e, gl_u, gl_len = self.links
        e = edge_cost(self.start_arr, self.problem[0], dist, self.energy, self.climb)
        gl_node[0], gl_e[0], gl_len[0] = 0, e, dist
        self.link_of[0] = 0
        self.counters[kernel.N_LINKS] = 1
        self.counters[kernel.BEST_NODE] = 0
        self.best[0] = self.cost[0] + gl_e[0]

    def run(self, max_iterations: int, mode: int = kernel.GART) -> int:
        """At most ``max_iterations`` iterations; the kernel's status (BATCH_DONE, IMPROVED or NEW_NODE)."""
        need = self.n_nodes + max_iterations
        if need > self.coords.shape[0]:
            self._allocate(max(need, 2 * self.coords.shape[0]))
        stop = self.counters[kernel.ITERATIONS] + max_iterations
        while True:
            if self.counters[kernel.RANDOM_POS] >= self.rand.shape[0]:
                self.more_random()
            status = kernel.grow_batch(
                self.tree_arrays,
                self.links,
                self.counters,
                self.best,
                self.rand,
                self.problem,
                self.params,
                int(stop - self.counters[kernel.ITERATIONS]),
                mode,
            )
            if status != kernel.NEED_RANDOM:
                return status
            self.more_random()  # (at least one iteration is left: a sample needed more numbers)

    def more_random(self) -> None:
        """Append the stream's next batch to the unread uniform numbers."""
        pos = int(self.counters[kernel.RANDOM_POS])
        self.rand = np.concatenate([self.rand[pos:], self.stream.draw_batch()])
        self.counters[kernel.RANDOM_POS] = 0

    # ------------------------------------------------------------------ output
    def branch(self, node: int) -> list[int]:
        """Node ids from the root to ``node``."""
        ids = []
        parent = self.parent
        while node >= 0:
            ids.append(node)
            node = int(parent[node])
        return ids[::-1]

    def path_to_goal(self, node: int) -> np.ndarray:
        """(M, d) path root -> ``node`` -> goal."""
        pts = self.coords[self.branch(node)]
        if pts.shape[0] == 1 or math.dist(pts[-1].tolist(), self.goal) > 1e-9:
            pts = np.vstack([pts, np.array(self.goal)])
        return pts

    def tree_snapshot(self) -> Tree:
        """The tree as arrays (copies)."""
        n = self.n_nodes
        return Tree(nodes=self.coords[:n].copy(), parents=self.parent[:n].copy(), forbidden=np.zeros(n, dtype=bool))


def grow_compiled(
    search: CompiledGart, t0: float, deadline: float, iter_limit: float, stop_at_first: bool
) -> tuple[list[tuple[float, float]], float | None]:
    """:func:`companion.planning.gart.grow` for a :class:`CompiledGart`: same budgets, same history."""
    history: list[tuple[float, float]] = []
    first_s = None
    clock = time.perf_counter
    goal, space = search.problem[0], search.problem[4]
    if segment_clear(search.start_arr, goal, space):  # trivial problem: the straight line
        search.link_straight_line()
        first_s = clock() - t0
        history.append((first_s, search.best_cost))
    batch = _FIRST_BATCH
    while first_s is None or not stop_at_first:
        left = iter_limit - search.iterations
        if left <= 0:
            break
        t_call = clock()
        if t_call >= deadline:
            break
        size = int(min(left, batch))
        status = search.run(size)
        now = clock()
        if status == kernel.IMPROVED:
            if first_s is None:
                first_s = now - t0
            history.append((now - t0, search.best_cost))
        elif now - t_call < 0.5 * _SLICE_S:
            batch = min(2 * batch, _MAX_BATCH)
        elif now - t_call > 2.0 * _SLICE_S and batch > 1:
            batch //= 2
    return history, first_s
