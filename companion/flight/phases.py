"""Flight phases of one leg as a small, pure state machine (DESIGN sections 7.4 and 10).

``CompanionDaemon.fly_leg`` is a thin loop around :func:`leg_step`: it observes the vehicle and
the active reference (:class:`LegObservation`), calls ``leg_step(state, observation)`` and acts
on the returned :class:`LegAction`. Nothing here does I/O or reads a clock, so every transition
is unit-tested without a vehicle (``tests/unit/test_phases.py``).

Phases (:class:`LegPhase`) and what moves between them, checked in this order:

1. the link is up and the vehicle disarmed, or left GUIDED (a pilot or the autopilot took
   over): ``ABORTED``, action ``ABORT`` (the companion stops commanding). While the link is down
   nothing is decided from the stale mode: the reference keeps streaming;
2. the link came back (``relink_pending``, the daemon already holds where the vehicle is):
   action ``REPLAN``, the rest of the leg is planned from where the vehicle is;
3. no active reference, or it has not ended: ``FOLLOWING``, ``KEEP``;
4. the reference has ended and the vehicle is within the acceptance radius of the goal:
   ``REACHED``;
5. the reference ended short of the goal (an evasion or a hold ends in a hover):
   ``STOPPED_SHORT``. Action ``RESUME`` (plan back to the leg's goal) as soon as it has ended
   when its decision asked for it (``ref_resume``), otherwise ``resume_after_s`` after its end;
   then again no sooner than ``resume_retry_s`` after the previous request while no way back is
   found. A reference that stops short never times out: the vehicle hovers clear of the threat;
6. the reference ended at the goal but the vehicle is not there: ``ARRIVING`` (``KEEP``), or
   ``TIMED_OUT`` (``ABORT``) ``timeout_margin_s`` after the reference's end.

Times are mission times (s, the vehicle's clock).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

__all__ = [
    "LegPhase",
    "ActionKind",
    "LegAction",
    "LegState",
    "LegObservation",
    "leg_step",
    "RESUME_AFTER_S",
    "RESUME_RETRY_S",
]

#: A reference that ended short of its goal without asking to resume is continued this long
#: after its end (s of mission time).
RESUME_AFTER_S = 2.0
#: While no way back to the mission is found, ask again no sooner than this (s of mission time).
RESUME_RETRY_S = 1.0


class LegPhase(enum.Enum):
    """Where the flight of one leg is."""

    FOLLOWING = "following"  # a reference is flown (or none yet, e.g. after link back)
    ARRIVING = "arriving"  # the reference ended at the goal; the vehicle closes in
    STOPPED_SHORT = "stopped_short"  # the reference ended short of the goal (evade / hold)
    REACHED = "reached"  # done (terminal)
    TIMED_OUT = "timed_out"  # the goal was not reached in time (terminal)
    ABORTED = "aborted"  # disarmed or not in GUIDED any more (terminal)

    @property
    def terminal(self) -> bool:
        return self in (LegPhase.REACHED, LegPhase.TIMED_OUT, LegPhase.ABORTED)


class ActionKind(enum.Enum):
    """What the daemon does after a step."""

    KEEP = "keep"  # keep streaming the active reference
    RESUME = "resume"  # plan back from the stopped reference to the leg's goal
    REPLAN = "replan"  # replan the rest of the leg from where the vehicle is (link back)
    REACHED = "reached"  # the leg is done
    ABORT = "abort"  # end the flight (``LegAction.reason`` says why)


@dataclass(frozen=True)
class LegAction:
    """One action of :func:`leg_step`; ``reason`` is set for ``ABORT``, ``RESUME``, ``REPLAN``."""

    kind: ActionKind
    reason: str = ""


KEEP = LegAction(ActionKind.KEEP)


@dataclass(frozen=True)
class LegState:
    """The machine's memory for one leg.

    Attributes
    ----------
    phase : LegPhase
    last_resume_t_s : float
        Mission time of the last ``RESUME`` (-inf before the first).
    reason : str
        Why a terminal phase was entered (empty otherwise).
    """

    phase: LegPhase = LegPhase.FOLLOWING
    last_resume_t_s: float = -math.inf
    reason: str = ""


@dataclass(frozen=True)
class LegObservation:
    """What the daemon sees at one step.

    Attributes
    ----------
    t_s : float
        Mission time now (s).
    seq : int
        Mission item of the leg's goal (named in messages).
    connected : bool
        The vehicle's heartbeat is being heard.
    armed : bool or None
        None: not known yet.
    guided : bool or None
        The vehicle is in GUIDED; None: mode not known yet.
    mode_name : str
        The vehicle's mode (for messages).
    relink_pending : bool
        The link came back after a loss: the daemon holds, the leg must be replanned.
    dist_to_goal_m : float
        Vehicle distance to the leg's goal (m); inf when the position is unknown.
    acceptance_radius_m : float
    ref_end_t_s : float or None
        Mission time the active reference ends (None: no reference, e.g. holding after link back).
    ref_ends_short : bool
        The active reference ends farther than the acceptance radius from the goal.
    ref_resume : bool
        The active reference came from a decision that stops short on purpose (``resume``):
        plan back as soon as it has ended.
    timeout_margin_s : float
        Time after the reference's end to reach the goal before giving up (s).
    resume_after_s, resume_retry_s : float
        See :data:`RESUME_AFTER_S` and :data:`RESUME_RETRY_S`.
    """

    t_s: float
    seq: int
    connected: bool
    armed: bool | None
    guided: bool | None
    mode_name: str
    relink_pending: bool
    dist_to_goal_m: float
    acceptance_radius_m: float
    ref_end_t_s: float | None
    ref_ends_short: bool
    ref_resume: bool
    timeout_margin_s: float
    resume_after_s: float = RESUME_AFTER_S
    resume_retry_s: float = RESUME_RETRY_S


def leg_step(state: LegState, obs: LegObservation) -> tuple[LegState, LegAction]:
    """One step of the leg's state machine (pure; see the module docstring for the rules).

    Parameters
    ----------
    state : LegState
        The previous state (``LegState()`` at the start of a leg).
    obs : LegObservation

    Returns
    -------
    (LegState, LegAction)
        The new state and what to do. A terminal state returns itself with its action again.
    """
    if state.phase.terminal:
        return state, _terminal_action(state)
    if obs.connected:
        if obs.armed is False:
            return _end(state, LegPhase.ABORTED, "the vehicle disarmed in flight")
        if obs.guided is False:
            return _end(
                state,
                LegPhase.ABORTED,
                f"the vehicle left GUIDED (now {obs.mode_name}): a pilot or the autopilot "
                f"took over; the companion stops commanding",
            )
        if obs.relink_pending:
            return (
                replace(state, phase=LegPhase.FOLLOWING),
                LegAction(ActionKind.REPLAN, "link back: replan the leg from the vehicle"),
            )
    if obs.ref_end_t_s is None or obs.t_s < obs.ref_end_t_s:
        return replace(state, phase=LegPhase.FOLLOWING), KEEP
    if obs.dist_to_goal_m <= obs.acceptance_radius_m:
        return _end(state, LegPhase.REACHED, "")
    if obs.ref_ends_short:
        return _stopped_short(state, obs, obs.ref_end_t_s)
    if obs.t_s > obs.ref_end_t_s + obs.timeout_margin_s:
        return _end(
            state,
            LegPhase.TIMED_OUT,
            f"item {obs.seq} not reached: {obs.dist_to_goal_m:.1f} m away "
            f"{obs.timeout_margin_s:.0f} s after the reference arrived",
        )
    return replace(state, phase=LegPhase.ARRIVING), KEEP


def _stopped_short(state: LegState, obs: LegObservation, ref_end_t_s: float) -> tuple[LegState, LegAction]:
    """The reference ended short of the goal at ``ref_end_t_s`` (``obs.ref_end_t_s``, known here)."""
    stopped = replace(state, phase=LegPhase.STOPPED_SHORT)
    due_t_s = ref_end_t_s + (0.0 if obs.ref_resume else obs.resume_after_s)
    if obs.t_s < due_t_s or obs.t_s < state.last_resume_t_s + obs.resume_retry_s:
        return stopped, KEEP
    return (
        replace(stopped, last_resume_t_s=obs.t_s),
        LegAction(ActionKind.RESUME, "the reference stopped short of the goal"),
    )


def _end(state: LegState, phase: LegPhase, reason: str) -> tuple[LegState, LegAction]:
    new = replace(state, phase=phase, reason=reason)
    return new, _terminal_action(new)


def _terminal_action(state: LegState) -> LegAction:
    if state.phase is LegPhase.REACHED:
        return LegAction(ActionKind.REACHED)
    return LegAction(ActionKind.ABORT, state.reason)
