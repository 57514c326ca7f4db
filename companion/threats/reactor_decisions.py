"""The reactor's decisions (DESIGN 7.3 to 7.5): one at a time in a planning worker (the pure
``decide`` on the reactor's state, an observation of the daemon's reference, the leg and the
policy; the state that comes back adopted), updates that arrive meanwhile folded into the next
one; the >= 10 Hz monitor of the active reference; a way back to the mission on request
(``resume``); a decision engaged, its latency measured from the trigger to the first setpoint of
the new trajectory, then published, recorded and told."""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import replace
from typing import Callable

from companion.errors import CompanionError
from companion.threats.decision.kinds import DecisionKind, Trigger
from companion.threats.decision.step import (ActiveTrajectory, DecisionPolicy, DecisionState, LegContext,
                                             Observation, active_conflict, decide)
from companion.threats.model import ThreatTable
from companion.threats.statustext import statustext_for

log = logging.getLogger(__name__)

#: How long to wait for the first setpoint of a new reference (latency measurement, s).
FIRST_SETPOINT_WAIT_S = 1.0


class ReactorDecisions:
    """The decisions of a ``ThreatReactor`` (a part of it: it uses the reactor's table, policy,
    decision state, leg, callables and bus, and ``publish_path`` and ``refresh_alternatives``)."""

    settings: object
    table: ThreatTable
    policy: DecisionPolicy
    decision_state: DecisionState | None
    leg_context: LegContext | None
    leg: object
    leg_index: int
    decisions: int
    latencies_ms: dict[str, list[float]]
    monitor_period_s: float
    pause: Callable
    clock_now_s: Callable[[], float]
    in_worker: Callable
    engage: Callable
    send_now: Callable[[], None]
    reference: Callable
    position_ned_m: Callable
    record: Callable
    statustext: Callable | None
    fleet: object
    threats_now: Callable
    has_threats: Callable
    _busy: bool
    _resume_waiting: bool
    _pending: tuple[float, str] | None

    def schedule(self, trigger_mono_s: float, trigger: str = "threat") -> None:
        """Decide now, or right after the decision under way (with the newest threats).

        Outside a leg, or without an active reference (the daemon holds where the vehicle is
        after a link loss), nothing is decided: the next reference is checked when engaged.
        """
        if self.leg_context is None or self.leg is None or self.reference() is None:
            return
        if self._busy:
            if self._pending is None:
                self._pending = (trigger_mono_s, trigger)
            return
        self._busy = True
        asyncio.get_running_loop().create_task(self._decide(trigger_mono_s, trigger), name="threat-decision")

    async def resume(self):
        """Ask for a way back to the leg's goal (the reference ended short of it).

        Waits for the decision under way, if any. Returns the Decision (kind ``none`` with
        ``resume`` True when there is no clear way back yet: ask again later), or None outside a
        leg.
        """
        if self.leg_context is None or self.leg is None or self.reference() is None:
            return None
        self._resume_waiting = True
        try:
            while self._busy:
                await asyncio.sleep(0.005)
        finally:
            self._resume_waiting = False
        self._busy = True
        return await self._decide(time.monotonic(), "resume", resume=True)

    async def _decide(self, trigger_mono_s: float, trigger: str, resume: bool = False):
        """Decisions one after the other until no update is pending; returns the first one."""
        first = None
        try:
            while True:
                leg, leg_context, ref, t = self.leg, self.leg_context, self.reference(), self.clock_now_s()
                if leg_context is None:                 # the leg ended while a decision was pending
                    break
                self.table.expire(t)
                obs = self.observation(t, Trigger.RESUME if resume else Trigger(trigger))
                if trigger == "monitor" and self._stays_clear(obs):
                    pass                                # the usual tick: nothing for a worker to do
                else:
                    sent = self.decision_state
                    decision, state = await self.in_worker(decide, sent, obs, leg_context, self.policy)
                    first = decision if first is None else first
                    if leg is not None and leg is self.leg:
                        self._adopt(sent, state)
                    if leg is not None and leg is self.leg and ref is not None and ref is self.reference():
                        await self.apply(decision, trigger_mono_s, trigger)
                    elif self.reference() is not None:      # the daemon changed the reference meanwhile
                        log.info("decision %s dropped: the reference changed while deciding", decision.kind)
                if self._pending is None:
                    break
                (trigger_mono_s, trigger), self._pending = self._pending, None
                resume = False
        except Exception:  # noqa: BLE001 - a failed decision must not stop the flight
            log.exception("threat decision failed; the current reference is kept")
        finally:
            self._busy = False
        return first

    def observation(self, t_s: float, trigger: Trigger = Trigger.THREAT) -> Observation:
        """What a decision at mission time ``t_s`` sees: every threat then (``threats_now``) and
        the daemon's active reference (``reference()``; ``resume``: it ends short on purpose)."""
        ref = self.reference()
        active = None if ref is None else ActiveTrajectory(ref.trajectory, ref.t0_s, ref.path_id,
                                                           bool(getattr(ref, "resume", False)))
        return Observation(t_s, tuple(self.threats_now(t_s)), active, trigger)

    def _adopt(self, sent: DecisionState, returned: DecisionState) -> None:
        """Take the state a decision returned; alternatives refreshed while it ran are kept (and
        the larger counter, so that no path id is given twice)."""
        current = self.decision_state
        if current is sent:
            self.decision_state = returned
        else:
            self.decision_state = replace(returned, counter=max(current.counter, returned.counter),
                                          alternatives=current.alternatives)

    def _stays_clear(self, obs: Observation) -> bool:
        """The monitor's check of the active reference, here: ``active_conflict`` (the first
        step of ``decide``), a millisecond of numpy instead of a round trip to a worker process
        ten times a second. False when in doubt."""
        try:
            return active_conflict(obs, self.leg_context, self.policy) is None
        except Exception:  # noqa: BLE001 - the worker's decision will say what is wrong
            log.debug("monitor pre-check failed", exc_info=True)
            return False

    async def apply(self, decision, trigger_mono_s: float, trigger: str) -> None:
        """Engage the decision's trajectory, measure its latency, publish, record and tell it.

        Only decisions with a trajectory, and ``rejected``, are published; ``none`` (keep, or no
        way back yet) and a decision without a new reference are logged only.
        """
        if decision.trajectory is None and decision.kind != DecisionKind.REJECTED:
            log.debug("threat check (%s): %s %s (%.1f ms)", trigger, decision.kind, decision.reason,
                      decision.decide_ms)
            return
        latency_ms = None
        kind = str(decision.kind)                         # a plain string in events and records
        if decision.trajectory is not None and self.fleet is not None:
            current = self.reference()
            if not await self.fleet.delay_check(decision.trajectory, decision.start_t_s, decision.path_id):
                return                     # another vehicle's new trajectory conflicts: decide again
            if self.reference() is not current:
                log.info("decision %s dropped: the reference changed during the delay check", decision.kind)
                return
        if decision.trajectory is not None:
            ref = self.engage(decision.trajectory, decision.path_id, t0_s=decision.start_t_s,
                              resume=bool(decision.resume))
            self.send_now()
            deadline = time.monotonic() + FIRST_SETPOINT_WAIT_S
            while ref.first_sent_monotonic_s is None and time.monotonic() < deadline:
                await asyncio.sleep(0.001)
            if ref.first_sent_monotonic_s is not None:
                latency_ms = (ref.first_sent_monotonic_s - trigger_mono_s) * 1000.0
                self.latencies_ms.setdefault(kind, []).append(latency_ms)
        label = getattr(decision, "label", None) or kind
        event = {**decision.as_event(), "label": label, "trigger": trigger, "latency_ms": latency_ms,
                 "t_s": self.clock_now_s(), "pos_ned_m": self.position_ned_m(), "leg": self.leg_index}
        if "threat_id" in event:
            event["source"] = self.source_of(event["threat_id"])
        self.decisions += 1
        log.warning("decision %s (%s, %s): %s (latency %s ms, decide %.1f ms, plan %.1f ms, seed %d)",
                    kind, label, trigger, decision.reason,
                    "n/a" if latency_ms is None else f"{latency_ms:.1f}", decision.decide_ms,
                    decision.plan_ms, self.settings.seed)
        self.bus.publish_event(event)
        self.record("decision", kind=kind, path_ned_m=decision.path_ned_m, **event)
        threat_id = decision.conflict.threat_id if decision.conflict is not None else None
        self._tell(*statustext_for(kind, label, threat_id, latency_ms))
        self.publish_path()
        self.refresh_alternatives()

    def _tell(self, text: str, severity: str) -> None:
        if self.statustext is None:
            return
        try:
            self.statustext(text, severity)
        except CompanionError as exc:            # e.g. the link is down: the event is published
            log.info("STATUSTEXT %r not sent: %s", text, exc)

    async def _monitor(self) -> None:
        """Re-check the active reference every ``monitor_period_s`` (wall clock) while a leg is
        flown and a threat is known; skip a tick while a decision is under way."""
        next_s = time.monotonic()
        while True:
            next_s = max(next_s + self.monitor_period_s, time.monotonic())
            await self.pause(next_s - time.monotonic())
            if self.leg_context is None or self.leg is None or self._busy or self._resume_waiting \
                    or self.reference() is None:
                continue
            self.table.expire(self.clock_now_s())
            if self.has_threats():
                self.schedule(time.monotonic(), "monitor")
