"""The threat decision as a pure step: ``decide(state, observation) -> (decision, state)``
(DESIGN 7, paper section 3.3).

Everything a decision needs is a value (``values.py``, exported from here too): the leg's
airspace and goal (``LegContext``), the policy (``DecisionPolicy``), what is seen now
(``Observation``: the time, the threats, the reference being flown, what asked) and the small
state carried from one decision to the next (``DecisionState``: the seed and counter of the
random draws, the running estimates of the decision's own duration, the replan back-off, the
M-GART alternatives). The state is sent to a
planning worker process and back; the caller owns it (and the active reference) and adopts the
returned state.

- ``decide`` with a ``threat`` or ``monitor`` trigger: the active reference is checked against
  the tubes over the horizon. Clear -> ``none`` (keep it). Otherwise the strategies of the
  policy produce candidates (``candidates.py``), all judged by the same space-time check and
  chosen by the same cost (``choice.choose``). With ``hybrid`` the fast candidates (evade and
  hold, retime, switch: milliseconds) are always generated; when none of them reaches the goal
  clear (retime, switch) and the conflict is further away than the measured replanning time, a
  replan joins them (not against a manned aircraft: its well-clear cylinder is kept by the fast
  candidates, which see it, where a planner only sees obstacles). A candidate that still intrudes replaces the active reference only when
  it is strictly better over the same window (from the time it would start), so the same answer
  is never decided twice (once the caller engages it).
- ``decide`` with the ``resume`` trigger (after an evasion or a hold has ended in a hover):
  plan back to the mission (replan through time, waiting for a mover where that is cheapest,
  or switch).
- ``active_conflict``: the monitor's cheap check of the active reference (the first step of a
  decision), run where the caller is.
- ``plan_alternatives_for``: M-GART alternatives (slow: in the background).

Randomness: every replan and alternatives search draws from a generator derived from the
state's seed and counter (``numpy.random.default_rng([seed, counter, stream])``), so a decision
is reproducible from its inputs. Pure: no asyncio, no zenoh, no clock of its own (times are in
the observation; the wall clock only measures the decision's own duration). Module-level
functions: they pickle by reference.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from companion.kernels import ensure_compiled
from companion.threats.decision import candidates as gen
from companion.threats.decision.alternatives import Alternative, airspace_for, plan_alternatives
from companion.threats.decision.choice import Candidate, Decision, ReferenceState, choose
from companion.threats.decision.kinds import CandidateKind, DecisionKind, Strategy, Trigger
from companion.threats.decision.prediction import is_manned, range_for, tubes_for
from companion.threats.decision.spacetime import Conflict
from companion.threats.decision.values import (
    ActiveTrajectory,
    DecisionError,
    DecisionPolicy,
    DecisionState,
    LegContext,
    Observation,
)
from companion.threats.decision.worlds import airspace, planning_slab

#: The step's values (``values.py``) are part of its API: callers import them from here.
__all__ = [
    "DecisionError",
    "ActiveTrajectory",
    "LegContext",
    "DecisionPolicy",
    "DecisionState",
    "Observation",
    "decide",
    "active_conflict",
    "plan_alternatives_for",
    "reference_state",
]

log = logging.getLogger(__name__)

#: After a replan that found nothing clear, no replan for this long (clock s): the same
#: failing answer is not sought again every monitor tick.
REPLAN_BACKOFF_S = 1.0
#: Longest candidate accepted (s): a longer one is a numerical failure, logged and dropped.
MAX_DURATION_S = 3600.0
#: An intruding candidate replaces an intruding active reference only with this much more
#: minimum clearance (m).
BETTER_BY_M = 1.0
#: Streams of the derived generators: a replan and an alternatives search that start from the
#: same counter (side by side in two workers) still draw different numbers.
REPLAN_STREAM, ALTERNATIVES_STREAM = 0, 1


# ---------------------------------------------------------------------------- the situation
def reference_state(active: ActiveTrajectory, t_s: float) -> ReferenceState:
    """Reference of ``active`` at clock time ``t_s`` (its own dimension; at rest after its end)."""
    traj = active.trajectory
    tau = np.array([min(max(t_s - active.start_t_s, 0.0), traj.duration_s)])
    pos, vel, acc = (np.atleast_2d(v)[0].astype(float) for v in traj.sample(tau))
    if t_s - active.start_t_s >= traj.duration_s:
        vel, acc = np.zeros_like(vel), np.zeros_like(acc)
    yaw = float(traj.yaw_rad(tau)[0]) if hasattr(traj, "yaw_rad") else 0.0
    return ReferenceState(float(t_s), pos, vel, acc, yaw)


def _relevant(threats, t_s: float, pos: np.ndarray, dim: int, settings) -> list:
    """Local, unexpired threats within their range of ``pos`` now (``prediction.range_for``:
    the sensor range, or the manned one)."""
    out = []
    for th in threats:
        if th.frame != "local_ned":
            raise DecisionError(f"threat {th.id!r}: convert global threats to local NED first (ThreatTable(home=...))")
        if th.expires_t_s <= t_s:
            continue
        if float(np.linalg.norm(th.position_at(t_s)[:dim] - pos[:dim])) - th.radius_m <= range_for(th, settings):
            out.append(th)
    return out


def _situation(t_s: float, obs: Observation, leg: LegContext, policy: DecisionPolicy) -> gen.Situation | None:
    """Everything the candidates need, from the active reference's state at ``t_s``."""
    if obs.active is None:
        return None
    ref = reference_state(obs.active, t_s)
    s, dim = policy.settings, leg.world.dim
    relevant = _relevant(obs.threats, t_s, ref.pos_ned_m, dim, s)
    room_m = s.manned_vertical_room_m if any(map(is_manned, relevant)) else s.vertical_room_m
    lift = float(ref.pos_ned_m[2]) if dim == 2 and ref.pos_ned_m.shape[0] == 3 else None
    here = [ref.pos_ned_m[:dim]]
    return gen.Situation(
        ref,
        tubes_for(relevant, s),
        airspace(leg.world, leg.world_key, here, s, room_m),
        planning_slab(leg.world, leg.world_key, here),
        leg.goal_ned_m,
        s,
        policy.pipeline,
        lift,
    )


