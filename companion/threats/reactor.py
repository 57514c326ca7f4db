"""The daemon's side of threat management: threats in, decisions out (DESIGN sections 6 and 7).

``ThreatReactor`` connects the zenoh ``ThreatBus``, the ``ThreatTable`` and one
``ThreatManager`` per flight to the daemon through a few callables (it never sees the daemon):

- **Threats in.** zenoh samples arrive on the event loop (``ThreatBus.subscribe(loop=...)``);
  every PUT or DELETE updates the table and asks the manager for a decision. A threat the
  companion learns itself (an ADS-B report, ``companion.threats.adsb``) goes through
  :meth:`ThreatReactor.on_local_threat`: the very same path as a PUT, then it is republished on
  ``uav/<sysid>/threats/<id>`` for the other processes (never back to this one).
- **Monitor** (DESIGN 7.3). While a leg is flown and any threat is known, the active reference
  is re-checked every ``monitor_period_s`` of wall-clock time (default 0.1 s, >= 10 Hz), on the
  same path as a threat update; a tick is skipped while a decision is under way.
- **One decision at a time**, in a worker thread (``in_worker``): updates that arrive meanwhile
  are folded into the next decision (the newest table always wins). A decision of kind
  ``none`` (the reference stays clear, or no way back yet) publishes nothing.
- **Resume** (DESIGN 7.4). The reactor never asks the same question again by itself: when the
  active reference has ended short of the leg's goal (an ``evade`` or ``hold``), the daemon's
  flight-phase logic (``companion.phases``) calls :meth:`ThreatReactor.resume`, which asks
  ``manager.resume`` for a way back to the mission.
- **Tell** (DESIGN 7.5). A decision with a trajectory becomes the active reference from the
  manager's start time (``engage``), so the setpoint does not jump; its latency runs from the
  trigger (threat receipt on the zenoh thread, monitor tick, or resume request) to the first
  setpoint of the new trajectory handed to the vehicle link. It is published on
  ``uav/<sysid>/events`` (with ``trigger`` and ``label``) and ``uav/<sysid>/path``, written to
  the flight record, and sent to the ground stations as a short STATUSTEXT
  (:func:`statustext_for`). Rejected threats are published, recorded and told the same way.
- **Alternatives.** M-GART alternatives are refreshed in the background at every leg start,
  after every decision and every ``flight.alternatives_period_s`` (mission time), from the
  reference ``alternatives_lead_s`` ahead (entry nodes the vehicle can still reach).

Everything but the manager's work runs on the event loop thread.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from typing import Callable

import numpy as np

from companion.errors import CompanionError
from companion.geo import GeoError, LocalFrame
from companion.threats.bus import ThreatBus
from companion.threats.update import ThreatUpdate, rejected_event
from companion.threats.model import ThreatTable
from companion.threats.policy import ThreatManager

#: At most one STATUSTEXT about rejected threat samples per this many seconds (wall clock): a
#: flood of junk must not flood the vehicle's links (every rejection is still published and
#: recorded).
REJECTED_TEXT_PERIOD_S = 2.0

__all__ = ["ThreatReactor", "statustext_for", "MONITOR_PERIOD_S", "STATUSTEXT_MAX_CHARS"]

log = logging.getLogger(__name__)

#: Wall-clock period of the continuous re-check of the active reference (s): >= 10 Hz.
MONITOR_PERIOD_S = 0.1
#: STATUSTEXT carries at most 50 characters.
STATUSTEXT_MAX_CHARS = 50
#: Decisions told to the ground stations as a WARNING (the others as a NOTICE).
WARNING_KINDS = frozenset({"evade", "hold", "rejected"})
#: How long to wait for the first setpoint of a new reference (latency measurement, s).
FIRST_SETPOINT_WAIT_S = 1.0


def statustext_for(kind: str, label: str, threat_id: str | None,
                   latency_ms: float | None) -> tuple[str, str]:
    """The STATUSTEXT of one published decision and its severity.

    Parameters
    ----------
    kind : str
        The decision's kind (``evade``, ``replan``, ``rejected`` ...).
    label : str
        Its short label, e.g. ``"evade left"`` (the kind when the manager gives none).
    threat_id : str or None
        The threat that caused it; None for a plan back to the mission.
    latency_ms : float or None
        Trigger to first setpoint (ms), when measured.

    Returns
    -------
    (str, str)
        The text, at most ``STATUSTEXT_MAX_CHARS`` characters (the label is shortened first,
        the latency kept), e.g. ``"AVOID m1: evade left, 31 ms"``; and the severity name,
        ``"WARNING"`` for an evasion, a hold or a rejected threat, else ``"NOTICE"``.

    Examples
    --------
    >>> statustext_for("replan", "replan", "p1", 140.2)
    ('AVOID p1: replan, 140 ms', 'NOTICE')
    """
    if kind == "rejected":
        head = f"THREAT {threat_id or '?'} rejected"
    else:
        head = f"AVOID {threat_id}" if threat_id else "RESUME"
    tail = "" if latency_ms is None else f", {latency_ms:.0f} ms"
    text = f"{head}: {label}" if label else head
    text = text[:STATUSTEXT_MAX_CHARS - len(tail)] + tail
    return text, "WARNING" if kind in WARNING_KINDS else "NOTICE"


class ThreatReactor:
    """Threats in, decisions out, for one flight (see the module docstring).

    Parameters
    ----------
    settings : companion.config.Settings
        Uses ``zenoh`` (the bus), ``threats``, ``smoothing``, ``gart`` (the manager), ``flight``
        (alternatives) and ``seed`` (logged with every decision).
    clock_now_s : callable () -> float
        Mission time now (s; the vehicle's clock): threats are stamped with it.
    in_worker : coroutine function (fn, *args, **kwargs)
        Runs ``fn`` in a planning thread and returns its result.
    rng : numpy.random.Generator
        The flight's generator (the manager's and the alternatives' seeds come from it).
    engage : callable (trajectory, path_id, *, t0_s, resume) -> reference
        Makes a decision's trajectory the active reference from mission time ``t0_s``
        (``resume``: it stops short on purpose) and returns it; the reference's
        ``first_sent_monotonic_s`` is set when the setpoint stream first samples it.
    send_now : callable ()
        Sends the current setpoint at once (the new reference's first setpoint).
    reference : callable () -> reference or None
        The active reference (``trajectory``, ``t0_s``, ``path_id``, ``state(t_s)``).
    position_ned_m : callable () -> ndarray (3,) or None
        The vehicle's position (for the events).
    record : callable (line_type, **fields)
        Writes one line of the flight record.
    statustext : callable (text, severity_name) or None
        Sends a STATUSTEXT to the ground stations (through the vehicle); None: not told.
    bus : ThreatBus, optional
        Default ``ThreatBus.from_settings(settings.zenoh, clock=clock_now_s)``.
    manager_factory : callable (leg) -> ThreatManager, optional
        Builds the flight's manager at the first leg (default: a ``ThreatManager`` from
        ``settings``).
    monitor_period_s : float
        See :data:`MONITOR_PERIOD_S`.
    on_table_change : callable (threats, now_t_s), optional
        Called on the loop after every PUT or DELETE (and a restore) with the threats held and
        the mission time: the daemon's threat snapshot (``companion.state``).
    """

    def __init__(self, settings, *, clock_now_s: Callable[[], float], in_worker, rng: np.random.Generator,
                 engage: Callable, send_now: Callable[[], None], reference: Callable,
                 position_ned_m: Callable, record: Callable, statustext: Callable | None = None,
                 bus: ThreatBus | None = None, manager_factory: Callable | None = None,
                 monitor_period_s: float = MONITOR_PERIOD_S, on_table_change: Callable | None = None):
        self.settings = settings
        self.clock_now_s = clock_now_s
        self.in_worker = in_worker
        self.rng = rng
        self.engage = engage
        self.send_now = send_now
        self.reference = reference
        self.position_ned_m = position_ned_m
        self.record = record
        self.statustext = statustext
        self.bus = bus if bus is not None else ThreatBus.from_settings(settings.zenoh, clock=clock_now_s)
        self.manager_factory = manager_factory or self._default_manager
        self.monitor_period_s = float(monitor_period_s)
        self.on_table_change = on_table_change
        self.table = ThreatTable()
        self.manager = None
        self.leg = None
        self.leg_index = -1
        self.decisions = 0
        self.latencies_ms: dict[str, list[float]] = {}
        self._busy = False
        self._rejected_told_s = -math.inf
        self._resume_waiting = False
        self._pending: tuple[float, str] | None = None
        self._alt_busy = False
        self._alt_dirty = False
        self._local_seq = 0
        self._tasks: list[asyncio.Task] = []

    def _default_manager(self, leg) -> ThreatManager:
        s = self.settings
        return ThreatManager(leg.world, leg.goal_ned_m, settings=s.threats, limits=s.smoothing.limits,
                             kappa_max_1_m=s.smoothing.kappa_max_1_m, gart_settings=s.gart, rng=self.rng,
                             time_scale=s.link.time_scale)

    # ------------------------------------------------------------------ lifecycle
    async def start(self, home_lla) -> None:
        """Open the bus, subscribe to threats, serve the threat list, start the monitor."""
        self.table.set_home(LocalFrame(*home_lla))
        self.bus.open()
        self.bus.subscribe(self.on_update, loop=asyncio.get_running_loop())
        self.bus.serve_threats(lambda: self.table.snapshot(self.clock_now_s()))
        loop = asyncio.get_running_loop()
        for coro in (self._monitor(), self._refresh_alternatives_periodically()):
            self._tasks.append(loop.create_task(coro, name=coro.__name__))

    async def stop(self) -> None:
        """Stop the background tasks and close the bus."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        self.bus.close()

    def publish_status(self, status: dict) -> None:
        """Publish ``status`` (``uav/<sysid>/status``) with the number of threats held."""
        self.table.expire(self.clock_now_s())
        status["threats"] = len(self.table)
        self.bus.publish_status(status)

    def latency_summary(self) -> dict:
        """Per decision kind: n, p50, p99 and max of the measured latencies (ms)."""
        return {kind: {"n": len(v), "p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)),
                       "max": float(np.max(v))} for kind, v in self.latencies_ms.items()}

    # ------------------------------------------------------------------ threats in
    def on_update(self, update: ThreatUpdate) -> None:
        """One zenoh sample (on the loop): store it, then decide."""
        if update.action == "rejected":
            self.reject(rejected_event(update))
            return
        if update.action == "delete":
            known = self.table.delete(update.uid)
            self.record("threat", id=update.uid, source=update.source, removed=True, known=known,
                        t_s=update.received_t_s)
            log.info("threat %s removed by %s%s", update.uid, update.source, "" if known else " (was not known)")
        else:
            try:
                self.table.put(update.threat)
            except (CompanionError, GeoError) as exc:   # e.g. a global threat before home
                self.reject({"event": "rejected", "threat_id": update.uid, "source": update.source,
                             "field": getattr(exc, "field", "payload"), "reason": str(exc)})
                return
            th = self.table.get(update.uid)
            self.record("threat", id=th.uid, source=th.source, kind=th.kind, position_ned_m=th.pos_ned_m,
                        velocity_ned_m_s=th.velocity_ned_m_s, radius_m=th.radius_m, t_s=update.received_t_s)
        self.table_changed()
        self.schedule(update.received_mono_s, "threat")

    def table_changed(self) -> None:
        """Tell ``on_table_change`` (the snapshot) the threats now held."""
        if self.on_table_change is None:
            return
        now = self.clock_now_s()
        try:
            self.on_table_change(self.table.snapshot(now), now)
        except Exception:  # noqa: BLE001 - the snapshot is a courtesy; the flight goes on
            log.exception("threat table change handler failed")

    def restore(self, threats) -> list[str]:
        """Put threats known before a restart (``companion.state``) back in the table, times
        unchanged (the remaining TTL is kept); recorded with ``restored=True``. Returns their ids.
        Decided on at the next leg start (``on_leg_started``), like any threat held then."""
        ids = []
        for th in threats:
            self.table.put(th)
            ids.append(th.id)
            self.record("threat", id=th.id, kind=th.kind, position_ned_m=th.pos_ned_m,
                        velocity_ned_m_s=th.velocity_ned_m_s, radius_m=th.radius_m,
                        t_s=th.received_t_s, expires_t_s=th.expires_t_s, restored=True)
        self.table_changed()
        return ids

    def on_local_threat(self, threat, received_mono_s: float | None = None) -> None:
        """A threat this process learnt itself (e.g. ADS-B; on the loop): stored and decided
        exactly as a zenoh PUT (:meth:`on_update`), then republished for other consumers."""
        self._local_seq += 1
        update = ThreatUpdate("put", threat.id, threat, None, self.bus.key(f"threats/{threat.id}"),
                              threat.received_t_s,
                              time.monotonic() if received_mono_s is None else received_mono_s,
                              self._local_seq)
        self.on_update(update)
        try:
            self.bus.republish_threat(threat)
        except Exception as exc:  # noqa: BLE001 - republishing is a courtesy; the flight goes on
            log.info("threat %s not republished: %s", threat.id, exc)

    def source_of(self, threat_uid: str | None) -> str | None:
        """Who put the threat ``threat_uid`` (its ``Threat.source``); None for the static world
        or a threat no longer held."""
        threat = self.table.get(threat_uid) if threat_uid is not None else None
        return threat.source if threat is not None else None

    def reject(self, event: dict) -> None:
        """Publish, record and tell a rejected threat sample (the flight goes on)."""
        event = {**event, "t_s": self.clock_now_s()}
        log.warning("threat rejected: %s", event.get("reason"))
        self.decisions += 1
        self.bus.publish_event(event)
        self.record("decision", kind="rejected", reason=event.get("reason"), t_s=event["t_s"],
                    field=event.get("field"), threat_id=event.get("threat_id"), source=event.get("source"))
        if time.monotonic() - self._rejected_told_s >= REJECTED_TEXT_PERIOD_S:
            self._rejected_told_s = time.monotonic()     # a flood of junk: one line per period
            self._tell(*statustext_for("rejected", str(event.get("field") or ""), event.get("threat_id"), None))

    # ------------------------------------------------------------------ decisions
    def schedule(self, trigger_mono_s: float, trigger: str = "threat") -> None:
        """Decide now, or right after the decision under way (with the newest threats).

        Outside a leg, or without an active reference (the daemon holds where the vehicle is
        after a link loss), nothing is decided: the next reference is checked when engaged.
        """
        if self.manager is None or self.leg is None or self.reference() is None:
            return
        if self._busy:
            if self._pending is None:
                self._pending = (trigger_mono_s, trigger)
            return
        self._busy = True
        asyncio.get_running_loop().create_task(self._decide(trigger_mono_s, trigger), name="threat-decision")

    async def resume(self):
        """Ask the manager for a way back to the leg's goal (the reference ended short of it).

        Waits for the decision under way, if any. Returns the manager's Decision (kind ``none``
        with ``resume`` True when there is no clear way back yet: ask again later), or None
        outside a leg.
        """
        if self.manager is None or self.leg is None or self.reference() is None:
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
                leg, ref, t = self.leg, self.reference(), self.clock_now_s()
                self.table.expire(t)
                decide = self.manager.resume if resume else self.manager.on_threats
                decision = await self.in_worker(decide, self.table.snapshot(t), t)
                first = decision if first is None else first
                if leg is not None and leg is self.leg and ref is not None and ref is self.reference():
                    await self.apply(decision, trigger_mono_s, trigger)
                elif self.reference() is not None:      # the daemon changed the reference meanwhile
                    log.info("decision %s dropped: the reference changed while deciding", decision.kind)
                    self.set_active(self.reference())
                if self._pending is None:
                    break
                (trigger_mono_s, trigger), self._pending = self._pending, None
                resume = False
        except Exception:  # noqa: BLE001 - a failed decision must not stop the flight
            log.exception("threat decision failed; the current reference is kept")
        finally:
            self._busy = False
        return first

    async def apply(self, decision, trigger_mono_s: float, trigger: str) -> None:
        """Engage the decision's trajectory, measure its latency, publish, record and tell it.

        Only decisions with a trajectory, and ``rejected``, are published; ``none`` (keep, or no
        way back yet) and a decision without a new reference are logged only.
        """
        if decision.trajectory is None and decision.kind != "rejected":
            log.debug("threat check (%s): %s %s (%.1f ms)", trigger, decision.kind, decision.reason,
                      decision.decide_ms)
            return
        latency_ms = None
        if decision.trajectory is not None:
            ref = self.engage(decision.trajectory, decision.path_id, t0_s=decision.start_t_s,
                              resume=bool(decision.resume))
            self.send_now()
            deadline = time.monotonic() + FIRST_SETPOINT_WAIT_S
            while ref.first_sent_monotonic_s is None and time.monotonic() < deadline:
                await asyncio.sleep(0.001)
            if ref.first_sent_monotonic_s is not None:
                latency_ms = (ref.first_sent_monotonic_s - trigger_mono_s) * 1000.0
                self.latencies_ms.setdefault(decision.kind, []).append(latency_ms)
        label = getattr(decision, "label", None) or decision.kind
        event = {**decision.as_event(), "label": label, "trigger": trigger, "latency_ms": latency_ms,
                 "t_s": self.clock_now_s(), "pos_ned_m": self.position_ned_m(), "leg": self.leg_index}
        if "threat_id" in event:
            event["source"] = self.source_of(event["threat_id"])
        self.decisions += 1
        log.warning("decision %s (%s, %s): %s (latency %s ms, decide %.1f ms, plan %.1f ms, seed %d)",
                    decision.kind, label, trigger, decision.reason,
                    "n/a" if latency_ms is None else f"{latency_ms:.1f}", decision.decide_ms,
                    decision.plan_ms, self.settings.seed)
        self.bus.publish_event(event)
        self.record("decision", kind=decision.kind, path_ned_m=decision.path_ned_m, **event)
        threat_id = decision.conflict.threat_id if decision.conflict is not None else None
        self._tell(*statustext_for(decision.kind, label, threat_id, latency_ms))
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
            await asyncio.sleep(next_s - time.monotonic())
            if self.manager is None or self.leg is None or self._busy or self._resume_waiting \
                    or self.reference() is None:
                continue
            self.table.expire(self.clock_now_s())
            if len(self.table):
                self.schedule(time.monotonic(), "monitor")

    # ------------------------------------------------------------------ legs and alternatives
    def set_active(self, ref) -> None:
        """The daemon engaged ``ref`` (any reference): the manager checks that one now
        (``ref.resume``: it ends short of the goal on purpose)."""
        if self.manager is not None:
            self.manager.set_active(ref.trajectory, ref.t0_s, ref.path_id,
                                    ends_short=bool(getattr(ref, "resume", False)))

    def on_leg_started(self, leg, ref) -> None:
        """A leg starts with reference ``ref``: the manager gets its world, goal and reference."""
        if self.manager is None:
            self.manager = self.manager_factory(leg)
        self.manager.set_leg(leg.world, leg.goal_ned_m)
        self.set_active(ref)
        self.manager.set_alternatives([])
        self.leg, self.leg_index = leg, leg.index
        self.publish_path()
        self.refresh_alternatives()
        self.table.expire(self.clock_now_s())
        if len(self.table):
            self.schedule(time.monotonic(), "monitor")

    def on_leg_ended(self) -> None:
        self.leg = None
        if self.manager is not None:
            self.manager.set_alternatives([])

    def refresh_alternatives(self) -> None:
        """Recompute the M-GART alternatives from the current reference in the background."""
        if self.manager is None or self.leg is None or self.settings.flight.alternatives_k == 0:
            return
        if self._alt_busy:
            self._alt_dirty = True
            return
        self._alt_busy = True
        asyncio.get_running_loop().create_task(self._alternatives_loop(), name="alternatives")

    async def _refresh_alternatives_periodically(self) -> None:
        """Keep the alternatives starting just ahead of the vehicle."""
        s = self.settings
        while True:
            await asyncio.sleep(s.flight.alternatives_period_s / s.link.time_scale)
            self.refresh_alternatives()

    async def _alternatives_loop(self) -> None:
        f = self.settings.flight
        try:
            while True:
                self._alt_dirty = False
                leg, t = self.leg, self.clock_now_s()
                if leg is None:
                    break
                threats = self.table.snapshot(t)
                rng = np.random.default_rng(self.rng.integers(2**63))
                ref = self.reference()
                start = None if ref is None else ref.state(t + f.alternatives_lead_s)[0]
                alternatives = await self.in_worker(
                    self.manager.compute_alternatives, threats, t, f.alternatives_k, rng=rng,
                    max_time_s=f.alternatives_budget_s, start_ned_m=start)
                if leg is self.leg and alternatives:     # none found: keep the previous ones
                    self.manager.set_alternatives(alternatives)
                    self.publish_path()
                    self.record("alternatives", leg=leg.index, t_s=t, paths=[a.path_ned_m for a in alternatives])
                if not self._alt_dirty:
                    break
        except Exception:  # noqa: BLE001 - without alternatives the manager replans or holds
            log.exception("refreshing the alternatives failed")
        finally:
            self._alt_busy = False

    def publish_path(self) -> None:
        """Publish the active reference and the alternatives on ``uav/<sysid>/path``."""
        ref = self.reference()
        if ref is None or self.manager is None:
            return
        t = np.linspace(0.0, ref.trajectory.duration_s, max(2, int(ref.trajectory.duration_s * 2)))
        self.bus.publish_path({
            "t_s": self.clock_now_s(), "leg": self.leg_index, "path_id": ref.path_id,
            "t0_s": ref.t0_s, "duration_s": ref.trajectory.duration_s,
            "reference_ned_m": ref.trajectory.sample(t)[0],
            "alternatives": [{"path_id": a.path_id, "path_ned_m": a.path_ned_m}
                             for a in self.manager.alternatives]})

    def min_separation_m(self, pos_ned_m: np.ndarray, t_s: float) -> float:
        """Distance from ``pos_ned_m`` to the surface of the nearest threat now (inf if none)."""
        best = math.inf
        for th in self.table.snapshot(t_s):
            best = min(best, float(np.linalg.norm(th.position_at(t_s) - pos_ned_m)) - th.radius_m)
        return best
