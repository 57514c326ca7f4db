"""The stages of the trajectory pipeline, one work method each (Nav2's ``nav2_core``, OMPL).

- ``Planner.plan(problem, budget, rng=...) -> PlanResult``: GART (``GartPlanner``); M-GART's
  ``AlternativesPlanner.plan(problem, budget, k, rng=...) -> [PlanResult]`` (``MgartPlanner``).
  A planner never owns the world: it comes with the ``PlanningProblem`` (OMPL's
  ``SpaceInformation`` and ``ProblemDefinition`` in one), and the outcome is the planner's own
  status value (``PlanResult.status``).
- ``Smoother.smooth(path, world=None) -> curve``: ``G2Smoother`` (curvature bounded by K_max),
  ``G1Smoother`` (quartic midpoint interpolation) or ``PolylineSmoother`` (``none``: the
  polyline itself, stopping at every corner); each repairs its corners against ``world``.
- ``Timer.time(curve, limits, start_speed_m_s=...) -> Trajectory``: the speed profile
  (``companion.smoothing.timing``), ``SpeedProfileTimer``.
- the check stage (``Checker``, ``TrajectoryChecker``) is in ``companion.flight.checker``.

Every stage is a frozen dataclass of settings (picklable: the pipeline goes to planning
processes). Numerics only: no I/O.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from companion.errors import CompanionError
from companion.flight.trajectory import Trajectory
from companion.planning import GartSettings, MgartSettings, PlanResult, gart, mgart
from companion.smoothing import TrajectoryLimits, smooth_g1, smooth_g2, time_parameterize
from companion.world import World

__all__ = [
    "PipelineError",
    "PlanningProblem",
    "PlanBudget",
    "Planner",
    "AlternativesPlanner",
    "Smoother",
    "Timer",
    "GartPlanner",
    "MgartPlanner",
    "G2Smoother",
    "G1Smoother",
    "PolylineSmoother",
    "SpeedProfileTimer",
    "SMOOTHERS",
]

log = logging.getLogger(__name__)


class PipelineError(CompanionError, ValueError):
    """Wrong input to a pipeline stage (the message names the argument)."""


@dataclass(frozen=True)
class PlanningProblem:
    """What to plan: the world (its validity checker) and the two ends.

    Attributes
    ----------
    world : World
    start, goal : ndarray, shape (d,)
    """

    world: World
    start: np.ndarray
    goal: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.world, World):
            raise PipelineError(f"world: expected a companion.world.World, got {type(self.world).__name__}")
        for name in ("start", "goal"):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (self.world.dim,):
                raise PipelineError(f"{name}: expected {self.world.dim} numbers, got shape {value.shape}")
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class PlanBudget:
    """How long a planner may search (OMPL's termination condition).

    Attributes
    ----------
    max_time_s : float
        Wall-clock budget of the first search (s).
    attempts : int
        A search that times out is tried again with twice the budget, this many searches in all.
    first_path_s : float or None
        After every attempt timed out, one last search of this budget that stops at its first
        path (a replan would rather fly a first path than none).
    """

    max_time_s: float
    attempts: int = 1
    first_path_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("max_time_s", "first_path_s"):
            value = getattr(self, name)
            if value is None and name == "first_path_s":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise PipelineError(f"{name}: must be a finite number of seconds > 0, got {value!r}")
        if isinstance(self.attempts, bool) or not isinstance(self.attempts, int) or self.attempts < 1:
            raise PipelineError(f"attempts: must be an integer >= 1, got {self.attempts!r}")

    @property
    def total_s(self) -> float:
        """Longest time the budget allows (s)."""
        return self.max_time_s * (2**self.attempts - 1) + (self.first_path_s or 0.0)


class Planner(Protocol):
    def plan(self, problem: PlanningProblem, budget: PlanBudget, *, rng: np.random.Generator) -> PlanResult: ...


class AlternativesPlanner(Protocol):
    def plan(
        self, problem: PlanningProblem, budget: PlanBudget, k: int, *, rng: np.random.Generator
    ) -> list[PlanResult]: ...


class Smoother(Protocol):
    #: Curvature (1/m) that bounds the speed through a corner (inf: the vehicle stops there).
    turn_kappa_1_m: float

    def smooth(self, path: np.ndarray, world: World | None = None): ...


class Timer(Protocol):
    def time(
        self,
        curve,
        limits: TrajectoryLimits,
        *,
        start_speed_m_s: float = 0.0,
        yaw_mode: str = "tangent",
        yaw_hold_rad: float | None = None,
    ) -> Trajectory: ...


# ---------------------------------------------------------------------------- planners
def iteration_budget(seconds: float, iterations_per_s: float | None) -> dict:
    """The search budget of ``seconds``: wall-clock, or with ``iterations_per_s`` that many
    iterations a second and no clock (a search whose result does not depend on the machine)."""
    if iterations_per_s is None:
        return {"max_time_s": seconds}
    return {"max_iterations": max(1, math.ceil(seconds * iterations_per_s))}


@dataclass(frozen=True)
class GartPlanner:
    """GART (paper section 3.1) in a ``PlanBudget``.

    ``iterations_per_s`` (optional) turns the budget's seconds into iterations
    (``iteration_budget``): the fast-time campaign's reproducible searches.
    """

    settings: GartSettings = GartSettings()
    iterations_per_s: float | None = None

    def plan(self, problem: PlanningProblem, budget: PlanBudget, *, rng: np.random.Generator) -> PlanResult:
        """The last search's result, with the ``iterations`` and ``elapsed_s`` of all of them."""
        budget_s = budget.max_time_s
        iterations, elapsed_s = 0, 0.0
        for attempt in range(budget.attempts):
            result = gart(
                problem.world,
                problem.start,
                problem.goal,
                rng=rng,
                settings=self.settings,
                **iteration_budget(budget_s, self.iterations_per_s),
            )
            iterations, elapsed_s = iterations + result.iterations, elapsed_s + result.elapsed_s
            if result.status != "timeout":
                return dataclasses.replace(result, iterations=iterations, elapsed_s=elapsed_s)
            if attempt + 1 < budget.attempts:
                log.info(
                    "no path in %.2f s (attempt %d); searching again for %.2f s", budget_s, attempt + 1, 2 * budget_s
                )
            budget_s *= 2
        if budget.first_path_s is not None:
            result = gart(
                problem.world,
                problem.start,
                problem.goal,
                rng=rng,
                stop_at_first=True,
                settings=self.settings,
                **iteration_budget(budget.first_path_s, self.iterations_per_s),
            )
            iterations, elapsed_s = iterations + result.iterations, elapsed_s + result.elapsed_s
        return dataclasses.replace(result, iterations=iterations, elapsed_s=elapsed_s)


@dataclass(frozen=True)
class MgartPlanner:
    """M-GART (paper section 3.3): up to ``k`` distinct paths, cheapest first (``iterations_per_s``
    as ``GartPlanner``'s)."""

    settings: MgartSettings = MgartSettings()
    iterations_per_s: float | None = None

    def plan(
        self, problem: PlanningProblem, budget: PlanBudget, k: int, *, rng: np.random.Generator
    ) -> list[PlanResult]:
        return mgart(
            problem.world,
            problem.start,
            problem.goal,
            k,
            rng=rng,
            settings=self.settings,
            **iteration_budget(budget.max_time_s, self.iterations_per_s),
        )


# ---------------------------------------------------------------------------- smoothers
@dataclass(frozen=True)
class G2Smoother:
    """Cubic Bezier spiral pairs, curvature-continuous and bounded by K_max (``smooth_g2``)."""

    kappa_max_1_m: float = 0.1
    max_halvings: int = 12

    @property
    def turn_kappa_1_m(self) -> float:
        return self.kappa_max_1_m

    def smooth(self, path: np.ndarray, world: World | None = None):
        return smooth_g2(path, self.kappa_max_1_m, world=world, max_halvings=self.max_halvings)


@dataclass(frozen=True)
class G1Smoother:
    """Quartic midpoint interpolation, tangent-continuous (``smooth_g1``); its curvature is not
    bounded, ``kappa_max_1_m`` only sizes the leads of joins."""

    kappa_max_1_m: float = 0.1
    max_halvings: int = 12

    @property
    def turn_kappa_1_m(self) -> float:
        return self.kappa_max_1_m

    def smooth(self, path: np.ndarray, world: World | None = None):
        return smooth_g1(path, world=world, max_halvings=self.max_halvings)


@dataclass(frozen=True)
class PolylineSmoother:
    """``none``: the polyline itself; the timing stops the vehicle at every corner."""

    turn_kappa_1_m: float = math.inf

    def smooth(self, path: np.ndarray, world: World | None = None):
        return np.asarray(path, dtype=float)


#: The smoother of each ``smoothing.method``.
SMOOTHERS = {"g2": G2Smoother, "g1": G1Smoother, "none": PolylineSmoother}


# ---------------------------------------------------------------------------- timer
@dataclass(frozen=True)
class SpeedProfileTimer:
    """The speed profile under speed, acceleration, lateral-acceleration and jerk limits."""

    grid_step_m: float = 1.0

    def time(
        self,
        curve,
        limits: TrajectoryLimits,
        *,
        start_speed_m_s: float = 0.0,
        yaw_mode: str = "tangent",
        yaw_hold_rad: float | None = None,
    ) -> Trajectory:
        trajectory = time_parameterize(
            curve,
            limits,
            start_speed_m_s=start_speed_m_s,
            grid_step_m=self.grid_step_m,
            yaw_mode=yaw_mode,
            yaw_hold_rad=yaw_hold_rad,
        )
        trajectory.notes[:0] = list(getattr(curve, "notes", []))
        return trajectory
