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
- ``Checker.check(trajectory, world=None, stretch=...) -> Checked``: the static-world validity of
  the curve (its straight pieces exactly, its corners sampled, against the inflated obstacles) and, when a closed-loop checker is given
  (``companion.smoothing.feasibility.FeasibilityChecker``), the helicopter model flying it;
  the outcome is a ``TrajectoryStatus`` value.

Every stage is a frozen dataclass of settings (picklable: the pipeline goes to planning
processes). Numerics only: no I/O.
"""

from __future__ import annotations

import enum
import logging
import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from companion.errors import CompanionError
from companion.flight.trajectory import Trajectory
from companion.planning import GartSettings, MgartSettings, PlanResult, gart, mgart
from companion.smoothing import TrajectoryLimits, smooth_g1, smooth_g2, time_parameterize
from companion.smoothing.bezier_maths import bernstein
from companion.world import World

__all__ = ["PipelineError", "PlanningProblem", "PlanBudget", "Planner", "AlternativesPlanner", "Smoother",
           "Timer", "Checker", "TrajectoryStatus", "Checked", "GartPlanner", "MgartPlanner", "G2Smoother",
           "G1Smoother", "PolylineSmoother", "SpeedProfileTimer", "TrajectoryChecker", "SMOOTHERS"]

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
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise PipelineError(f"{name}: must be a finite number of seconds > 0, got {value!r}")
        if isinstance(self.attempts, bool) or not isinstance(self.attempts, int) or self.attempts < 1:
            raise PipelineError(f"attempts: must be an integer >= 1, got {self.attempts!r}")

    @property
    def total_s(self) -> float:
        """Longest time the budget allows (s)."""
        return self.max_time_s * (2 ** self.attempts - 1) + (self.first_path_s or 0.0)


class TrajectoryStatus(enum.Enum):
    """Outcome of the check stage (an expected outcome: a value, never an exception)."""

    #: The trajectory is valid as timed.
    VALID = "valid"
    #: Valid once its durations were stretched (closed loop): the stretched one is returned.
    STRETCHED = "stretched"
    #: The closed loop cannot fly it within the limits (even stretched, where allowed).
    INFEASIBLE = "infeasible"
    #: The curve enters an inflated static obstacle or leaves the world's bounds.
    BLOCKED = "blocked"

    @property
    def flyable(self) -> bool:
        return self in (TrajectoryStatus.VALID, TrajectoryStatus.STRETCHED)


@dataclass(frozen=True)
class Checked:
    """A checked trajectory.

    Attributes
    ----------
    status : TrajectoryStatus
    trajectory : Trajectory
        The one to fly (stretched when ``status`` is STRETCHED).
    report : FeasibilityReport or None
        The closed-loop figures (None without a closed-loop check).
    reason : str
        Why it is not VALID ('' when it is).
    """

    status: TrajectoryStatus
    trajectory: Trajectory
    report: object = None
    reason: str = ""


class Planner(Protocol):
    def plan(self, problem: PlanningProblem, budget: PlanBudget, *, rng: np.random.Generator) -> PlanResult: ...


class AlternativesPlanner(Protocol):
    def plan(self, problem: PlanningProblem, budget: PlanBudget, k: int, *,
             rng: np.random.Generator) -> list[PlanResult]: ...


class Smoother(Protocol):
    #: Curvature (1/m) that bounds the speed through a corner (inf: the vehicle stops there).
    turn_kappa_1_m: float

    def smooth(self, path: np.ndarray, world: World | None = None): ...


class Timer(Protocol):
    def time(self, curve, limits: TrajectoryLimits, *, start_speed_m_s: float = 0.0, yaw_mode: str = "tangent",
             yaw_hold_rad: float | None = None) -> Trajectory: ...


class Checker(Protocol):
    def check(self, trajectory: Trajectory, world: World | None = None, *, stretch: bool = True) -> Checked: ...


# ---------------------------------------------------------------------------- planners
@dataclass(frozen=True)
class GartPlanner:
    """GART (paper section 3.1) in a ``PlanBudget``."""

    settings: GartSettings = GartSettings()

    def plan(self, problem: PlanningProblem, budget: PlanBudget, *, rng: np.random.Generator) -> PlanResult:
        budget_s = budget.max_time_s
        for attempt in range(budget.attempts):
            result = gart(problem.world, problem.start, problem.goal, rng=rng, max_time_s=budget_s,
                          settings=self.settings)
            if result.status != "timeout":
                return result
            if attempt + 1 < budget.attempts:
                log.info("no path in %.2f s (attempt %d); searching again for %.2f s", budget_s, attempt + 1,
                         2 * budget_s)
            budget_s *= 2
        if budget.first_path_s is not None:
            result = gart(problem.world, problem.start, problem.goal, rng=rng, max_time_s=budget.first_path_s,
                          stop_at_first=True, settings=self.settings)
        return result


@dataclass(frozen=True)
class MgartPlanner:
    """M-GART (paper section 3.3): up to ``k`` distinct paths, cheapest first."""

    settings: MgartSettings = MgartSettings()

    def plan(self, problem: PlanningProblem, budget: PlanBudget, k: int, *,
             rng: np.random.Generator) -> list[PlanResult]:
        return mgart(problem.world, problem.start, problem.goal, k, rng=rng, max_time_s=budget.max_time_s,
                     settings=self.settings)


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

    def time(self, curve, limits: TrajectoryLimits, *, start_speed_m_s: float = 0.0, yaw_mode: str = "tangent",
             yaw_hold_rad: float | None = None) -> Trajectory:
        trajectory = time_parameterize(curve, limits, start_speed_m_s=start_speed_m_s, grid_step_m=self.grid_step_m,
                                       yaw_mode=yaw_mode, yaw_hold_rad=yaw_hold_rad)
        trajectory.notes[:0] = list(getattr(curve, "notes", []))
        return trajectory


# ---------------------------------------------------------------------------- checker
@dataclass(frozen=True)
class TrajectoryChecker:
    """Static-world validity and, with ``closed_loop``, the closed-loop feasibility check.

    Attributes
    ----------
    closed_loop : FeasibilityChecker-like or None
        ``check(trajectory)`` and ``check_and_stretch(trajectory)`` -> ``FeasibilityReport``.
    tolerance_m : float
        Clearance below zero still accepted (m): the rounding of a path that grazes the margin.
    """

    closed_loop: object = field(default=None, compare=False)
    tolerance_m: float = 1e-6

    def check(self, trajectory: Trajectory, world: World | None = None, *, stretch: bool = True) -> Checked:
        """Check ``trajectory`` (t = 0 at its start) in ``world`` (the planning dimension).

        ``stretch``: the closed loop may slow down a trajectory it cannot fly (only one that
        starts at rest: a stretched splice would no longer start at the current speed).
        """
        if not isinstance(trajectory, Trajectory):
            raise PipelineError(f"trajectory: expected a Trajectory, got {type(trajectory).__name__}")
        if world is not None:
            reason = self.static_reason(trajectory, world)
            if reason:
                return Checked(TrajectoryStatus.BLOCKED, trajectory, reason=reason)
        if self.closed_loop is None:
            return Checked(TrajectoryStatus.VALID, trajectory)
        report = self.closed_loop.check_and_stretch(trajectory) if stretch else self.closed_loop.check(trajectory)
        flown = report.trajectory
        if report.stretch > 1.0:
            flown.notes.append(f"feasibility: timing stretched x{report.stretch:.3g} ({trajectory.duration_s:.1f} s "
                               f"-> {flown.duration_s:.1f} s; first timing: max |delta| "
                               f"{report.initial_max_abs_delta:.2f}, tracking error "
                               f"{report.initial_max_tracking_error_m:.2f} m)")
        if not report.feasible:
            flown.notes.append(f"feasibility: still infeasible: {report.reason}")
            return Checked(TrajectoryStatus.INFEASIBLE, flown, report, report.reason)
        status = TrajectoryStatus.STRETCHED if report.stretch > 1.0 else TrajectoryStatus.VALID
        return Checked(status, flown, report)

    def static_reason(self, trajectory: Trajectory, world: World) -> str:
        """Why the curve of ``trajectory`` is not free in ``world`` ('' when it is).

        Straight pieces are checked exactly (``World.segment_free``); curved pieces (the
        corners) at ``CORNER_SAMPLES`` points each, against the inflated obstacles and the bounds.
        """
        curve = trajectory.curve
        if curve.d != world.dim:
            raise PipelineError(f"world: a {world.dim}D world for a {curve.d}D trajectory")
        corners = []
        for piece in curve.pieces:
            if piece.shape[0] == 2:
                if not world.segment_free(piece[0], piece[1]):
                    return f"a straight piece from {piece[0].round(2).tolist()} crosses a static obstacle"
            else:
                corners.append(bernstein(piece.shape[0] - 1, _CORNER_U) @ piece)
        if not corners:
            return ""
        pts = np.vstack(corners)
        span = np.maximum(np.abs(world.bounds_min), np.abs(world.bounds_max))
        if not np.all((pts >= world.bounds_min - 1e-9 * span) & (pts <= world.bounds_max + 1e-9 * span)):
            return "a corner leaves the world's bounds"
        clearance = world.clearance_m(pts)
        if np.min(clearance) < -self.tolerance_m:
            k = int(np.argmin(clearance))
            return f"a corner enters a static obstacle ({-clearance[k]:.2f} m deep at {pts[k].round(2).tolist()})"
        return ""


#: Bezier parameters at which the check samples each corner piece.
CORNER_SAMPLES = 17
_CORNER_U = np.linspace(0.0, 1.0, CORNER_SAMPLES)
