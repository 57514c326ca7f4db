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

import logging
import math
import time

import numpy as np

from companion.errors import PlanningError
from companion.planning.compiled_search import CompiledGart, compiled_case, grow_compiled
from companion.planning.cost import path_cost, path_length_m
from companion.planning.problem import failed_result, validate_problem
from companion.planning.result import PlanResult
from companion.planning.search import GartSearch
from companion.planning.settings import GartSettings
from companion.planning.shortcut_kernel import shortcut_and_cost, shortcut_case
from companion.planning.simplify import shortcut_path
from companion.world import World

__all__ = ["gart", "GartSearch", "validate_problem", "finish_path"]

log = logging.getLogger(__name__)


def finish_path(world: World, path: np.ndarray, settings: GartSettings) -> tuple[np.ndarray, float, float]:
    """Shortcut (if enabled) and cost a found path: (path, cost, length_m)."""
    if shortcut_case(world, settings):   # compiled, the same answer
        path, cost = shortcut_and_cost(world, path, settings)
        return path, cost, path_length_m(path)
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
        return failed_result("invalid_start", t0)
    if not world.point_free(goal_t):
        return failed_result("invalid_goal", t0)
    if max_time_s is None and max_iterations is None:
        max_time_s = settings.time_budget_s
    deadline = t0 + max_time_s if max_time_s is not None else math.inf
    iter_limit = max_iterations if max_iterations is not None else math.inf
    search: CompiledGart | GartSearch
    if compiled_case(world, settings):   # the whole iteration compiled (numba), the tree in arrays
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
    return PlanResult(status="exact", path=path, cost=cost, length_m=length, iterations=search.iterations,
                      elapsed_s=time.perf_counter() - t0, time_to_first_s=first_s, tree=tree,
                      cost_history=tuple(history))


def grow(search: GartSearch, t0: float, deadline: float, iter_limit: float,
         stop_at_first: bool) -> tuple[list[tuple[float, float]], float | None]:
    """Iterate until a budget is spent (or the first path, with ``stop_at_first``).

    Returns the cost history ``[(t_s, best cost)]`` and the time of the first path (or None).
    """
    history: list[tuple[float, float]] = []
    first_s = None
    clock = time.perf_counter
    start_t, goal_t = search.start, search.goal
    if search.world.segment_free(start_t, goal_t):  # trivial problem: the straight line
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
    return history, first_s
