"""The mission's legs flown one after the other, each by the pure phase machine (DESIGN 7.4, 10).

``LegRunner.step`` is a task of the executor's schedule: it observes the vehicle and the active
reference (``LegObservation``), steps ``companion.flight.phases.leg_step`` and acts on the
action: the next leg when this one is reached (after the waypoint's hold time), a plan back to
the mission when the reference ended short of the goal (the threat decision's way back, or a
replan from the vehicle without threats), a replan of the leg from where the vehicle is when
the link came back, and the end of the flight when the vehicle left GUIDED, disarmed or timed
out. Slow work (a replan) is a job; the phase machine waits for it without stopping the ticks.

No asyncio and no I/O.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import logging
import math
from collections.abc import Callable, Sequence

import numpy as np

from companion.flight.active import ReferenceOwner
from companion.flight.phases import ActionKind, LegObservation, LegState, leg_step
from companion.flight.plan import plan_leg
from companion.flight.ports import FlightSink, Jobs, VehiclePort
from companion.threats.decision.step import LegContext

__all__ = ["LegRunner", "FlightOutcome", "LegReplanner"]

log = logging.getLogger(__name__)


class FlightOutcome(enum.Enum):
    """Where the legs stand."""

    FLYING = "flying"
    COMPLETED = "completed"  # every leg reached
    ABORTED = "aborted"  # ``LegRunner.reason`` says why


@dataclasses.dataclass(frozen=True)
class LegReplanner:
    """How a leg is planned again from a point: ``fn(leg, start_ned_m, seed)`` returns a new
    ``LegPlan`` (or None: nothing left to fly); run as a job, so ``fn`` pickles (a module-level
    function, or a ``functools.partial`` of one)."""

    fn: Callable

    @classmethod
    def in_world(cls, world, pipeline, flight) -> LegReplanner:
        """Replans in ``world`` (the mission's) through ``pipeline`` (the legs' trajectory
        pipeline) with the ``flight`` planning settings."""
        return cls(functools.partial(replan_from, world=world, pipeline=pipeline, flight=flight))


def replan_from(leg, start_ned_m, seed: int, *, world, pipeline, flight):
    """``leg`` planned again from ``start_ned_m`` (``companion.flight.plan.plan_leg``), its
    randomness from ``seed``."""
    return plan_leg(
        leg.index, leg.waypoint, start_ned_m, world, pipeline=pipeline, settings=flight, rng=np.random.default_rng(seed)
    )


class LegRunner:
    """Flies ``legs`` (see the module docstring).

    Parameters
    ----------
    legs : sequence of LegPlan
    owner : ReferenceOwner
    vehicle : VehiclePort
    jobs : Jobs
    sink : FlightSink
    now_s : callable () -> float
        Mission time now.
    replanner : LegReplanner
    timeout_margin_s : float
        Time after a reference's end to reach the goal before the flight is aborted.
    avoidance : Avoidance, optional
        The threat decisions (told of each leg; asked for a way back).
    leg_started : callable (LegPlan), optional
        Told when a leg starts (the daemon makes its goal the vehicle's current mission item).
    seed : int
        Seeds of the replans (each replan ``seed + its number``).
    """

    def __init__(
        self,
        legs: Sequence,
        *,
        owner: ReferenceOwner,
        vehicle: VehiclePort,
        jobs: Jobs,
        sink: FlightSink,
        now_s: Callable[[], float],
        replanner: LegReplanner,
        timeout_margin_s: float,
        avoidance=None,
        leg_started: Callable | None = None,
        seed: int = 0,
    ) -> None:
        self.legs = list(legs)
        self.owner = owner
        self.vehicle = vehicle
        self.jobs = jobs
        self.sink = sink
        self.now_s = now_s
        self.replanner = replanner
        self.timeout_margin_s = float(timeout_margin_s)
        self.avoidance = avoidance
        self.leg_started = leg_started
        self.seed = int(seed)
        self.index = -1
        self.state = LegState()
        self.outcome = FlightOutcome.FLYING
        self.reason = ""
        self.reached = 0
        self.relink_pending = False
        self._waiting = False  # a replan or a way back is being worked out
        self._hold_until_s: float | None = None
        self._replans = 0

    @property
    def leg(self):
        return self.legs[self.index] if 0 <= self.index < len(self.legs) else None

    @property
    def done(self) -> bool:
        return self.outcome is not FlightOutcome.FLYING

    def start(self) -> None:
        """Engage the first leg (the vehicle hovers where the legs start)."""
        self._start_leg(0)

    # ------------------------------------------------------------------ the phase task
    def step(self, now_mono_s: float) -> None:
        """The schedule's phase task: observe, step the phase machine, act."""
        if self.done or self._waiting:
            return
        t = self.now_s()
        if self._hold_until_s is not None:
            if t >= self._hold_until_s:
                self._next_leg()
            return
        leg = self.leg
        self.state, action = leg_step(self.state, self.observe(leg, t))
        if action.kind is ActionKind.ABORT:
            self._end(FlightOutcome.ABORTED, action.reason)
        elif action.kind is ActionKind.REACHED:
            self._reached(leg, t)
        elif action.kind is ActionKind.REPLAN:
            self.relink_pending = False
            self._replan(leg)
        elif action.kind is ActionKind.RESUME:
            self._continue(leg, action.reason)

    def observe(self, leg, t_s: float) -> LegObservation:
        """What the phase machine sees now."""
        view, ref = self.vehicle.view(), self.owner.current
        radius = leg.waypoint.acceptance_radius_m
        return LegObservation(
            t_s=t_s,
            seq=leg.waypoint.seq,
            connected=view.connected,
            armed=view.armed,
            guided=view.guided,
            mode_name=view.mode_name,
            relink_pending=self.relink_pending,
            dist_to_goal_m=math.inf
            if view.pos_ned_m is None
            else math.dist(view.pos_ned_m.tolist(), leg.goal_ned_m.tolist()),
            acceptance_radius_m=radius,
            ref_end_t_s=None if ref is None else ref.t_end_s,
            ref_ends_short=ref is not None and ref.end_gap_m(leg.goal_ned_m) > radius,
            ref_resume=ref is not None and ref.resume,
            timeout_margin_s=self.timeout_margin_s,
        )

    def on_link_back(self, pos_ned_m) -> None:
        """The link came back after a loss: hold where the vehicle is, then replan the leg."""
        if self.done or self.owner.current is None or pos_ned_m is None:
            return
        self.owner.hold(pos_ned_m)
        self.sink.event("hold", reason="link back: hold, then replan the leg", pos_ned_m=np.asarray(pos_ned_m))
        self.relink_pending = True

    # ------------------------------------------------------------------ legs
    def _start_leg(self, index: int) -> None:
        self.index, self.state, self._hold_until_s = index, LegState(), None
        leg = self.leg
        if self.leg_started is not None:
            self.leg_started(leg)
        self.owner.engage(leg.trajectory, f"leg{leg.index}", turn=True)
        self.sink.event("leg_started", leg=leg.index, seq=leg.waypoint.seq)
        if self.avoidance is not None:
            self.avoidance.start_leg(LegContext(leg.index, leg.world, leg.goal_ned_m))

    def _reached(self, leg, t_s: float) -> None:
        if self.avoidance is not None:
            self.avoidance.end_leg()
        self.reached += 1
        pos = self.vehicle.view().pos_ned_m
        self.sink.event(
            "reached",
            leg=leg.index,
            seq=leg.waypoint.seq,
            error_m=None if pos is None else round(float(np.linalg.norm(pos - leg.goal_ned_m)), 3),
        )
        self._hold_until_s = t_s + max(leg.waypoint.hold_s, 0.0)
        if leg.waypoint.hold_s <= 0:
            self._next_leg()

    def _next_leg(self) -> None:
        if self.index + 1 < len(self.legs):
            self._start_leg(self.index + 1)
        else:
            self._end(FlightOutcome.COMPLETED, "")

    def _end(self, outcome: FlightOutcome, reason: str) -> None:
        self.outcome, self.reason = outcome, reason
        if self.avoidance is not None:
            self.avoidance.end_leg()
        if outcome is FlightOutcome.ABORTED:
            log.error("flight aborted: %s", reason)

    # ------------------------------------------------------------------ replans and ways back
    def _replan(self, leg) -> None:
        """Plan the rest of ``leg`` from where the vehicle is (a job)."""
        pos = self.vehicle.view().pos_ned_m
        if pos is None:
            return
        self._waiting = True
        self._replans += 1
        self.jobs.submit(
            "replan",
            self.replanner.fn,
            (leg, pos, self.seed + self._replans),
            done=functools.partial(self._replanned, leg, pos),
            failed=self._replan_failed,
        )

    def _replanned(self, leg, pos, new) -> None:
        self._waiting = False
        if leg is not self.leg or self.done:
            return
        if new is not None:
            self.owner.engage(new.trajectory, f"leg{leg.index}-resume", turn=True)
        checked = (
            None
            if new is None or new.feasibility is None
            else {k: v for k, v in new.feasibility.items() if k != "pieces"}
        )
        self.sink.event("resumed", leg=leg.index, from_ned_m=pos, feasibility=checked)

    def _replan_failed(self, error: BaseException) -> None:
        self._waiting = False
        self._end(FlightOutcome.ABORTED, f"the leg could not be planned again: {error}")

    def _continue(self, leg, reason: str) -> None:
        """Plan back to the leg's goal from a reference that ended short of it."""
        if self.avoidance is None:
            self.sink.event("continue", leg=leg.index, reason=reason)
            self._replan(leg)
            return
        self._waiting = True
        self.avoidance.request_resume(functools.partial(self._way_back, leg, reason))

    def _way_back(self, leg, reason: str, decision) -> None:
        self._waiting = False
        if decision is not None and decision.trajectory is not None:
            self.sink.event(
                "continue", leg=leg.index, reason=reason, decision=decision.kind.value, path_id=decision.path_id
            )
        else:
            log.info(
                "leg %d: no clear way back to the mission yet (%s)",
                leg.index,
                "no decision" if decision is None else decision.reason,
            )
