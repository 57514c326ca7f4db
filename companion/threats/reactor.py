"""The daemon's threats in and decisions out over zenoh (DESIGN sections 6 and 7.5).

``ThreatReactor`` connects the zenoh ``ThreatBus`` and the ``ThreatTable`` to the flight
executor's avoidance (``companion.flight.avoidance``), which decides:

- **Threats in.** zenoh samples arrive on the event loop (``bus.inbound.subscribe(loop=...)``);
  every PUT or DELETE updates the table and tells the avoidance (``on_change``). A threat the
  companion learns itself (an ADS-B report, ``companion.threats.transport.adsb``) goes through
  :meth:`ThreatReactor.on_local_threat`: the very same path as a PUT, then it is republished on
  ``uav/<sysid>/threats/<id>`` for the other processes (never back to this one). Rejected
  samples are published, recorded and told.
- **What is known** (the avoidance's ``ThreatSource``): ``threats_at`` is the table's threats
  plus the other vehicles' (``fleet.enabled``; ``companion.fleet``), as tubes along their
  shared trajectories.
- **Decisions out** (``tell_decision``, ``publish_path``, called by the daemon's flight sink):
  ``uav/<sysid>/events`` (with the threat's source), ``uav/<sysid>/path``, and a short
  STATUSTEXT (``companion.threats.statustext``).
- **Other vehicles.** ``FleetLink`` publishes the active reference on ``uav/<sysid>/trajectory``
  (``fleet_publish``, a task of the executor's schedule, and at every new reference) and the
  delay check before a decision is engaged (``commit_gate``).

Everything runs on the event loop thread.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable

import numpy as np

from companion.errors import CompanionError
from companion.geo import GeoError, LocalFrame
from companion.threats.model import ThreatTable
from companion.threats.statustext import statustext_for
from companion.threats.transport.bus import ThreatBus
from companion.threats.transport.update import ThreatUpdate, rejected_event

#: At most one STATUSTEXT about rejected threat samples per this many seconds (wall clock): a
#: flood of junk must not flood the vehicle's links (every rejection is still published and
#: recorded).
REJECTED_TEXT_PERIOD_S = 2.0

__all__ = ["ThreatReactor"]

log = logging.getLogger(__name__)


class ThreatReactor:
    """Threats in, decisions out, for one flight (see the module docstring).

    Parameters
    ----------
    settings : companion.config.Settings
        Uses ``zenoh`` (the bus) and ``fleet``.
    clock_now_s : callable () -> float
        Mission time now (s; the vehicle's clock): threats are stamped with it.
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
    on_table_change : callable (threats, now_t_s), optional
        Called on the loop after every PUT or DELETE (and a restore) with the threats held and
        the mission time: the daemon's threat snapshot (``companion.threats.snapshot``).

    Attributes
    ----------
    on_change : callable (received_monotonic_s) or None
        Told after every PUT or DELETE (the executor's ``Avoidance.on_threats_changed``).
    """

    def __init__(
        self,
        settings,
        *,
        clock_now_s: Callable[[], float],
        record: Callable,
        statustext: Callable | None = None,
        bus: ThreatBus | None = None,
        keep_bus_open: bool = False,
        on_table_change: Callable | None = None,
    ):
        self.settings = settings
        self.clock_now_s = clock_now_s
        self.record = record
        self.statustext = statustext
        self.keep_bus_open = keep_bus_open
        self.bus = bus if bus is not None else ThreatBus.from_settings(settings.zenoh, clock=clock_now_s)
        self.bus.clock = clock_now_s
        self.on_table_change = on_table_change
        self.on_change: Callable[[float], None] | None = None
        self.table = ThreatTable()
        self.fleet = None
        self.rejected = 0
        self._rejected_told_s = -math.inf
        self._local_seq = 0

    # ------------------------------------------------------------------ lifecycle
    async def start(self, home_lla, *, reference: Callable, position_ned_m: Callable) -> None:
        """Open the bus, subscribe to threats, serve the threat list; with ``fleet.enabled``,
        share ``reference()`` (the active reference) with the other vehicles."""
        self.table.set_home(LocalFrame(*home_lla))
        self.bus.open()
        loop = asyncio.get_running_loop()
        self.bus.inbound.subscribe(self.on_update, loop=loop)
        self.bus.outbound.serve_threats(lambda: self.table.snapshot(self.clock_now_s()))
        if self.settings.fleet.enabled:
            from companion.fleet.link import FleetLink

            self.fleet = FleetLink(
                self.settings,
                self.bus.session,
                self.bus.sysid,
                home_lla,
                clock_now_s=self.clock_now_s,
                reference=reference,
                position_ned_m=position_ned_m,
            )
            self.fleet.start(loop)

    async def stop(self) -> None:
        """Close the bus, or only unsubscribe with ``keep_bus_open``."""
        if self.fleet is not None:
            await self.fleet.stop()
        if self.keep_bus_open:
            self.bus.unsubscribe()
        else:
            self.bus.close()

    def commit_gate(self, loop: asyncio.AbstractEventLoop):
        """The fleet's delay check for the executor (None without other vehicles)."""
        if self.fleet is None:
            return None
        from companion.fleet.link import FleetCommitGate

        return FleetCommitGate(self.fleet, loop)

    def fleet_publish(self, now_s: float | None = None) -> None:
        """Publish our trajectory to the other vehicles (the schedule's task; every new reference)."""
        if self.fleet is not None:
            self.fleet.publish()

    def publish_status(self, status: dict) -> None:
        """Publish ``status`` (``uav/<sysid>/status``) with the number of threats held."""
        self.table.expire(self.clock_now_s())
        status["threats"] = len(self.table)
        self.bus.outbound.publish_status(status)

    # ------------------------------------------------------------------ what is known
    def threats_at(self, t_s: float) -> tuple:
        """Every threat to decide on at mission time ``t_s``: the table's and the other vehicles'."""
        self.table.expire(t_s)
        held = self.table.snapshot(t_s)
        return held if self.fleet is None else (*held, *self.fleet.threats(t_s))

    def any_known(self) -> bool:
        """Anything to monitor: a threat held, or another vehicle known."""
        self.table.expire(self.clock_now_s())
        return bool(len(self.table)) or (self.fleet is not None and len(self.fleet.peers) > 0)

    def min_separation_m(self, pos_ned_m: np.ndarray, t_s: float) -> float:
        """Distance from ``pos_ned_m`` to the surface of the nearest threat now (inf if none)."""
        best = math.inf
        for th in self.table.snapshot(t_s):
            best = min(best, float(np.linalg.norm(th.position_at(t_s) - pos_ned_m)) - th.radius_m)
        return best

    # ------------------------------------------------------------------ threats in
    def on_update(self, update: ThreatUpdate) -> None:
        """One zenoh sample (on the loop): store it, then tell the avoidance."""
        if update.action == "rejected":
            self.reject(rejected_event(update))
            return
        if update.action == "delete":
            known = self.table.delete(update.uid)
            self.record(
                "threat", id=update.uid, source=update.source, removed=True, known=known, t_s=update.received_t_s
            )
            log.info("threat %s removed by %s%s", update.uid, update.source, "" if known else " (was not known)")
        else:
            try:
                self.table.put(update.threat)
            except (CompanionError, GeoError) as exc:  # e.g. a global threat before home
                self.reject(
                    {
                        "event": "rejected",
                        "threat_id": update.uid,
                        "source": update.source,
                        "field": getattr(exc, "field", "payload"),
                        "reason": str(exc),
                    }
                )
                return
            th = self.table.get(update.uid)
            self.record(
                "threat",
                id=th.uid,
                source=th.source,
                kind=th.kind,
                position_ned_m=th.pos_ned_m,
                velocity_ned_m_s=th.velocity_ned_m_s,
                radius_m=th.radius_m,
                t_s=update.received_t_s,
            )
        self.table_changed()
        if self.on_change is not None:
            self.on_change(update.received_mono_s)

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
        """Put threats known before a restart (``companion.threats.snapshot``) back in the table,
        times unchanged (the remaining TTL is kept); recorded with ``restored=True``. Returns
        their ids. Decided on at the next leg start, like any threat held then."""
        ids = []
        for th in threats:
            self.table.put(th)
            ids.append(th.id)
            self.record(
                "threat",
                id=th.id,
                kind=th.kind,
                position_ned_m=th.pos_ned_m,
                velocity_ned_m_s=th.velocity_ned_m_s,
                radius_m=th.radius_m,
                t_s=th.received_t_s,
                expires_t_s=th.expires_t_s,
                restored=True,
            )
        self.table_changed()
        return ids

    def on_local_threat(self, threat, received_mono_s: float | None = None) -> None:
        """A threat this process learnt itself (e.g. ADS-B; on the loop): stored and decided
        exactly as a zenoh PUT (:meth:`on_update`), then republished for other consumers."""
        self._local_seq += 1
        update = ThreatUpdate(
            "put",
            threat.id,
            threat,
            None,
            self.bus.key(f"threats/{threat.id}"),
            threat.received_t_s,
            time.monotonic() if received_mono_s is None else received_mono_s,
            self._local_seq,
        )
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
        self.rejected += 1
        self.bus.outbound.publish_event(event)
        self.record(
            "decision",
            kind="rejected",
            reason=event.get("reason"),
            t_s=event["t_s"],
            field=event.get("field"),
            threat_id=event.get("threat_id"),
            source=event.get("source"),
        )
        if time.monotonic() - self._rejected_told_s >= REJECTED_TEXT_PERIOD_S:
            self._rejected_told_s = time.monotonic()  # a flood of junk: one line per period
            self.tell(*statustext_for("rejected", str(event.get("field") or ""), event.get("threat_id"), None))

    # ------------------------------------------------------------------ decisions out
    def tell_decision(self, decision, event: dict) -> None:
        """Publish, record and tell one decision (``Avoidance`` built ``event``)."""
        if "threat_id" in event:
            event = {**event, "source": self.source_of(event["threat_id"])}
        self.bus.outbound.publish_event(event)
        self.record("decision", kind=event["event"], path_ned_m=decision.path_ned_m, **event)
        threat_id = decision.conflict.threat_id if decision.conflict is not None else None
        self.tell(*statustext_for(event["event"], event["label"], threat_id, event["latency_ms"]))

    def publish_path(self, reference, alternatives, leg_index: int) -> None:
        """Publish the active reference and the alternatives on ``uav/<sysid>/path``."""
        if reference is None:
            return
        t = np.linspace(0.0, reference.trajectory.duration_s, max(2, int(reference.trajectory.duration_s * 2)))
        self.bus.outbound.publish_path(
            {
                "t_s": self.clock_now_s(),
                "leg": leg_index,
                "path_id": reference.path_id,
                "t0_s": reference.t0_s,
                "duration_s": reference.trajectory.duration_s,
                "reference_ned_m": reference.trajectory.sample(t)[0],
                "alternatives": [{"path_id": a.path_id, "path_ned_m": a.path_ned_m} for a in alternatives],
            }
        )

    def tell(self, text: str, severity: str) -> None:
        """A STATUSTEXT to the ground stations (logged if it cannot be sent)."""
        if self.statustext is None:
            return
        try:
            self.statustext(text, severity)
        except CompanionError as exc:  # e.g. the link is down: the event is published
            log.info("STATUSTEXT %r not sent: %s", text, exc)