def _remaining_s(sit: gen.Situation, active: ActiveTrajectory) -> float:
    """Time left on the active reference from the situation's time (s)."""
    return max(active.start_t_s + active.trajectory.duration_s - sit.ref.t_s, 0.0)


def _keep_at(sit: gen.Situation, active: ActiveTrajectory) -> Candidate:
    """The active reference as the ``keep`` candidate, judged."""
    keep = Candidate(
        CandidateKind.KEEP,
        "keep",
        active.trajectory,
        _remaining_s(sit, active),
        active.path_id,
        ends_short=active.ends_short,
    )
    t = sit.times(sit.settings.check_step_s)
    pos = gen.positions_at(active.trajectory, active.start_t_s, t, sit.dim)
    res = gen.check(sit, t, pos, static=False)  # the static world was checked before
    return keep.judged(res, 0)


def active_conflict(obs: Observation, leg: LegContext, policy: DecisionPolicy) -> Conflict | None:
    """First conflict of the observation's active reference with its threats over the horizon
    (None: clear, or nothing active). The monitor's check: a millisecond of numpy."""
    sit = _situation(obs.t_s, obs, leg, policy)
    if sit is None or not sit.tubes:  # no threat within the sensor range: nothing to meet
        return None
    return _keep_at(sit, obs.active).conflict


