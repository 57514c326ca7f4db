"""One trajectory pipeline: plan -> smooth -> time -> check (STYLE: Nav2 and OMPL).

``TrajectoryPipeline`` composes the stages of ``companion.flight.stages`` (a planner, an
M-GART planner for alternatives, a smoother, a timer) and ``companion.flight.checker``, built from the typed
settings in one place (``from_settings``). Every trajectory the companion plans goes through
it: a mission leg (``companion.flight.plan``), a join onto a path and a replan
(``companion.threats.decision.join`` and ``candidates``), the alternatives
(``alternatives.plan_alternatives``); the escapes (``evasion``) are closed-form and take their
speed limit from it. So ``smoothing.method``, the limits and the closed-loop check take effect
everywhere.

The pipeline is immutable and picklable (it goes to the planning worker processes in the
decision's policy, ``companion.threats.decision.values.DecisionPolicy``). Numerics only: no I/O, no asyncio.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar, cast

import numpy as np

from companion.flight.checker import Checked, Checker, TrajectoryChecker, TrajectoryStatus
from companion.flight.stages import (
    SMOOTHERS,
    AlternativesPlanner,
    GartPlanner,
    MgartPlanner,
    PipelineError,
    PlanBudget,
    Planner,
    PlanningProblem,
    Smoother,
    SpeedProfileTimer,
    Timer,
)
from companion.planning import GartSettings, MgartSettings, PlanResult
from companion.smoothing import FeasibilitySettings, SmoothingSettings, TrajectoryLimits
from companion.world import World

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = ["TrajectoryPipeline", "PipelineError", "PlanningProblem", "PlanBudget", "TrajectoryStatus", "Checked"]


def planner_settings(smoothing: SmoothingSettings, planning: GartSettings) -> GartSettings:
    """The planner's settings: corners that fit the G2 smoother's K_max unless
    ``planning.kappa_max_1_m`` sets its own (G1 and polylines need no room at the corners)."""
    if planning.kappa_max_1_m is not None or smoothing.method != "g2":
        return planning
    return dataclasses.replace(planning, kappa_max_1_m=smoothing.kappa_max_1_m)


_P = TypeVar("_P")


def _with_budget(planner: _P, iterations_per_s: float | None) -> _P:
    """``planner`` with another ``iterations_per_s``.

    The planners of ``TrajectoryPipeline.from_settings`` (GartPlanner, MgartPlanner) are
    dataclasses with that field, which the Planner protocols do not say: hence the casts
    (``dataclasses.replace`` raises TypeError for another planner).
    """
    return cast(_P, dataclasses.replace(cast("DataclassInstance", planner), iterations_per_s=iterations_per_s))


@dataclass(frozen=True)
class TrajectoryPipeline:
    """Plan, smooth, time and check: the stages as members, one work method each.

    Attributes
    ----------
    planner : Planner
        GART.
    alternatives_planner : AlternativesPlanner
        M-GART.
    smoother : Smoother
    timer : Timer
    checker : Checker
    limits : TrajectoryLimits
        The vehicle's limits of every planned trajectory.
    """

    planner: Planner
    alternatives_planner: AlternativesPlanner
    smoother: Smoother
    timer: Timer
    checker: Checker
    limits: TrajectoryLimits

    @classmethod
    def from_settings(
        cls,
        smoothing: SmoothingSettings,
        planning: GartSettings | None = None,
        feasibility: FeasibilitySettings | None = None,
        *,
        closed_loop=None,
        iterations_per_s: float | None = None,
    ) -> TrajectoryPipeline:
        """The pipeline of the settings tree's ``smoothing``, ``planning`` and ``feasibility``.

        Parameters
        ----------
        smoothing : SmoothingSettings
            ``method`` picks the smoother; ``limits``, ``grid_step_m``, ``kappa_max_1_m`` and
            ``repair_max_halvings`` the rest.
        planning : GartSettings, optional
            GART's settings (K_max filled from ``smoothing`` for G2: ``planner_settings``).
        feasibility : FeasibilitySettings, optional
            With ``enabled`` and a ``closed_loop`` checker, every trajectory that may be
            stretched is checked on the closed loop (None: when a ``closed_loop`` is given).
        closed_loop : FeasibilityChecker-like, optional
            The closed-loop checker (its LQI is designed once per process; the daemon's
            ``CheckerHandle`` pickles as the worker's own).
        iterations_per_s : float, optional
            Search budgets in iterations instead of wall-clock seconds (``stages.iteration_budget``):
            the same paths on any machine, as the fast-time campaign needs.
        """
        if not isinstance(smoothing, SmoothingSettings):
            raise PipelineError(f"smoothing: expected SmoothingSettings, got {type(smoothing).__name__}")
        planning = GartSettings() if planning is None else planning
        if not isinstance(planning, GartSettings):
            raise PipelineError(f"planning: expected GartSettings, got {type(planning).__name__}")
        if feasibility is not None and not isinstance(feasibility, FeasibilitySettings):
            raise PipelineError(f"feasibility: expected FeasibilitySettings, got {type(feasibility).__name__}")
        use_closed_loop = closed_loop is not None and (feasibility is None or feasibility.enabled)
        gart_settings = planner_settings(smoothing, planning)
        method = SMOOTHERS[smoothing.method]
        smoother = (
            method() if smoothing.method == "none" else method(smoothing.kappa_max_1_m, smoothing.repair_max_halvings)
        )
        return cls(
            GartPlanner(gart_settings, iterations_per_s),
            MgartPlanner(MgartSettings(gart=gart_settings), iterations_per_s),
            smoother,
            SpeedProfileTimer(smoothing.grid_step_m),
            TrajectoryChecker(closed_loop if use_closed_loop else None),
            smoothing.limits,
        )

    @classmethod
    def for_limits(
        cls,
        limits: TrajectoryLimits | None = None,
        kappa_max_1_m: float = 0.1,
        gart_settings: GartSettings | None = None,
    ) -> TrajectoryPipeline:
        """``from_settings`` of a G2 smoothing tree with these limits and K_max (tests, benchmarks,
        and the decision policy's default)."""
        smoothing = SmoothingSettings(kappa_max_1_m=kappa_max_1_m, limits=limits or TrajectoryLimits())
        return cls.from_settings(smoothing, gart_settings or GartSettings(kappa_max_1_m=kappa_max_1_m))

    def with_iteration_budgets(self, iterations_per_s: float | None) -> TrajectoryPipeline:
        """This pipeline with its searches budgeted in iterations (see ``from_settings``)."""
        return dataclasses.replace(
            self,
            planner=_with_budget(self.planner, iterations_per_s),
            alternatives_planner=_with_budget(self.alternatives_planner, iterations_per_s),
        )

    @property
    def reproducible(self) -> bool:
        """Budgets in iterations, not wall-clock seconds: the same trajectories on any machine
        (callers then leave their own wall-clock cut-offs out too)."""
        return getattr(self.planner, "iterations_per_s", None) is not None

    def search_time_s(self, result: PlanResult) -> float:
        """The time ``result``'s searches took on their budget's clock: wall-clock seconds, or
        their iterations at the planner's ``iterations_per_s`` (reproducible)."""
        iterations_per_s = getattr(self.planner, "iterations_per_s", None)  # (as reproducible reads it)
        return result.iterations / iterations_per_s if iterations_per_s is not None else result.elapsed_s

    # ------------------------------------------------------------------ the stages
    def plan(self, problem: PlanningProblem, budget: PlanBudget, *, rng: np.random.Generator) -> PlanResult:
        """Stage 1: a path (``PlanResult.status`` says whether there is one)."""
        return self.planner.plan(problem, budget, rng=rng)

    def alternatives(
        self, problem: PlanningProblem, budget: PlanBudget, k: int, *, rng: np.random.Generator
    ) -> list[PlanResult]:
        """Stage 1 for switching targets: up to ``k`` distinct paths (M-GART)."""
        return self.alternatives_planner.plan(problem, budget, k, rng=rng)

    @property
    def turn_kappa_1_m(self) -> float:
        """Curvature that bounds the speed through a corner (inf: the smoother stops there)."""
        return self.smoother.turn_kappa_1_m

    def trajectory(
        self,
        path,
        world: World | None,
        *,
        limits: TrajectoryLimits | None = None,
        start_speed_m_s: float = 0.0,
        yaw_mode: str = "tangent",
        yaw_hold_rad: float | None = None,
    ) -> Checked:
        """Stages 2-4 on a collision-free polyline: smooth (repaired in ``world``), time, check.

        Parameters
        ----------
        path : array_like, shape (M, d)
        world : World or None
            Static obstacles (the planning dimension): corners are repaired and the curve is
            checked; None: neither.
        limits : TrajectoryLimits, optional
            Default: the pipeline's.
        start_speed_m_s : float
            Speed along the first segment at t = 0 (a splice); the closed loop may stretch the
            timing only of a trajectory that starts at rest.

        Returns
        -------
        Checked
        """
        path = np.asarray(path, dtype=float)
        if path.ndim != 2 or path.shape[0] < 2:
            raise PipelineError(f"path: expected an (M, d) polyline with M >= 2, got shape {path.shape}")
        curve = self.smoother.smooth(path, world)
        timed = self.timer.time(
            curve, limits or self.limits, start_speed_m_s=start_speed_m_s, yaw_mode=yaw_mode, yaw_hold_rad=yaw_hold_rad
        )
        return self.checker.check(timed, world, stretch=start_speed_m_s == 0.0)
