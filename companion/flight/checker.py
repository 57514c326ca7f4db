"""The check stage of the trajectory pipeline: ``Checker.check(trajectory, world, stretch=...)``.

``TrajectoryChecker`` checks the static-world validity of the curve (its straight pieces
exactly, its corners sampled, against the inflated obstacles and the bounds) and, when a
closed-loop checker is given (``companion.smoothing.feasibility.FeasibilityChecker``), the
helicopter model flying it, stretching the timing of a trajectory that starts at rest until it
is feasible. The outcome is a ``TrajectoryStatus`` value in a ``Checked``, never an exception.

Numerics only: no I/O.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from companion.flight.stages import PipelineError
from companion.flight.trajectory import Trajectory
from companion.smoothing.bezier_maths import bernstein
from companion.world import World

if TYPE_CHECKING:
    from companion.smoothing.feasibility import FeasibilityReport

__all__ = ["TrajectoryStatus", "Checked", "Checker", "TrajectoryChecker", "CORNER_SAMPLES"]


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
    report: FeasibilityReport | None = None
    reason: str = ""


class Checker(Protocol):
    def check(self, trajectory: Trajectory, world: World | None = None, *, stretch: bool = True) -> Checked: ...


class ClosedLoopCheck(Protocol):
    """The closed-loop check (a :class:`~companion.smoothing.feasibility.FeasibilityChecker`)."""

    def check(self, trajectory: Trajectory) -> FeasibilityReport: ...

    def check_and_stretch(self, trajectory: Trajectory) -> FeasibilityReport: ...


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

    closed_loop: ClosedLoopCheck | None = field(default=None, compare=False)
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
            flown.notes.append(
                f"feasibility: timing stretched x{report.stretch:.3g} ({trajectory.duration_s:.1f} s "
                f"-> {flown.duration_s:.1f} s; first timing: max |delta| "
                f"{report.initial_max_abs_delta:.2f}, tracking error "
                f"{report.initial_max_tracking_error_m:.2f} m)"
            )
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