# ---------------------------------------------------------------------------- the decision
def decide(
    state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy
) -> tuple[Decision, DecisionState]:
    """Decide what to do about ``obs`` (see the module docstring).

    New candidates start from the active reference's state at the time the decision is
    expected to take effect (``obs.t_s`` plus the measured decision time, in clock seconds:
    ``policy.time_scale``), which the vehicle keeps flying until then: the setpoint never jumps.

    Parameters
    ----------
    state : DecisionState
    obs : Observation
        ``trigger`` ``resume``: a way back to the mission; otherwise a check of the active
        reference and, on a conflict, a new one.
    leg : LegContext
    policy : DecisionPolicy

    Returns
    -------
    decision : Decision
        With a trajectory: engage it so that its t = 0 is ``decision.start_t_s``, and give it
        to the next observation as the active reference.
    state : DecisionState
        The state for the next decision (a new value; ``state`` is unchanged).

    Notes
    -----
    The first call in a process compiles the kernels before any clock of the decision
    (``companion.kernels.ensure_compiled``): the budgets and the measured durations never
    include numba's compile.
    """
    ensure_compiled()
    if obs.trigger is Trigger.RESUME:
        return _resume(state, obs, leg, policy)
    return _on_threats(state, obs, leg, policy)


def _on_threats(state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy):
    t0 = time.perf_counter()
    sit = _situation(obs.t_s, obs, leg, policy)
    if sit is None:
        return Decision(DecisionKind.NONE, "no active trajectory", decide_ms=_ms_since(t0)), state
    active, s = obs.active, policy.settings
    keep = _keep_at(sit, active)
    if keep.clear:
        return Decision(
            DecisionKind.NONE,
            "the active reference stays clear",
            decide_ms=_ms_since(t0),
            resume=active.ends_short,
            min_clearance_m=keep.min_clearance_m,
        ), state
    ttc = keep.conflict.time_to_conflict_s
    what = f"{keep.conflict.threat_id} in {ttc:.1f} s"
    fast = _situation(obs.t_s + policy.fast_lead_s(state), obs, leg, policy)
    cands = _fast_candidates(fast, active, state.alternatives, policy.strategy)
    continues = any(c.clear and not c.ends_short for c in cands)  # a clear way to the goal
    slow_lead = policy.fast_lead_s(state) + policy.replan_lead_s(state)
    stop_s = float(np.linalg.norm(fast.ref.vel_ned_m_s)) / s.evade_accel_m_s2
    urgent = ttc <= slow_lead + stop_s + s.urgency_margin_s
    hybrid = policy.strategy is Strategy.HYBRID
    if policy.strategy is Strategy.REPLAN or (
        hybrid and not continues and not urgent and not _meets_manned(sit, keep.conflict)
    ):
        # there is time to replan: plan from where the vehicle will be when it is done
        slow = _situation(obs.t_s + slow_lead, obs, leg, policy)
        cands, state = _replan(state, slow, policy)
        if hybrid:
            cands += gen.evade_candidates(slow, _remaining_s(slow, active))
        return _finish(state, slow, keep, cands, what, t0, active, policy, branch="replan")
    state = replace(state, fast_estimate=state.fast_estimate.updated(time.perf_counter() - t0, s.estimate_gain))
    return _finish(state, fast, keep, cands, what, t0, active, policy)


def _meets_manned(sit: gen.Situation, conflict: Conflict) -> bool:
    """The conflict is with a manned aircraft: its cylinder is no obstacle a replan could plan
    around (it moves at 50 m/s), so the fast candidates answer it."""
    return any(tube.threat_id == conflict.threat_id and is_manned(tube) for tube in sit.tubes)


def _resume(state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy):
    """Plan back to the mission from the active reference (after an evasion or a hold), from
    its state when the measured replanning time has passed."""
    t0 = time.perf_counter()
    sit = _situation(obs.t_s + policy.replan_lead_s(state), obs, leg, policy)
    if sit is None:
        return Decision(DecisionKind.NONE, "no active trajectory", decide_ms=_ms_since(t0)), state
    cands: list[Candidate] = []
    if policy.strategy.switches:
        cands += gen.switch_to_alternatives(sit, state.alternatives)[0]
    if policy.strategy is not Strategy.SWITCH:
        replans, state = _replan(state, sit, policy)
        cands += replans
    s = policy.settings
    best = choose([c for c in _sane(cands) if c.clear], s.clearance_weight_s_m, s.clearance_cap_m)
    if best is None:
        return Decision(
            DecisionKind.NONE,
            "no clear way back to the mission yet",
            decide_ms=_ms_since(t0),
            resume=True,
            candidates=_counts(cands),
            branch="resume",
        ), state
    return _engage(state, sit, best, "back to the mission", None, cands, t0, branch="resume")


