"""The threat decision as a pure step: ``decide(state, observation) -> (decision, state)``
(DESIGN 7, paper section 3.3).

Everything a decision needs is a value: the leg's airspace and goal (``LegContext``), the policy
(``DecisionPolicy``), what is seen now (``Observation``: the time, the threats, the reference
being flown, what asked) and the small state carried from one decision to the next
(``DecisionState``: the seed and counter of the random draws, the running estimates of the
decision's own duration, the replan back-off, the M-GART alternatives). The state is sent to a
planning worker process and back; the caller owns it (and the active reference) and adopts the
returned state.

- ``decide`` with a ``threat`` or ``monitor`` trigger: the active reference is checked against
  the tubes over the horizon. Clear -> ``none`` (keep it). Otherwise the strategies of the
  policy produce candidates (``candidates.py``), all judged by the same space-time check and
  chosen by the same cost (``choice.choose``). With ``hybrid`` the fast candidates (evade and
  hold, retime, switch: milliseconds) are always generated; when none of them reaches the goal
  clear (retime, switch) and the conflict is further away than the measured replanning time, a
  replan joins them. A candidate that still intrudes replaces the active reference only when
  it is strictly better, so the same answer is never decided twice (once the caller engages it).
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
import uuid
from dataclasses import dataclass, field, replace

import numpy as np

from companion.errors import CompanionError
from companion.planning import GartSettings, MgartSettings
from companion.smoothing import TrajectoryLimits
from companion.threats.decision import candidates as gen
from companion.threats.decision.alternatives import Alternative, airspace_for, plan_alternatives
from companion.threats.decision.choice import Candidate, Decision, ReferenceState, choose
from companion.threats.decision.estimate import RunningEstimate
from companion.threats.decision.kinds import CandidateKind, DecisionKind, Strategy, Trigger
from companion.threats.decision.prediction import predict_tubes
from companion.threats.decision.spacetime import Conflict
from companion.threats.decision.worlds import airspace, planning_slab
from companion.threats.settings import ThreatSettings
from companion.world import World

__all__ = ["DecisionError", "ActiveTrajectory", "LegContext", "DecisionPolicy", "DecisionState", "Observation",
           "decide", "active_conflict", "plan_alternatives_for", "rejected", "reference_state"]

log = logging.getLogger(__name__)

#: First estimate of the fast candidates' wall-clock time (s), before any was measured.
FAST_ESTIMATE_S = 0.03
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


class DecisionError(CompanionError, ValueError):
    """Bad arguments to the threat decision (naming them)."""


def _finite_positive(name: str, value) -> float:
    if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise DecisionError(f"{name}: must be a finite number > 0, got {value!r}")
    return float(value)


# ---------------------------------------------------------------------------- values
@dataclass(frozen=True)
class ActiveTrajectory:
    """The reference being flown, as the decision sees it (the caller owns the real one).

    Attributes
    ----------
    trajectory : Trajectory-like
        ``sample(t_s) -> (pos, vel, acc)``, ``duration_s``; t = 0 at ``start_t_s``.
    start_t_s : float
        Clock time of its t = 0 (s).
    path_id : str
    ends_short : bool
        It stops short of the leg's goal on purpose (an evasion or a hold: resume after it).
    """

    trajectory: object
    start_t_s: float
    path_id: str
    ends_short: bool = False

    def __post_init__(self) -> None:
        if not hasattr(self.trajectory, "sample") or not hasattr(self.trajectory, "duration_s"):
            raise DecisionError("trajectory: expected an object with sample(t_s) and duration_s")
        if not (isinstance(self.start_t_s, (int, float)) and math.isfinite(self.start_t_s)):
            raise DecisionError(f"start_t_s: must be finite, got {self.start_t_s!r}")
        object.__setattr__(self, "start_t_s", float(self.start_t_s))
        object.__setattr__(self, "path_id", str(self.path_id))
        object.__setattr__(self, "ends_short", bool(self.ends_short))


@dataclass(frozen=True, eq=False)
class LegContext:
    """The leg's static airspace: its index, world (2D or 3D, local NED) and goal (d,).

    ``world_key`` (default: made unique at construction) names the world in the per-process
    memo of its widened copies (``worlds.py``); it travels with the leg to a worker process.
    """

    index: int
    world: World
    goal_ned_m: np.ndarray
    world_key: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.world, World):
            raise DecisionError(f"world: expected a World, got {type(self.world).__name__}")
        goal = np.asarray(self.goal_ned_m, dtype=float).reshape(-1)
        if goal.shape != (self.world.dim,) or not np.all(np.isfinite(goal)):
            raise DecisionError(f"goal_ned_m: expected {self.world.dim} finite numbers, got {self.goal_ned_m!r}")
        goal.setflags(write=False)
        object.__setattr__(self, "goal_ned_m", goal)
        object.__setattr__(self, "index", int(self.index))
        if not self.world_key:
            object.__setattr__(self, "world_key", uuid.uuid4().hex)


@dataclass(frozen=True)
class DecisionPolicy:
    """The policy as data.

    Attributes
    ----------
    settings : ThreatSettings
    limits : TrajectoryLimits
        Limits of new planned trajectories.
    kappa_max_1_m : float
        K_max of the G2 smoothing.
    gart_settings : GartSettings
        Of the replans and (in ``MgartSettings``) the alternatives.
    strategy : Strategy
        ``hybrid`` (DESIGN section 7, the default) or a single strategy (the benchmark).
    time_scale : float
        Clock seconds per wall-clock second (a SITL speed-up): the decision's own measured
        duration, in clock seconds, is how far ahead its candidates start.
    """

    settings: ThreatSettings = field(default_factory=ThreatSettings)
    limits: TrajectoryLimits = field(default_factory=TrajectoryLimits)
    kappa_max_1_m: float = 0.1
    gart_settings: GartSettings | None = None
    strategy: Strategy = Strategy.HYBRID
    time_scale: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.settings, ThreatSettings):
            raise DecisionError(f"settings: expected ThreatSettings, got {type(self.settings).__name__}")
        if not isinstance(self.limits, TrajectoryLimits):
            raise DecisionError(f"limits: expected TrajectoryLimits, got {type(self.limits).__name__}")
        try:
            object.__setattr__(self, "strategy", Strategy(self.strategy))
        except ValueError:
            raise DecisionError(f"strategy: expected one of {', '.join(Strategy)}, got {self.strategy!r}") from None
        object.__setattr__(self, "kappa_max_1_m", _finite_positive("kappa_max_1_m", self.kappa_max_1_m))
        object.__setattr__(self, "time_scale", _finite_positive("time_scale", self.time_scale))
        if self.gart_settings is None:
            object.__setattr__(self, "gart_settings", GartSettings(kappa_max_1_m=self.kappa_max_1_m))
        elif not isinstance(self.gart_settings, GartSettings):
            raise DecisionError(f"gart_settings: expected GartSettings, got {type(self.gart_settings).__name__}")

    @classmethod
    def from_settings(cls, settings, strategy: Strategy | str = Strategy.HYBRID) -> "DecisionPolicy":
        """From the companion's ``Settings`` (``threats``, ``smoothing``, ``gart``, ``link.time_scale``:
        None, not read from the vehicle yet, is real time as for the daemon's clock)."""
        return cls(settings.threats, settings.smoothing.limits, settings.smoothing.kappa_max_1_m, settings.gart,
                   strategy, settings.link.time_scale or 1.0)

    def lead_s(self, estimate: RunningEstimate) -> float:
        """Clock seconds that a step of ``estimate`` is expected to take (mean + 1 deviation)."""
        return (estimate.mean_s + estimate.dev_s) * self.time_scale


