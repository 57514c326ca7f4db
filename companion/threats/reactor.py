"""The daemon's side of threat management: threats in, decisions out (DESIGN sections 6 and 7).

``ThreatReactor`` connects the zenoh ``ThreatBus``, the ``ThreatTable`` and one
``ThreatManager`` per flight to the daemon through a few callables (it never sees the daemon):

- **Threats in.** zenoh samples arrive on the event loop (``ThreatBus.inbound.subscribe(loop=...)``);
  every PUT or DELETE updates the table and asks the manager for a decision. A threat the
  companion learns itself (an ADS-B report, ``companion.threats.transport.adsb``) goes through
  :meth:`ThreatReactor.on_local_threat`: the very same path as a PUT, then it is republished on
  ``uav/<sysid>/threats/<id>`` for the other processes (never back to this one).
- **Other vehicles** (``fleet.enabled``; ``companion.fleet``). ``FleetLink`` publishes the
  active reference on ``uav/<sysid>/trajectory`` whenever one is engaged and twice a second, and
  turns the others' into threats: ``threats_now`` is the table's threats plus theirs.
- **Monitor** (DESIGN 7.3). While a leg is flown and any threat or other vehicle is known, the
  active reference is re-checked every ``monitor_period_s`` of wall-clock time (default 0.1 s,
  >= 10 Hz), in this process (``manager.check``); only a conflict goes to a worker for a
  decision. A tick is skipped while a decision is under way.
- **One decision at a time**, in a worker thread (``in_worker``): updates that arrive meanwhile
  are folded into the next decision (the newest table always wins). A decision of kind
  ``none`` (the reference stays clear, or no way back yet) publishes nothing.
- **Resume** (DESIGN 7.4). The reactor never asks the same question again by itself: when the
  active reference has ended short of the leg's goal (an ``evade`` or ``hold``), the daemon's
  flight-phase logic (``companion.flight.phases``) calls :meth:`ThreatReactor.resume`, which asks
  ``manager.resume`` for a way back to the mission.
- **Delay check.** With other vehicles known, a decision's trajectory is first published as
  pending and flown only if it still clears them after the communication delay (RMADER).
- **Tell** (DESIGN 7.5). A decision with a trajectory becomes the active reference from the
  manager's start time (``engage``), so the setpoint does not jump; its latency runs from the
  trigger (threat receipt on the zenoh thread, monitor tick, or resume request) to the first
  setpoint of the new trajectory handed to the vehicle link. It is published on
  ``uav/<sysid>/events`` (with ``trigger`` and ``label``) and ``uav/<sysid>/path``, written to
  the flight record, and sent to the ground stations as a short STATUSTEXT
  (``companion.threats.statustext``). Rejected threats are published, recorded and told the same way.
- **Alternatives.** M-GART alternatives are refreshed in the background at every leg start,
  after every decision and every ``flight.alternatives_period_s`` (mission time), from the
  reference ``alternatives_lead_s`` ahead (entry nodes the vehicle can still reach).

Everything but the manager's work runs on the event loop thread. ``ThreatReactor`` (this
module: set-up and threats in) is made of ``reactor_decisions`` (decide, monitor, resume, tell)
and ``reactor_legs`` (legs, alternatives, the published path).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from typing import Callable

import numpy as np

from companion.errors import CompanionError
from companion.flight.pipeline import TrajectoryPipeline
from companion.geo import GeoError, LocalFrame
from companion.threats.transport.bus import ThreatBus
from companion.threats.model import ThreatTable
from companion.threats.decision.policy import ThreatManager
from companion.threats.reactor_decisions import ReactorDecisions
from companion.threats.reactor_legs import LegsAndAlternatives
from companion.threats.statustext import statustext_for
from companion.threats.transport.update import ThreatUpdate, rejected_event

#: At most one STATUSTEXT about rejected threat samples per this many seconds (wall clock): a
#: flood of junk must not flood the vehicle's links (every rejection is still published and
#: recorded).
REJECTED_TEXT_PERIOD_S = 2.0

__all__ = ["ThreatReactor", "MONITOR_PERIOD_S"]

log = logging.getLogger(__name__)

#: Wall-clock period of the continuous re-check of the active reference (s): >= 10 Hz.
MONITOR_PERIOD_S = 0.1


class ThreatReactor(ReactorDecisions, LegsAndAlternatives):
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
        Default ``ThreatBus.from_settings(settings.zenoh, clock=clock_now_s)``; stamped with
        this clock, opened at ``start``.
    keep_bus_open : bool
        The bus outlives this flight (``companion serve``'s session): ``stop`` only
        unsubscribes, it does not close it.
    manager_factory : callable (leg) -> ThreatManager, optional
        Builds the flight's manager at the first leg (default: a ``ThreatManager`` from
        ``settings``).
    monitor_period_s : float
        See :data:`MONITOR_PERIOD_S`.
    pause : callable (delay_s) -> awaitable, optional
        How the monitor and the fleet's publication wait (default ``asyncio.sleep``; the daemon
        gives ``CompanionDaemon.pause``: in the setpoint stream's wake-ups while it runs).
    on_table_change : callable (threats, now_t_s), optional
        Called on the loop after every PUT or DELETE (and a restore) with the threats held and
        the mission time: the daemon's threat snapshot (``companion.threats.snapshot``).
    """

    def __init__(self, settings, *, clock_now_s: Callable[[], float], in_worker, rng: np.random.Generator,
                 engage: Callable, send_now: Callable[[], None], reference: Callable,
                 position_ned_m: Callable, record: Callable, statustext: Callable | None = None,
                 bus: ThreatBus | None = None, manager_factory: Callable | None = None,
                 monitor_period_s: float = MONITOR_PERIOD_S, on_table_change: Callable | None = None,
                 keep_bus_open: bool = False, pause: Callable = asyncio.sleep):
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
        self.keep_bus_open = keep_bus_open
        self.bus = bus if bus is not None else ThreatBus.from_settings(settings.zenoh, clock=clock_now_s)
        self.bus.clock = clock_now_s
        self.manager_factory = manager_factory or self._default_manager
        self.monitor_period_s = float(monitor_period_s)
        self.pause = pause
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
        self.fleet = None

    def _default_manager(self, leg) -> ThreatManager:
        s = self.settings
        return ThreatManager(leg.world, leg.goal_ned_m, settings=s.threats,
                             pipeline=TrajectoryPipeline.from_settings(s.smoothing, s.planning), rng=self.rng,
                             time_scale=s.link.time_scale)

    # ------------------------------------------------------------------ lifecycle
    async def start(self, home_lla) -> None:
        """Open the bus, subscribe to threats, serve the threat list, start the monitor."""
        self.table.set_home(LocalFrame(*home_lla))
        self.bus.open()
        self.bus.inbound.subscribe(self.on_update, loop=asyncio.get_running_loop())
        self.bus.outbound.serve_threats(lambda: self.table.snapshot(self.clock_now_s()))
        loop = asyncio.get_running_loop()
        for coro in (self._monitor(), self._refresh_alternatives_periodically()):
            self._tasks.append(loop.create_task(coro, name=coro.__name__))
        if self.settings.fleet.enabled:
            from companion.fleet.link import FleetLink

            self.fleet = FleetLink(self.settings, self.bus.session, self.bus.sysid, home_lla,
                                   clock_now_s=self.clock_now_s, reference=self.reference,
                                   position_ned_m=self.position_ned_m, pause=self.pause)
            self.fleet.start(loop)

    async def stop(self) -> None:
        """Stop the background tasks; close the bus, or only unsubscribe with ``keep_bus_open``."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        if self.fleet is not None:
            await self.fleet.stop()
        if self.keep_bus_open:
            self.bus.unsubscribe()
        else:
            self.bus.close()

    def publish_status(self, status: dict) -> None:
        """Publish ``status`` (``uav/<sysid>/status``) with the number of threats held."""
        self.table.expire(self.clock_now_s())
        status["threats"] = len(self.table)
        self.bus.outbound.publish_status(status)

    def latency_summary(self) -> dict:
        """Per decision kind: n, p50, p99 and max of the measured latencies (ms)."""
        return {kind: {"n": len(v), "p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)),
                       "max": float(np.max(v))} for kind, v in self.latencies_ms.items()}

    # ------------------------------------------------------------------ threats in
    def threats_now(self, t_s: float) -> list:
        """Every threat to decide on at mission time ``t_s``: the table's and the other vehicles'."""
        held = self.table.snapshot(t_s)
        return held if self.fleet is None else [*held, *self.fleet.threats(t_s)]

    def has_threats(self) -> bool:
        """Anything to monitor: a threat held, or another vehicle known."""
        return bool(len(self.table)) or (self.fleet is not None and len(self.fleet.peers) > 0)

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
        """Put threats known before a restart (``companion.threats.snapshot``) back in the table, times
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
            self.bus.outbound.republish_threat(threat)
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
        self.bus.outbound.publish_event(event)
        self.record("decision", kind="rejected", reason=event.get("reason"), t_s=event["t_s"],
                    field=event.get("field"), threat_id=event.get("threat_id"), source=event.get("source"))
        if time.monotonic() - self._rejected_told_s >= REJECTED_TEXT_PERIOD_S:
            self._rejected_told_s = time.monotonic()     # a flood of junk: one line per period
            self._tell(*statustext_for("rejected", str(event.get("field") or ""), event.get("threat_id"), None))