def _fast_candidates(sit: gen.Situation, active: ActiveTrajectory, alternatives, strategy: Strategy) -> list[Candidate]:
    """The candidates of milliseconds: evade and hold, retime, switch (by strategy)."""
    remaining = _remaining_s(sit, active)
    out: list[Candidate] = []
    if strategy in (Strategy.HYBRID, Strategy.EVADE, Strategy.HOLD):
        out += gen.evade_candidates(sit, remaining, brake_only=strategy is Strategy.HOLD)
    if strategy in (Strategy.HYBRID, Strategy.RETIME):
        out += gen.retime_candidates(sit, active.trajectory, active.start_t_s, remaining, active.ends_short)
    if strategy.switches and not any(c.clear and c.kind == CandidateKind.RETIME for c in out):
        out += gen.switch_to_alternatives(sit, alternatives)[0]
    return out


def _rng(seed: int, counter: int, stream: int) -> np.random.Generator:
    """The generator of one replan or alternatives search, derived from the state."""
    return np.random.default_rng([seed, counter, stream])


def _replan(state: DecisionState, sit: gen.Situation, policy: DecisionPolicy):
    """Replan candidates and the state after them, unless a replan found nothing clear less
    than ``REPLAN_BACKOFF_S`` ago."""
    if sit.ref.t_s < state.replan_blocked_until_s:
        return [], state
    t0 = time.perf_counter()
    counter = state.counter + 1
    out = gen.replan_candidates(sit, rng=_rng(state.seed, counter, REPLAN_STREAM), path_id=f"replan-{counter}")
    estimate = state.replan_estimate.updated(time.perf_counter() - t0, policy.settings.estimate_gain)
    blocked = state.replan_blocked_until_s
    if not any(c.clear for c in out):
        blocked = sit.ref.t_s + REPLAN_BACKOFF_S * policy.time_scale
    return out, replace(state, counter=counter, replan_estimate=estimate, replan_blocked_until_s=blocked)


def _finish(
    state: DecisionState,
    sit: gen.Situation,
    keep: Candidate,
    cands: list[Candidate],
    what: str,
    t0: float,
    active: ActiveTrajectory,
    policy: DecisionPolicy,
    branch: str = "fast",
):
    s = policy.settings
    best = choose(_sane(cands), s.clearance_weight_s_m, s.clearance_cap_m)
    # an intruding candidate is compared with the active reference over its own window (from the
    # situation's time): inside a receding tube, the reference is as good from then on
    if best is None or (not best.clear and best.min_clearance_m < _keep_at(sit, active).min_clearance_m + BETTER_BY_M):
        return Decision(
            DecisionKind.NONE,
            f"{what}: no candidate better than the active reference",
            decide_ms=_ms_since(t0),
            resume=active.ends_short,
            conflict=keep.conflict,
            candidates=_counts(cands),
            min_clearance_m=keep.min_clearance_m,
            branch=branch,
        ), state
    return _engage(state, sit, best, what, keep.conflict, cands, t0, branch)