@dataclass(frozen=True)
class DecisionState:
    """What one decision hands to the next (small, explicit: sent to a worker and back).

    Attributes
    ----------
    seed : int
        Seed of the derived generators.
    counter : int
        Advanced by every replan, engaged decision and alternatives search (path ids, draws).
    replan_estimate, fast_estimate : RunningEstimate
        Measured wall-clock time of a replan and of the fast candidates (s).
    replan_blocked_until_s : float
        No replan before this clock time (a replan found nothing clear just before).
    alternatives : tuple of Alternative
        The M-GART switching targets.
    """

    seed: int
    counter: int
    replan_estimate: RunningEstimate
    fast_estimate: RunningEstimate
    replan_blocked_until_s: float
    alternatives: tuple[Alternative, ...] = ()

    @classmethod
    def initial(cls, policy: DecisionPolicy, seed: int) -> "DecisionState":
        """The state of a flight's first decision: the policy's first estimates, no alternatives."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise DecisionError(f"seed: expected an int >= 0, got {seed!r}")
        return cls(int(seed), 0, RunningEstimate(policy.settings.replan_budget_s), RunningEstimate(FAST_ESTIMATE_S),
                   -math.inf, ())

    def with_alternatives(self, alternatives, *, dim: int | None = None, spacing_m: float = 2.0) -> "DecisionState":
        """This state with new switching targets (``Alternative`` or (M, d) paths, converted
        with entries ``spacing_m`` apart); every one of dimension ``dim`` (the leg's world's)."""
        alts = []
        for i, alt in enumerate(alternatives):
            if not isinstance(alt, Alternative):
                alt = Alternative.from_path(f"alt{i}", alt, spacing_m)
            want = alts[0].path_ned_m.shape[1] if dim is None and alts else dim
            if want is not None and alt.path_ned_m.shape[1] != want:
                raise DecisionError(f"alternatives[{i}]: dimension {alt.path_ned_m.shape[1]} "
                                    f"does not match the world's {want}")
            alts.append(alt)
        return replace(self, alternatives=tuple(alts))

    @property
    def replan_estimate_s(self) -> float:
        """Current replanning estimate: running mean + 3 mean absolute deviations (s)."""
        return self.replan_estimate.high_s


@dataclass(frozen=True)
class Observation:
    """What a decision sees: clock time ``t_s``, every threat known then (local frame, stamped on
    the same clock), the reference being flown (None: nothing to decide) and what asked."""

    t_s: float
    threats: tuple = ()
    active: ActiveTrajectory | None = None
    trigger: Trigger = Trigger.THREAT

    def __post_init__(self) -> None:
        if not (isinstance(self.t_s, (int, float)) and math.isfinite(self.t_s)):
            raise DecisionError(f"t_s: must be finite, got {self.t_s!r}")
        if self.active is not None and not isinstance(self.active, ActiveTrajectory):
            raise DecisionError(f"active: expected an ActiveTrajectory, got {type(self.active).__name__}")
        try:
            object.__setattr__(self, "trigger", Trigger(self.trigger))
        except ValueError:
            raise DecisionError(f"trigger: expected one of {', '.join(Trigger)}, got {self.trigger!r}") from None
        object.__setattr__(self, "t_s", float(self.t_s))
        object.__setattr__(self, "threats", tuple(self.threats))


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


def _relevant(threats, t_s: float, pos: np.ndarray, dim: int, sensor_range_m: float) -> list:
    """Local, unexpired threats within the sensor range of ``pos`` now."""
    out = []
    for th in threats:
        if th.frame != "local_ned":
            raise DecisionError(f"threat {th.id!r}: convert global threats to local NED first "
                                f"(ThreatTable(home=...))")
        if th.expires_t_s <= t_s:
            continue
        if float(np.linalg.norm(th.position_at(t_s)[:dim] - pos[:dim])) - th.radius_m <= sensor_range_m:
            out.append(th)
    return out


def _situation(t_s: float, obs: Observation, leg: LegContext, policy: DecisionPolicy) -> gen.Situation | None:
    """Everything the candidates need, from the active reference's state at ``t_s``."""
    if obs.active is None:
        return None
    ref = reference_state(obs.active, t_s)
    s, dim = policy.settings, leg.world.dim
    tubes = predict_tubes(_relevant(obs.threats, t_s, ref.pos_ned_m, dim, s.sensor_range_m),
                          inflation_m=s.inflation_m, uncertainty_m_s=s.uncertainty_m_s,
                          uncertainty_max_m=s.uncertainty_max_m)
    lift = float(ref.pos_ned_m[2]) if dim == 2 and ref.pos_ned_m.shape[0] == 3 else None
    here = [ref.pos_ned_m[:dim]]
    return gen.Situation(ref, tubes, airspace(leg.world, leg.world_key, here, s),
                         planning_slab(leg.world, leg.world_key, here), leg.goal_ned_m, s, policy.limits,
                         policy.kappa_max_1_m, lift)


