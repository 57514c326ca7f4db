"""GART: the paper's guided, RRT*-based planner (section 3.1, Algorithm 1, Fig. 6a).

Each iteration samples (:mod:`~companion.planning.sampling`: goal bias, uniform, informed),
moves the sample under the obstacles' and the goal's potential
(:mod:`~companion.planning.guidance`), then steers, chooses a parent, rewires and tries the goal
(:mod:`~companion.planning.search`). This module runs the iterations within the budgets and
finishes the best path: shortcut by :mod:`companion.planning.simplify` (optional, separate
step) and costed. Everything random comes from ``rng``: a fixed seed gives the same path. In the
common case (no threat or tracking cost; a world of balls, vertical cylinders and prisms) the
iterations run compiled (:mod:`~companion.planning.compiled_search`), and without K_max or climb
penalty so do the shortcut and the costing (:mod:`~companion.planning.shortcut_kernel`), with
the same results.
"""

from __future__ import annotations

import functools
import logging
import math
import time

import numpy as np

from companion.errors import PlanningError
from companion.numba_cache import compile_once
from companion.planning import hausdorff_kernel, iteration_kernel
from companion.planning.compiled_mgart import CompiledMgartSearch
from companion.planning.compiled_search import CompiledGart, compiled_case, grow_compiled
from companion.planning.cost import path_cost, path_length_m
from companion.planning.problem import failed_result, validate_problem
from companion.planning.result import PlanResult
from companion.planning.search import GartSearch
from companion.planning.settings import CostWeights, GartSettings
from companion.planning.shortcut_kernel import shortcut_and_cost, shortcut_case
from companion.planning.simplify import shortcut_path
from companion.world import Box, Disc, Prism, Sphere, World

__all__ = ["gart", "GartSearch", "validate_problem", "finish_path", "warm"]

log = logging.getLogger(__name__)

#: The planners' compile on a cold numba cache, measured on the 2-core reference machine (s).
PLANNERS_COMPILE_S = 20.0
#: The kernels whose cache says whether the planners' cache is cold (most of the compile).
PLANNER_PROBES = (iteration_kernel.grow_batch, hausdorff_kernel.separated_kernel)


def _tiny_worlds() -> tuple[World, ...]:
    """A world of each kind the kernels specialise on: discs (2D) and spheres (3D) on the
    compiled iteration, a prism (the polyhedral queries), a box (the Python iteration's kernels)."""
    lo2, hi2, lo3, hi3 = np.zeros(2), np.full(2, 10.0), np.zeros(3), np.full(3, 10.0)
    square = ((4.0, 4.0), (6.0, 4.0), (6.0, 6.0), (4.0, 6.0))
    return (
        World([Disc((5.0, 5.0), 1.5)], lo2, hi2),
        World([Sphere((5.0, 5.0, 5.0), 1.5)], lo3, hi3),
        World([Prism(square)], lo2, hi2),
        World([Box((4.0, 4.0), (6.0, 6.0))], lo2, hi2),
    )


def _first_calls() -> None:
    """Call every planning kernel once per argument type: tiny GART searches by iterations (no
    clock) on the compiled and the Python iteration (a threat cost, a box), their shortcut and
    cost, M-GART's compiled search and radius query, and its distinctness test."""
    plain, threat_cost = GartSettings(), GartSettings(cost=CostWeights(threat=1.0))  # compiled, Python
    for world in _tiny_worlds():
        start, goal = np.full(world.dim, 1.0), np.full(world.dim, 9.0)
        _plan(world, start, goal, rng=np.random.default_rng(0), max_iterations=300, settings=threat_cost)
        result = _plan(world, start, goal, rng=np.random.default_rng(0), max_iterations=300, settings=plain)
        if compiled_case(world, plain):
            search = CompiledMgartSearch(world, tuple(start), tuple(goal), plain, np.random.default_rng(0))
            search.iterate(True, 50)
            search.nn.within(tuple(start), 1.0)
        if result.path is not None:
            points = hausdorff_kernel.resample_points(
                np.ascontiguousarray(result.path, dtype=float), np.ones(result.path.shape[0] - 1, dtype=np.int64)
            )
            hausdorff_kernel.separated_kernel(points, points[::-1].copy(), 1.0)


