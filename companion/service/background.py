"""The daemon's work beside the legs (``companion.daemon``).

- ``TelemetryWatchers``: subscriptions to the vehicle's messages, as asyncio tasks:
  LOCAL_POSITION_NED drives the mission clock and the tracking error, SERVO_OUTPUT_RAW the
  record's rotor inputs, ADSB_VEHICLE becomes threats (``companion.threats.transport.adsb``,
  treated as zenoh PUTs).
- ``DaemonTasks``: the daemon's rows of the executor's schedule (``companion.flight.schedule``):
  the record's samples, the zenoh status, the zenoh router watch (router loss), the fleet's
  publication and the record's writes between sends.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable

from companion.errors import CompanionError
from companion.flight.schedule import Task
from companion.geo import LocalFrame
from companion.threats.transport.adsb import threat_from_adsb

log = logging.getLogger(__name__)

__all__ = ["TelemetryWatchers", "DaemonTasks", "ZENOH_WATCH_PERIOD_S", "RECORD_WRITE_RATE_HZ"]

#: How often (wall clock, s) the zenoh session's peers and routers are counted (router loss).
ZENOH_WATCH_PERIOD_S = 1.0
#: How often the record's buffered lines are written (Hz): between two setpoints.
RECORD_WRITE_RATE_HZ = 10.0


class TelemetryWatchers:
    """The vehicle's messages the daemon follows (see the module docstring).

    Parameters
    ----------
    link : VehicleLink
    clock : VehicleClock
        Observes every LOCAL_POSITION_NED's ``time_boot_ms``.
    owner : ReferenceOwner
        The active reference (the tracking error's).
    reactor : ThreatReactor or None
        Where ADS-B threats go (None: ignored).
    adsb_settings : AdsbSettings or None
        None: ADS-B is not watched.
    home_lla : tuple
    now_s : callable () -> float
        Mission time.
    """

    def __init__(
        self, link, clock, owner, *, reactor=None, adsb_settings=None, home_lla=None, now_s: Callable[[], float]
    ) -> None:
        self.link = link
        self.clock = clock
        self.owner = owner
        self.reactor = reactor
        self.adsb_settings = adsb_settings
        self.home_lla = home_lla
        self.now_s = now_s
        self.errors_m: list[float] = []
        self.servo_us: list[float] | None = None
        self._tasks: list[asyncio.Task] = []

    def start(self) -> None:
        loop = asyncio.get_running_loop()
        coros = [self._watch_local_position(), self._watch_servos()]
        if self.adsb_settings is not None and self.reactor is not None:
            coros.append(self._watch_adsb())
        for coro in coros:
            self._tasks.append(loop.create_task(coro, name=coro.__name__))

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()

    def _own(self, fields: dict) -> bool:
        return fields.get("_sysid") == self.link.target_system

    async def _watch_local_position(self) -> None:
        """LOCAL_POSITION_NED with its timestamp: drives the clock and the tracking error."""
        async for fields in self.link.inbound.messages("LOCAL_POSITION_NED"):
            if not self._own(fields):
                continue
            boot_s = fields.get("time_boot_ms", 0) / 1000.0
            self.clock.observe(boot_s, fields["_t_s"])
            ref = self.owner.current
            if ref is not None:
                pos = self.link.frames.to_home_floats((fields["x"], fields["y"], fields["z"]))
                self.errors_m.append(math.dist(pos, ref.state_lists(boot_s)[0]))  # mission time is vehicle time

    async def _watch_servos(self) -> None:
        async for fields in self.link.inbound.messages("SERVO_OUTPUT_RAW"):
            if self._own(fields):
                self.servo_us = [fields.get(f"servo{i}_raw", 1500) for i in range(1, 5)]

    async def _watch_adsb(self) -> None:
        home = LocalFrame(*self.home_lla)
        async for fields in self.link.inbound.messages("ADSB_VEHICLE"):
            if not self._own(fields):
                continue
            try:
                threat = threat_from_adsb(fields, self.adsb_settings, self.now_s(), home)
            except (CompanionError, ValueError, TypeError) as exc:
                log.info("ADSB_VEHICLE ignored: %s", exc)
                continue
            if threat is not None:
                self.reactor.on_local_threat(threat, fields["_t_s"])


class DaemonTasks:
    """The daemon's rows of the executor's schedule (see the module docstring).

    Parameters
    ----------
    settings : companion.config.Settings
        ``link.record_rate_hz``, ``link.status_rate_hz``, ``fleet.publish_period_s``.
    link : VehicleLink
    owner : ReferenceOwner
    watchers : TelemetryWatchers
    summary : FlightSummary
    sink : FlightSink
        ``event`` (zenoh lost / back) and ``record``.
    status : callable () -> dict
        The status message.
    reactor : ThreatReactor or None
    recorder : RecordSinks or None
    leg_index : callable () -> int
    """

    def __init__(
        self,
        settings,
        *,
        link,
        owner,
        watchers: TelemetryWatchers,
        summary,
        sink,
        status: Callable[[], dict],
        reactor=None,
        recorder=None,
        leg_index: Callable[[], int] = lambda: -1,
    ) -> None:
        self.settings = settings
        self.link = link
        self.owner = owner
        self.watchers = watchers
        self.summary = summary
        self.sink = sink
        self.status = status
        self.reactor = reactor
        self.recorder = recorder
        self.leg_index = leg_index
        self._zenoh_had: bool | None = None

    def rows(self) -> list[Task]:
        """The rows, at their declared rates."""
        link = self.settings.link
        rows = [
            Task("telemetry", link.setpoint_rate_hz, lambda now: self.link.inbound.take_batches(), budget_ms=1.0),
            Task("record", link.record_rate_hz, self.record_sample, budget_ms=2.0),
        ]
        if self.recorder is not None:
            rows.append(Task("record_write", RECORD_WRITE_RATE_HZ, lambda now: self.recorder.flush(), budget_ms=3.0))
        if self.reactor is not None:
            rows += [
                Task("status", link.status_rate_hz, self.publish_status, budget_ms=2.0),
                Task("zenoh_watch", 1.0 / ZENOH_WATCH_PERIOD_S, self.watch_zenoh, budget_ms=1.0),
            ]
            if self.settings.fleet.enabled:
                rows.append(
                    Task(
                        "fleet_publish",
                        1.0 / self.settings.fleet.publish_period_s,
                        self.reactor.fleet_publish,
                        budget_ms=3.0,
                    )
                )
        return rows

    def record_sample(self, now_s: float) -> None:
        tele = self.link.telemetry
        ref = self.owner.current
        if tele.pos_ned_m is None or ref is None:
            return
        t = self.watchers.now_s()
        ref_pos, ref_vel = ref.state(t)[:2]
        if self.reactor is not None:
            self.summary.min_threat_separation_m = min(
                self.summary.min_threat_separation_m, self.reactor.min_separation_m(tele.pos_ned_m, t)
            )
        errors = self.watchers.errors_m
        self.sink.record(
            "sample",
            t_s=t,
            ref_pos_ned_m=ref_pos,
            ref_vel_ned_m_s=ref_vel,
            pos_ned_m=tele.pos_ned_m,
            vel_ned_m_s=tele.vel_ned_m_s,
            servo_us=self.watchers.servo_us,
            tracking_error_m=errors[-1] if errors else None,
            leg=self.leg_index(),
            path_id=ref.path_id,
            euler_rad=tele.attitude_rad,
        )

    def publish_status(self, now_s: float) -> None:
        self.reactor.publish_status(self.status())

    def watch_zenoh(self, now_s: float) -> None:
        """Event ``zenoh_lost`` when the session loses its last peer or router (e.g. the router
        stopped), ``zenoh_back`` when one is connected again. zenoh reconnects by itself
        (``connect/retry``) and redeclares the subscriptions; the flight goes on meanwhile on
        the threats already held."""
        try:
            now = self.reactor.bus.connected_peers() > 0
        except Exception as exc:  # noqa: BLE001 - the session is closing
            log.debug("zenoh session info: %s", exc)
            return
        if self._zenoh_had is not None and now != self._zenoh_had:
            self.sink.event("zenoh_back" if now else "zenoh_lost")
        self._zenoh_had = now