def _remaining_s(sit: gen.Situation, active: ActiveTrajectory) -> float:
    """Time left on the active reference from the situation's time (s)."""
    return max(active.start_t_s + active.trajectory.duration_s - sit.ref.t_s, 0.0)


def _keep_at(sit: gen.Situation, active: ActiveTrajectory) -> Candidate:
    """The active reference as the ``keep`` candidate, judged."""
    keep = Candidate(CandidateKind.KEEP, "keep", active.trajectory, _remaining_s(sit, active), active.path_id,
                     ends_short=active.ends_short)
    t = sit.times(sit.settings.check_step_s)
    pos = gen.positions_at(active.trajectory, active.start_t_s, t, sit.dim)
    res = gen.check(sit, t, pos, static=False)          # the static world was checked before
    return keep.judged(res, 0)


def active_conflict(obs: Observation, leg: LegContext, policy: DecisionPolicy) -> Conflict | None:
    """First conflict of the observation's active reference with its threats over the horizon
    (None: clear, or nothing active). The monitor's check: a millisecond of numpy."""
    sit = _situation(obs.t_s, obs, leg, policy)
    return None if sit is None else _keep_at(sit, obs.active).conflict


# ---------------------------------------------------------------------------- the decision
def decide(state: DecisionState, obs: Observation, leg: LegContext,
           policy: DecisionPolicy) -> tuple[Decision, DecisionState]:
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
    """
    if obs.trigger is Trigger.RESUME:
        return _resume(state, obs, leg, policy)
    return _on_threats(state, obs, leg, policy)


def rejected(error: Exception) -> Decision:
    """The ``rejected`` decision for an invalid threat sample (the flight goes on)."""
    return Decision(DecisionKind.REJECTED, str(error))


def _on_threats(state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy):
    t0 = time.perf_counter()
    sit = _situation(obs.t_s, obs, leg, policy)
    if sit is None:
        return Decision(DecisionKind.NONE, "no active trajectory", decide_ms=_ms_since(t0)), state
    active, s = obs.active, policy.settings
    keep = _keep_at(sit, active)
    if keep.clear:
        return Decision(DecisionKind.NONE, "the active reference stays clear", decide_ms=_ms_since(t0),
                        resume=active.ends_short, min_clearance_m=keep.min_clearance_m), state
    ttc = keep.conflict.time_to_conflict_s
    what = f"{keep.conflict.threat_id} in {ttc:.1f} s"
    fast = _situation(obs.t_s + policy.lead_s(state.fast_estimate), obs, leg, policy)
    cands = _fast_candidates(fast, active, state.alternatives, policy.strategy)
    continues = any(c.clear and not c.ends_short for c in cands)     # a clear way to the goal
    slow_lead = policy.lead_s(state.fast_estimate) + policy.lead_s(state.replan_estimate)
    stop_s = float(np.linalg.norm(fast.ref.vel_ned_m_s)) / s.evade_accel_m_s2
    urgent = ttc <= slow_lead + stop_s + s.urgency_margin_s
    hybrid = policy.strategy is Strategy.HYBRID
    if policy.strategy is Strategy.REPLAN or (hybrid and not continues and not urgent):
        # there is time to replan: plan from where the vehicle will be when it is done
        slow = _situation(obs.t_s + slow_lead, obs, leg, policy)
        cands, state = _replan(state, slow, policy)
        if hybrid:
            cands += gen.evade_candidates(slow, _remaining_s(slow, active))
        return _finish(state, slow, keep, cands, what, t0, active, policy)
    state = replace(state, fast_estimate=state.fast_estimate.updated(time.perf_counter() - t0, s.estimate_gain))
    return _finish(state, fast, keep, cands, what, t0, active, policy)


def _resume(state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy):
    """Plan back to the mission from the active reference (after an evasion or a hold), from
    its state when the measured replanning time has passed."""
    t0 = time.perf_counter()
    sit = _situation(obs.t_s + policy.lead_s(state.replan_estimate), obs, leg, policy)
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
        return Decision(DecisionKind.NONE, "no clear way back to the mission yet", decide_ms=_ms_since(t0),
                        resume=True, candidates=_counts(cands)), state
    return _engage(state, sit, best, "back to the mission", None, cands, t0)


def _fast_candidates(sit: gen.Situation, active: ActiveTrajectory, alternatives,
                     strategy: Strategy) -> list[Candidate]:
    """The candidates of milliseconds: evade and hold, retime, switch (by strategy)."""
    remaining = _remaining_s(sit, active)
    out: list[Candidate] = []
    if strategy in (Strategy.HYBRID, Strategy.EVADE, Strategy.HOLD):
        out += gen.evade_candidates(sit, remaining, brake_only=strategy is Strategy.HOLD)
    if strategy in (Strategy.HYBRID, Strategy.RETIME):
        out += gen.retime_candidates(sit, active.trajectory, active.start_t_s, remaining, active.ends_short)
    if strategy.switches and not any(
            c.clear and c.kind == CandidateKind.RETIME for c in out):
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
    out = gen.replan_candidates(sit, rng=_rng(state.seed, counter, REPLAN_STREAM),
                                gart_settings=policy.gart_settings, path_id=f"replan-{counter}")
    estimate = state.replan_estimate.updated(time.perf_counter() - t0, policy.settings.estimate_gain)
    blocked = state.replan_blocked_until_s
    if not any(c.clear for c in out):
        blocked = sit.ref.t_s + REPLAN_BACKOFF_S * policy.time_scale
    return out, replace(state, counter=counter, replan_estimate=estimate, replan_blocked_until_s=blocked)


def _finish(state: DecisionState, sit: gen.Situation, keep: Candidate, cands: list[Candidate], what: str,
            t0: float, active: ActiveTrajectory, policy: DecisionPolicy):
    s = policy.settings
    best = choose(_sane(cands), s.clearance_weight_s_m, s.clearance_cap_m)
    if best is None or (not best.clear and best.min_clearance_m < keep.min_clearance_m + BETTER_BY_M):
        return Decision(DecisionKind.NONE, f"{what}: no candidate better than the active reference",
                        decide_ms=_ms_since(t0), resume=active.ends_short, conflict=keep.conflict,
                        candidates=_counts(cands), min_clearance_m=keep.min_clearance_m), state
    return _engage(state, sit, best, what, keep.conflict, cands, t0)


def _engage(state: DecisionState, sit: gen.Situation, best: Candidate, what: str, conflict, cands,
            t0: float) -> tuple[Decision, DecisionState]:
    """The decision to fly ``best`` from the situation's time, and the state after it."""
    state = replace(state, counter=state.counter + 1)
    kind = DecisionKind(best.kind)
    planned = kind in (DecisionKind.SWITCH, DecisionKind.REPLAN)
    path_id = best.path_id if planned else f"{kind.value}-{state.counter}"
    clear = "clear" if best.clear else f"least intrusion, {best.min_clearance_m:.1f} m"
    decision = Decision(kind, f"{what}: {best.label} ({clear})", best.trajectory, sit.ref.t_s,
                        path_id, best.path_ned_m, conflict, plan_ms=_ms_since(t0),
                        resume=best.ends_short, label=best.label, candidates=_counts(cands),
                        min_clearance_m=best.min_clearance_m)
    decision = replace(decision, decide_ms=_ms_since(t0))
    log.info("threat decision %s (%s) path %s: decide %.1f ms", kind.value, decision.reason,
             path_id, decision.decide_ms)
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
def plan_alternatives_for(state: DecisionState, obs: Observation, leg: LegContext, policy: DecisionPolicy,
                          k: int, *, max_time_s: float, start_ned_m=None,
                          settings: MgartSettings | None = None) -> tuple[tuple[Alternative, ...], DecisionState]:
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
    if start_ned_m is None:
        if obs.active is None:
            raise DecisionError("start_ned_m: needed when no trajectory is active")
        start_ned_m = reference_state(obs.active, obs.t_s).pos_ned_m
    dim = leg.world.dim
    start = np.asarray(start_ned_m, dtype=float).reshape(-1)[:dim]
    if start.shape != (dim,) or not np.all(np.isfinite(start)):
        raise DecisionError(f"start_ned_m: expected at least {dim} finite numbers, got {start_ned_m!r}")
    sit = _situation(obs.t_s, obs, leg, policy)
    obstacles = [] if sit is None else gen.meeting_obstacles(sit, obs.active.trajectory, obs.active.start_t_s,
                                                             [start, leg.goal_ned_m])
    world = airspace_for(leg.world, [start])
    world = world.with_threats(obstacles) if obstacles else world
    counter = state.counter + 1
    s = policy.settings
    alts = plan_alternatives(world, start, leg.goal_ned_m, k, rng=_rng(state.seed, counter, ALTERNATIVES_STREAM),
                             max_time_s=max_time_s, settings=settings or MgartSettings(gart=policy.gart_settings),
                             spacing_m=s.entry_spacing_m, airspace=airspace(leg.world, leg.world_key, [start], s),
                             vertical_offsets_m=s.vertical_offsets_m, tag=f"-{counter}")
    return tuple(alts), replace(state, counter=counter)