def _engage(
    state: DecisionState,
    sit: gen.Situation,
    best: Candidate,
    what: str,
    conflict,
    cands,
    t0: float,
    branch: str = "fast",
) -> tuple[Decision, DecisionState]:
    """The decision to fly ``best`` from the situation's time, and the state after it."""
    state = replace(state, counter=state.counter + 1)
    kind = DecisionKind(best.kind)
    planned = kind in (DecisionKind.SWITCH, DecisionKind.REPLAN)
    path_id = best.path_id if planned else f"{kind.value}-{state.counter}"
    clear = "clear" if best.clear else f"least intrusion, {best.min_clearance_m:.1f} m"
    decision = Decision(
        kind,
        f"{what}: {best.label} ({clear})",
        best.trajectory,
        sit.ref.t_s,
        path_id,
        best.path_ned_m,
        conflict,
        plan_ms=_ms_since(t0),
        resume=best.ends_short,
        label=best.label,
        candidates=_counts(cands),
        min_clearance_m=best.min_clearance_m,
        branch=branch,
    )
    decision = replace(decision, decide_ms=_ms_since(t0))
    log.info(
        "threat decision %s (%s) path %s: decide %.1f ms", kind.value, decision.reason, path_id, decision.decide_ms
    )
    return decision, state


def _sane(cands) -> list[Candidate]:
    """Candidates with a finite, plausible duration (others are logged and dropped)."""
    out = []
    for c in cands:
        if math.isfinite(c.trajectory.duration_s) and c.trajectory.duration_s <= MAX_DURATION_S:
            out.append(c)
        else:
            log.warning("candidate %s dropped: duration %r s", c.label, c.trajectory.duration_s)
    return out


def _counts(cands) -> dict[str, int]:
    """How many candidates of each kind (plain strings: the event's ``candidates``)."""
    out: dict[str, int] = {}
    for c in cands:
        kind = CandidateKind(c.kind).value
        out[kind] = out.get(kind, 0) + 1
    return out


def _ms_since(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3


# ---------------------------------------------------------------------------- alternatives
def plan_alternatives_for(
    state: DecisionState,
    obs: Observation,
    leg: LegContext,
    policy: DecisionPolicy,
    k: int,
    *,
    max_time_s: float,
    start_ned_m=None,
) -> tuple[tuple[Alternative, ...], DecisionState]:
    """M-GART alternatives from the active reference's state at ``obs.t_s`` (or ``start_ned_m``)
    to the leg's goal, and the state after the search (its counter advanced).

    Slow (``max_time_s``): run it in the background, then ``state.with_alternatives``. Pop-ups
    are obstacles; a mover is placed where the active reference would meet it (its track
    around that time), so alternatives pass it on either side.

    Returns
    -------
    alternatives : tuple of Alternative
        Ids ``alt<i>-<counter>``; empty when M-GART found nothing.
    state : DecisionState
    """
    ensure_compiled()  # numba's compile never inside max_time_s
    if start_ned_m is None:
        if obs.active is None:
            raise DecisionError("start_ned_m: needed when no trajectory is active")
        start_ned_m = reference_state(obs.active, obs.t_s).pos_ned_m
    dim = leg.world.dim
    start = np.asarray(start_ned_m, dtype=float).reshape(-1)[:dim]
    if start.shape != (dim,) or not np.all(np.isfinite(start)):
        raise DecisionError(f"start_ned_m: expected at least {dim} finite numbers, got {start_ned_m!r}")
    sit = _situation(obs.t_s, obs, leg, policy)
    obstacles = (
        []
        if sit is None
        else gen.meeting_obstacles(sit, obs.active.trajectory, obs.active.start_t_s, [start, leg.goal_ned_m])
    )
    world = airspace_for(leg.world, [start])
    world = world.with_threats(obstacles) if obstacles else world
    counter = state.counter + 1
    s = policy.settings
    alts = plan_alternatives(
        world,
        start,
        leg.goal_ned_m,
        k,
        pipeline=policy.pipeline,
        rng=_rng(state.seed, counter, ALTERNATIVES_STREAM),
        max_time_s=max_time_s,
        spacing_m=s.entry_spacing_m,
        airspace=airspace(leg.world, leg.world_key, [start], s),
        vertical_offsets_m=s.vertical_offsets_m,
        tag=f"-{counter}",
    )
    return tuple(alts), replace(state, counter=counter)
