"""Threat avoidance inside the flight executor: monitor, decide, engage, tell (DESIGN 7.3-7.5).

``Avoidance`` owns the decision's state (``DecisionState``), the leg's airspace
(``LegContext``) and the policy (``DecisionPolicy``), and asks the pure step
``companion.threats.decision.step.decide(state, observation, leg, policy)`` for a decision:

- **Triggers.** A threat update (``on_threats_changed``), the monitor (``monitor``, a task of the
  executor's schedule at >= 10 Hz: the active reference is checked in this process by
  ``active_conflict``; only a conflict becomes a decision), a request to plan back to the
  mission (``request_resume``, from the phase machine when a reference ended short).
- **One decision at a time**, as a job (``Jobs``: a planning worker process in real time, in
  process on the virtual clock in fast time). Triggers that arrive meanwhile are folded into
  the next decision (the newest threats always win); a resume request goes first.
- **Engage.** A decision with a trajectory becomes the active reference from the decision's
  start time (``ReferenceOwner.engage``: the setpoint never jumps), unless the leg or the
  reference changed while deciding. Its latency runs from the trigger to the first setpoint of
  the new reference; the decision is then told (``FlightSink.decision``) with that latency.
- **Alternatives.** M-GART alternatives are refreshed as a job at every leg start, after every
  decision and periodically (``refresh_alternatives``, a task of the schedule), from the
  reference ``lead_s`` ahead, when the policy's strategy switches to them. With no threat
  held, a refresh on the same leg and reference as the last one that found alternatives is not
  run.
- **Delay check** (other vehicles known): a decision's trajectory passes the ``CommitGate``
  before it is engaged.
- **Manned traffic at 1 Hz.** When a decision finds nothing better than the reference against
  a manned aircraft (its well clear volume cannot always be kept), the monitor does not ask
  again on the same reports: the aircraft's next report (about 1 Hz), or
  ``MANNED_REDECIDE_S``, does. A drone-scale conflict is decided again at every tick.
- **Alerts** (``alerts`` settings given and enabled): the ``TrafficAlerts``
  (``companion.flight.alerting``) it owns predict the traffic against the reference at
  ``alerts.rate_hz`` (the schedule's ``alerts`` task), at once when the monitor finds a
  conflict, and tell every decision's action once it is told.

No asyncio and no I/O: the executor's ticks and the jobs' completions drive it.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from companion.flight.active import ReferenceOwner
from companion.flight.alerting import TrafficAlerts
from companion.flight.ports import FlightSink, Jobs
from companion.flight.reference import ActiveReference
from companion.threats.decision.kinds import Trigger
from companion.threats.decision.prediction import is_manned
from companion.threats.decision.screen import MonitorScreen, same_reports
from companion.threats.decision.step import (
    ActiveTrajectory,
    DecisionPolicy,
    DecisionState,
    LegContext,
    Observation,
    active_conflict,
    decide,
    plan_alternatives_for,
)

if TYPE_CHECKING:
    from companion.threats.decision.choice import Decision

__all__ = ["Avoidance", "ThreatSource", "CommitGate", "AlternativesPlan", "DecisionSteps", "active_trajectory"]

log = logging.getLogger(__name__)

#: How long a decision's event waits for the first setpoint of its reference (s, monotonic).
FIRST_SETPOINT_WAIT_S = 1.0
#: Longest wait (s, monotonic) before a manned conflict left unanswered is decided again on the
#: same reports (the module docstring).
MANNED_REDECIDE_S = 1.0


class ThreatSource(Protocol):
    """The threats to decide on (the threat table, plus other vehicles as tubes)."""

    def threats_at(self, t_s: float) -> tuple:
        """Every unexpired threat at mission time ``t_s`` (local NED)."""

    def any_known(self) -> bool:
        """Anything to monitor: a threat held, or another vehicle known."""


class CommitGate(Protocol):
    """The fleet's delay check: ``check(decision, proceed)`` calls ``proceed()`` once the
    decision's trajectory still clears the other vehicles after the communication delay (or
    never, when it does not)."""

    def check(self, decision, proceed: Callable[[], None]) -> None: ...


@dataclasses.dataclass(frozen=True)
class AlternativesPlan:
    """How M-GART alternatives are kept: ``k`` paths (0: none), planned within ``budget_s``
    from the reference ``lead_s`` ahead (mission s)."""

    k: int
    budget_s: float
    lead_s: float


@dataclasses.dataclass(frozen=True)
class DecisionSteps:
    """The pure steps the avoidance runs (module-level functions: jobs pickle them). The
    default is ``companion.threats.decision.step``'s; a test gives scripted ones."""

    decide: Callable = decide
    active_conflict: Callable = active_conflict
    plan_alternatives: Callable = plan_alternatives_for