@functools.cache
def warm() -> float:
    """Compile GART's and M-GART's kernels, or load them from numba's cache, once per process
    (before any budget's clock: :func:`gart` and :func:`~companion.planning.mgart.mgart` call
    it first). Logs ``compiling the planners (once, about N s)`` when the cache is cold.

    Returns
    -------
    float
        The seconds the first call took in this process (later calls return the same value at once).
    """
    return compile_once("the planners", _first_calls, PLANNER_PROBES, PLANNERS_COMPILE_S)


def finish_path(world: World, path: np.ndarray, settings: GartSettings) -> tuple[np.ndarray, float, float]:
    """Shortcut (if enabled) and cost a found path: (path, cost, length_m)."""
    if shortcut_case(world, settings):  # compiled, the same answer
        path, cost = shortcut_and_cost(world, path, settings)
        return path, cost, path_length_m(path)
    if settings.simplify.enabled and path.shape[0] > 2:
        path = shortcut_path(world, path, settings)
    return path, path_cost(world, path, settings.cost), path_length_m(path)


def gart(
    world: World,
    start,
    goal,
    *,
    rng: np.random.Generator,
    max_time_s: float | None = None,
    max_iterations: int | None = None,
    stop_at_first: bool = False,
    settings: GartSettings | None = None,
) -> PlanResult:
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

    Notes
    -----
    The first call in a process compiles the kernels (or loads them from numba's cache:
    :func:`warm`) before the budget's clock starts, so no budget pays for it.
    """
    warm()
    return _plan(
        world,
        start,
        goal,
        rng=rng,
        max_time_s=max_time_s,
        max_iterations=max_iterations,
        stop_at_first=stop_at_first,
        settings=settings,
    )


def _plan(
    world: World,
    start,
    goal,
    *,
    rng: np.random.Generator,
    max_time_s: float | None = None,
    max_iterations: int | None = None,
    stop_at_first: bool = False,
    settings: GartSettings | None = None,
) -> PlanResult:
    """:func:`gart` without the warm-up (the warm-up's own searches)."""
    t0 = time.perf_counter()
    settings = settings or GartSettings()
    if not isinstance(settings, GartSettings):
        raise PlanningError(f"settings: expected GartSettings, got {type(settings).__name__}")
    start_t, goal_t = validate_problem(world, start, goal, rng, max_time_s, max_iterations)
    if not world.point_free(start_t):
        return failed_result("invalid_start", t0)
    if not world.point_free(goal_t):
        return failed_result("invalid_goal", t0)
    if max_time_s is None and max_iterations is None:
        max_time_s = settings.time_budget_s
    deadline = t0 + max_time_s if max_time_s is not None else math.inf
    iter_limit = max_iterations if max_iterations is not None else math.inf
    search: CompiledGart | GartSearch
    if compiled_case(world, settings):  # the whole iteration compiled (numba), the tree in arrays
        search = CompiledGart(world, start_t, goal_t, settings, rng)
        history, first_s = grow_compiled(search, t0, deadline, iter_limit, stop_at_first)
        tree = search.tree_snapshot()
    else:
        search = GartSearch(world, start_t, goal_t, settings, rng)
        history, first_s = grow(search, t0, deadline, iter_limit, stop_at_first)
        tree = search.tree()
    if search.best_node < 0:
        return failed_result("timeout", t0, search.iterations, tree)
    path, cost, length = finish_path(world, search.path_to_goal(search.best_node), settings)
    return PlanResult(
        status="exact",
        path=path,
        cost=cost,
        length_m=length,
        iterations=search.iterations,
        elapsed_s=time.perf_counter() - t0,
        time_to_first_s=first_s,
        tree=tree,
        cost_history=tuple(history),
    )


def grow(
    search: GartSearch, t0: float, deadline: float, iter_limit: float, stop_at_first: bool
) -> tuple[list[tuple[float, float]], float | None]:
    """Iterate until a budget is spent (or the first path, with ``stop_at_first``).

    Returns the cost history ``[(t_s, best cost)]`` and the time of the first path (or None).
    """
    history: list[tuple[float, float]] = []
    first_s = None
    clock = time.perf_counter
    start_t, goal_t = search.start, search.goal
    if search.world.segment_free(start_t, goal_t):  # trivial problem: the straight line
        search.goal_links[0] = (
            search.ec.edge(start_t, goal_t, math.dist(start_t, goal_t)),
            None,
            math.dist(start_t, goal_t),
        )
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
                log.debug(
                    "gart: first path after %d iterations, %.1f ms, cost %.2f",
                    search.iterations,
                    1e3 * now,
                    search.best_cost,
                )
            history.append((now, search.best_cost))
    return history, first_s
