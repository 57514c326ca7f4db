"""The planning problem's checks, shared by GART and M-GART: arguments, then the two ends.

Wrong arguments raise :class:`~companion.errors.PlanningError` naming the argument; an end inside
an inflated obstacle is an expected outcome and comes back as a failed :class:`PlanResult`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from companion.errors import PlanningError
from companion.planning.result import PlanResult, Status
from companion.world import World

__all__ = ["validate_problem", "failed_result"]


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
            raise PlanningError(
                f"{name}: {list(p)} is outside the world bounds "
                f"{world.bounds_min.tolist()}..{world.bounds_max.tolist()}"
            )
        points.append(p)
    if max_time_s is not None:
        if (
            isinstance(max_time_s, bool)
            or not isinstance(max_time_s, (int, float))
            or not math.isfinite(max_time_s)
            or max_time_s <= 0
        ):
            raise PlanningError(f"max_time_s: must be a positive number of seconds, got {max_time_s!r}")
    if max_iterations is not None:
        if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations <= 0:
            raise PlanningError(f"max_iterations: must be a positive integer, got {max_iterations!r}")
    return points[0], points[1]


def failed_result(status: Status, t0: float, iterations: int = 0, tree=None) -> PlanResult:
    """A result without a path: ``status`` ('timeout', 'invalid_start', 'invalid_goal')."""
    return PlanResult(
        status=status,
        path=None,
        cost=math.inf,
        length_m=math.inf,
        iterations=iterations,
        elapsed_s=time.perf_counter() - t0,
        time_to_first_s=None,
        tree=tree,
    )