def active_trajectory(ref: ActiveReference | None) -> ActiveTrajectory | None:
    """The decision's value of the active reference."""
    if ref is None:
        return None
    return ActiveTrajectory(ref.trajectory, ref.t0_s, ref.path_id, bool(ref.resume))


@dataclasses.dataclass
class _Timing:
    """Where a decision's latency went, on the executor's clock (s): asked (the trigger), sent
    to a job, its result back, engaged (after the delay check)."""

    trigger_s: float
    submitted_s: float
    returned_s: float = math.nan
    engaged_s: float = math.nan

    def parts_ms(self, first_sent_s: float, decide_ms: float) -> dict[str, float]:
        """``queued`` (waiting for the decision before it), ``compute`` (the decision's own),
        ``transport`` (to the job and back, beyond its compute), ``gate`` (the delay check) and
        ``start`` (engaged to its first setpoint: the new reference takes effect at its start
        time, the decision's expected duration after the trigger), in ms."""
        ms = lambda a, b: round((b - a) * 1000.0, 2)  # noqa: E731
        job = ms(self.submitted_s, self.returned_s)
        return {
            "queued": ms(self.trigger_s, self.submitted_s),
            "compute": round(decide_ms, 2),
            "transport": round(job - decide_ms, 2),
            "gate": ms(self.returned_s, self.engaged_s),
            "start": ms(self.engaged_s, first_sent_s),
        }


@dataclasses.dataclass
class _Pending:
    ref: ActiveReference
    decision: Decision
    event: dict
    timing: _Timing
    deadline_mono_s: float


class Avoidance:
    """The executor's threat decisions (see the module docstring).

    Parameters
    ----------
    policy : DecisionPolicy
    state : DecisionState
        The decision's initial state (``DecisionState.initial``).
    owner : ReferenceOwner
        The active reference's owner: read at every decision, engaged with its outcome.
    threats : ThreatSource
    jobs : Jobs
    sink : FlightSink
    now_s : callable () -> float
        Mission time now.
    monotonic_s : callable () -> float
        The executor's clock (the latency's): wall clock in real time, virtual in fast time.
    send_now : callable ()
        Sends the current setpoint at once (a new reference's first setpoint).
    send_at : callable (t_s), optional
        Sends the setpoint when mission time ``t_s`` comes: the first setpoint of a reference
        engaged to start later (it waits for the stream's next tick otherwise, up to a period
        more). None: the next tick sends it (fast time, where the vehicle moves at the ticks).
    position_ned_m : callable () -> ndarray or None
        The vehicle's position (for the events).
    alternatives : AlternativesPlan
    commit_gate : CommitGate, optional
    steps : DecisionSteps
    alerts : AlertSettings, optional
        Traffic alerts to the ground stations (``companion.threats.alerts``); None or disabled:
        none.
    """

    def __init__(
        self,
        *,
        policy: DecisionPolicy,
        state: DecisionState,
        owner: ReferenceOwner,
        threats: ThreatSource,
        jobs: Jobs,
        sink: FlightSink,
        now_s: Callable[[], float],
        monotonic_s: Callable[[], float],
        send_now: Callable[[], None],
        position_ned_m: Callable,
        alternatives: AlternativesPlan,
        commit_gate: CommitGate | None = None,
        steps: DecisionSteps = DecisionSteps(),
        alerts=None,
        send_at: Callable[[float], None] | None = None,
    ) -> None:
        self.policy = policy
        self.steps = steps
        self.state = state
        self.owner = owner
        self.threats = threats
        self.jobs = jobs
        self.sink = sink
        self.now_s = now_s
        self.monotonic_s = monotonic_s
        self.send_now = send_now
        self.send_at = send_at
        self.position_ned_m = position_ned_m
        self.alternatives_plan = alternatives
        self.commit_gate = commit_gate
        self.leg: LegContext | None = None
        self.decisions = 0
        self.latencies_ms: dict[str, list[float]] = {}
        self.alternatives_skipped = 0
        self._busy = False
        self._queued: tuple[Trigger, float] | None = None
        self._unanswered: tuple | None = None  # (reference, threat reports, until s): a manned stand-off
        self._resume_wanted: Callable | None = None
        self._told: list[_Pending] = []
        self._alt_busy = False
        self._alt_dirty = False
        self._alt_last_key: tuple | None = None
        self.screen = MonitorScreen(policy.settings, policy.accel_bound_m_s2)
        self.alerts = (
            None
            if alerts is None or not alerts.enabled
            else TrafficAlerts(
                alerts,
                threats=threats.threats_at,
                reference=lambda: owner.current,
                own_down_m=self._own_down_m,
                now_s=now_s,
                sink=sink,
            )
        )

    def _own_down_m(self) -> float | None:
        pos = self.position_ned_m()
        return None if pos is None or len(pos) < 3 else float(pos[2])

    # ------------------------------------------------------------------ legs
    def start_leg(self, leg: LegContext) -> None:
        """A leg starts (its reference is engaged): its airspace, no alternatives yet; then
        alternatives are planned, and a decision is asked if anything is known."""
        self.leg = leg
        self.state = self.state.with_alternatives(())
        self._alt_last_key = None
        self.sink_path()
        self.refresh_alternatives()
        if self.threats.any_known():
            self._request(Trigger.MONITOR, self.monotonic_s())

    def end_leg(self) -> None:
        self.leg = None
        self.state = self.state.with_alternatives(())

    # ------------------------------------------------------------------ triggers
    def on_threats_changed(self, received_mono_s: float) -> None:
        """A threat was put or deleted: decide now, or right after the decision under way."""
        self._request(Trigger.THREAT, received_mono_s)

    def monitor(self, now_mono_s: float) -> None:
        """The schedule's monitor task: ask for a decision when something is known (the
        decision first checks the active reference here, in process)."""
        if self.leg is None or self._busy or self._resume_wanted is not None or self.owner.current is None:
            return
        if self.threats.any_known() and not self._still_unanswered(now_mono_s):
            self._request(Trigger.MONITOR, now_mono_s)

    def _still_unanswered(self, now_mono_s: float) -> bool:
        """The last decision found nothing better against a manned aircraft, on the reference
        and the very reports (identity) that the monitor would decide on again, not long ago."""
        if self._unanswered is None:
            return False
        ref, reports, until_s = self._unanswered
        same = (
            ref is self.owner.current
            and now_mono_s < until_s
            and same_reports(reports, tuple(self.threats.threats_at(self.now_s())))
        )
        if not same:
            self._unanswered = None
        return same

    def request_resume(self, answered: Callable[[object], None]) -> None:
        """Plan back to the leg's goal (the reference ended short of it); ``answered(decision)``
        is called with the outcome (kind ``none``: no clear way back yet; None: outside a leg)."""
        if self.leg is None or self.owner.current is None:
            answered(None)
            return
        self._resume_wanted = answered
        if not self._busy:
            self._next()

    # ------------------------------------------------------------------ deciding
    def _request(self, trigger: Trigger, trigger_mono_s: float) -> None:
        if self.leg is None or self.owner.current is None:
            return
        if self._busy:
            if self._queued is None:
                self._queued = (trigger, trigger_mono_s)
            return
        self._start(trigger, trigger_mono_s, None)

    def _observation(self, trigger: Trigger) -> Observation:
        t = self.now_s()
        return Observation(t, tuple(self.threats.threats_at(t)), active_trajectory(self.owner.current), trigger)

    def _start(self, trigger: Trigger, trigger_mono_s: float, answered: Callable | None) -> None:
        obs = self._observation(trigger)
        if trigger is not Trigger.RESUME and self._stays_clear(obs):
            self._next()  # the usual tick or report: nothing for a worker to do
            return
        self._busy = True
        asked = (self.leg, self.owner.current, self.state, obs.threats)
        timing = _Timing(trigger_mono_s, self.monotonic_s())
        self.jobs.submit(
            "decision",
            self.steps.decide,
            (self.state, obs, self.leg, self.policy),
            done=functools.partial(self._decided, asked, trigger, timing, answered),
            failed=functools.partial(self._failed, answered),
        )
        if trigger is not Trigger.RESUME and self.alerts is not None:
            self.alerts.check()  # a conflict: told while the decision is made

    def _stays_clear(self, obs: Observation) -> bool:
        """The active reference stays clear of the observed threats: proven by the screen
        (``screen.MonitorScreen``: exact, from the reference's table), else by ``active_conflict``."""
        try:
            return self._screened(obs) or self.steps.active_conflict(obs, self.leg, self.policy) is None
        except Exception:  # noqa: BLE001 - the decision will say what is wrong
            log.debug("monitor pre-check failed", exc_info=True)
            return False

    def _screened(self, obs: Observation) -> bool:
        if obs.active is None:
            return False
        assert self.leg is not None  # a decision starts with a leg (_request)
        return self.screen.proves_clear(obs.active, obs.threats, obs.t_s, self.leg.world.dim)

    def _decided(self, asked, trigger: Trigger, timing: _Timing, answered, result) -> None:
        leg, ref, sent, reports = asked
        timing.returned_s = self.monotonic_s()
        self._busy = False
        decision = None
        try:
            decision, state = result
            self._adopt(state, sent)
            self._unanswered = (
                (ref, reports, timing.returned_s + MANNED_REDECIDE_S) if _manned_unanswered(decision, reports) else None
            )
            if leg is self.leg and ref is self.owner.current:
                self._apply(decision, trigger, timing)
            elif self.owner.current is not None:
                log.info("decision %s dropped: the reference changed while deciding", decision.kind)
        except Exception:  # noqa: BLE001 - a failed decision must not stop the flight
            log.exception("threat decision failed; the current reference is kept")
            decision = None
        if answered is not None:
            answered(decision)
        self._next()

    def _failed(self, answered, error: BaseException) -> None:
        log.error("threat decision failed; the current reference is kept: %r", error)
        self._busy = False
        if answered is not None:
            answered(None)
        self._next()

    def _adopt(self, returned: DecisionState, sent: DecisionState) -> None:
        """Take a job's state; alternatives that arrived meanwhile are kept."""
        if self.state is sent:
            self.state = returned
        else:
            self.state = dataclasses.replace(
                returned, alternatives=self.state.alternatives, counter=max(returned.counter, self.state.counter)
            )

    def _next(self) -> None:
        """Start what waits: a resume first, then the folded triggers."""
        if self._busy:
            return
        if self._resume_wanted is not None:
            answered, self._resume_wanted = self._resume_wanted, None
            if self.leg is None or self.owner.current is None:
                answered(None)
            else:
                self._start(Trigger.RESUME, self.monotonic_s(), answered)
            return
        if self._queued is not None:
            (trigger, mono), self._queued = self._queued, None
            self._request(trigger, mono)

    # ------------------------------------------------------------------ engaging and telling
    def _apply(self, decision, trigger: Trigger, timing: _Timing) -> None:
        """Engage the decision's trajectory (after the delay check), then tell it; a decision
        without a new reference (``none``) is logged only."""
        if decision.trajectory is None:
            log.debug(
                "threat check (%s): %s %s (%.1f ms)",
                trigger.value,
                decision.kind.value,
                decision.reason,
                decision.decide_ms,
            )
            return
        current = self.owner.current
        proceed = functools.partial(self._commit, decision, trigger, timing, current)
        if self.commit_gate is None:
            proceed()
        else:
            self.commit_gate.check(decision, proceed)

    def _commit(self, decision, trigger: Trigger, timing: _Timing, expected) -> None:
        if self.owner.current is not expected:
            log.info("decision %s dropped: the reference changed during the delay check", decision.kind.value)
            return
        timing.engaged_s = self.monotonic_s()
        ref = self.owner.engage(
            decision.trajectory, decision.path_id, t0_s=decision.start_t_s, resume=bool(decision.resume)
        )
        self.send_now()
        if self.send_at is not None and ref.turn_start_s > self.now_s():
            self.send_at(ref.turn_start_s)
        event = self._event(decision, trigger)
        self._told.append(_Pending(ref, decision, event, timing, self.monotonic_s() + FIRST_SETPOINT_WAIT_S))
        self.tell_engaged(self.monotonic_s())
        self.refresh_alternatives()

    def tell_engaged(self, now_mono_s: float) -> None:
        """Tell the engaged decisions whose first setpoint went out (with their latency), or
        that waited longer than ``FIRST_SETPOINT_WAIT_S`` (without); a task of the schedule."""
        if not self._told:
            return
        waiting = []
        for p in self._told:
            sent = p.ref.first_sent_monotonic_s
            if sent is None and now_mono_s < p.deadline_mono_s:
                waiting.append(p)
                continue
            latency_ms = None if sent is None else (sent - p.timing.trigger_s) * 1000.0
            parts = None if sent is None else p.timing.parts_ms(sent, p.decision.decide_ms)
            if latency_ms is not None:
                self.latencies_ms.setdefault(p.decision.kind.value, []).append(latency_ms)
            self._publish(p.decision, {**p.event, "latency_ms": latency_ms, "latency_parts_ms": parts})
        self._told = waiting

    def _event(self, decision, trigger: Trigger) -> dict:
        return {
            **decision.as_event(),
            "label": decision.label or decision.kind.value,
            "trigger": trigger.value,
            "latency_ms": None,
            "t_s": self.now_s(),
            "pos_ned_m": self.position_ned_m(),
            "leg": None if self.leg is None else self.leg.index,
        }

    def _publish(self, decision, event: dict) -> None:
        self.decisions += 1
        log.warning(
            "decision %s (%s, %s): %s (latency %s ms, decide %.1f ms, plan %.1f ms)",
            event["event"],
            event["label"],
            event["trigger"],
            decision.reason,
            "n/a" if event["latency_ms"] is None else f"{event['latency_ms']:.1f}",
            decision.decide_ms,
            decision.plan_ms,
        )
        self.sink.decision(decision, event)
        if self.alerts is not None:
            self.alerts.decided(decision)
        self.sink_path()

    def sink_path(self) -> None:
        """Publish the active reference and the alternatives (``uav/<sysid>/path``)."""
        if self.leg is not None:
            self.sink.path(self.owner.current, self.state.alternatives, self.leg.index)

    # ------------------------------------------------------------------ alternatives
    def refresh_alternatives(self, now_mono_s: float | None = None) -> None:
        """Plan the M-GART alternatives again from the current reference, as a job (also the
        schedule's periodic task)."""
        if self.leg is None or self.alternatives_plan.k == 0 or not self.policy.strategy.switches:
            return
        if self._alt_busy:
            self._alt_dirty = True
            return
        self._plan_alternatives()

    def _plan_alternatives(self) -> None:
        plan = self.alternatives_plan
        assert self.leg is not None  # refresh_alternatives checks
        obs = self._observation(Trigger.MONITOR)
        ref = self.owner.current
        # planned again when the reference or the set of threats known changes, not on every
        # report of a threat already known: a switch is judged against the threats' latest
        # prediction anyway (candidates.switch_to_alternatives)
        key = (self.leg.index, None if ref is None else ref.path_id, frozenset(t.uid for t in obs.threats))
        if key == self._alt_last_key:
            self.alternatives_skipped += 1
            return
        start = None if ref is None else ref.state(obs.t_s + plan.lead_s)[0]
        self._alt_busy, self._alt_dirty = True, False
        fn = functools.partial(self.steps.plan_alternatives, max_time_s=plan.budget_s, start_ned_m=start)
        self.jobs.submit(
            "alternatives",
            fn,
            (self.state, obs, self.leg, self.policy, plan.k),
            done=functools.partial(self._alternatives_done, self.leg, self.state, key, obs.t_s),
            failed=self._alternatives_failed,
        )

    def _alternatives_done(self, leg: LegContext, sent, key, t_s: float, result) -> None:
        alternatives, state = result
        self._alt_busy = False
        if leg is self.leg and alternatives:  # none found: keep the previous ones
            base = state if self.state is sent else self.state
            self.state = dataclasses.replace(
                base.with_alternatives(alternatives), counter=max(state.counter, self.state.counter)
            )
            self._alt_last_key = key
            self.sink_path()
            self.sink.record("alternatives", leg=leg.index, t_s=t_s, paths=[a.path_ned_m for a in alternatives])
        else:
            self._alt_last_key = None
        if self._alt_dirty and self.leg is not None:
            self.refresh_alternatives()

    def _alternatives_failed(self, error: BaseException) -> None:
        log.error("refreshing the alternatives failed: %r", error)
        self._alt_busy = False


def _manned_unanswered(decision, reports) -> bool:
    """``decision`` kept the reference although it meets a manned aircraft of ``reports``."""
    if decision.trajectory is not None or decision.conflict is None:
        return False
    return any(getattr(th, "uid", None) == decision.conflict.threat_id and is_manned(th) for th in reports)
