"""The daemon's background tasks: telemetry watchers, the record's samples, the zenoh status,
the zenoh router watch and link loss (``companion.daemon``)."""

from __future__ import annotations

import asyncio
import logging
import math

from companion.errors import CompanionError
from companion.geo import LocalFrame
from companion.threats.transport.adsb import threat_from_adsb

log = logging.getLogger(__name__)

__all__ = ["BackgroundTasks", "ZENOH_WATCH_PERIOD_S"]

#: How often (wall clock, s) the zenoh session's peers and routers are counted (router loss).
ZENOH_WATCH_PERIOD_S = 1.0


class BackgroundTasks:
    """Mixin of ``CompanionDaemon``: the tasks that run beside the legs."""

    async def _watch_local_position(self) -> None:
        """LOCAL_POSITION_NED with its timestamp: drives the clock and the tracking error."""
        async for fields in self.link.inbound.messages("LOCAL_POSITION_NED"):
            if fields.get("_sysid") != self.link.target_system:
                continue
            boot_s = fields.get("time_boot_ms", 0) / 1000.0
            self.clock.observe(boot_s, fields["_t_s"])
            if self.reference is not None:
                pos = self.link.frames.to_home_floats((fields["x"], fields["y"], fields["z"]))
                ref_pos = self.reference.state_lists(boot_s)[0]   # mission time is vehicle time
                self._errors_m.append(math.dist(pos, ref_pos))

    async def _watch_servos(self) -> None:
        async for fields in self.link.inbound.messages("SERVO_OUTPUT_RAW"):
            if fields.get("_sysid") == self.link.target_system:
                self._servo_us = [fields.get(f"servo{i}_raw", 1500) for i in range(1, 5)]

    async def _watch_adsb(self) -> None:
        """ADSB_VEHICLE reports become threats, treated as zenoh PUTs (``companion.threats.transport.adsb``)."""
        home = LocalFrame(*self.home_lla)
        async for fields in self.link.inbound.messages("ADSB_VEHICLE"):
            if fields.get("_sysid") != self.link.target_system or self.threats is None:
                continue
            try:
                threat = threat_from_adsb(fields, self.settings.adsb, self.clock.now_s(), home)
            except (CompanionError, ValueError, TypeError) as exc:
                log.info("ADSB_VEHICLE ignored: %s", exc)
                continue
            if threat is not None:
                self.threats.on_local_threat(threat, fields["_t_s"])

    async def _record_samples(self) -> None:
        period = 1.0 / self.settings.link.record_rate_hz
        while True:
            await self.pause(period)
            tele = self.link.telemetry
            if tele.pos_ned_m is None or self.reference is None:
                continue
            t = self.clock.now_s()
            ref_pos, ref_vel = self.reference.state(t)[:2]
            if self.threats is not None:
                self.summary.min_threat_separation_m = min(
                    self.summary.min_threat_separation_m, self.threats.min_separation_m(tele.pos_ned_m, t))
            self.record("sample", t_s=t, ref_pos_ned_m=ref_pos, ref_vel_ned_m_s=ref_vel,
                        pos_ned_m=tele.pos_ned_m, vel_ned_m_s=tele.vel_ned_m_s,
                        servo_us=self._servo_us,
                        tracking_error_m=self._errors_m[-1] if self._errors_m else None,
                        leg=self.leg_index, path_id=self.reference.path_id, euler_rad=tele.attitude_rad)

    async def _publish_status(self) -> None:
        period = 1.0 / self.settings.link.status_rate_hz
        while True:
            await self.pause(period)
            if self.threats is not None:
                self.threats.publish_status(self.status())

    async def _watch_zenoh(self) -> None:
        """Event ``zenoh_lost`` when the session loses its last peer or router (e.g. the router
        stopped), ``zenoh_back`` when one is connected again. zenoh reconnects by itself
        (``connect/retry``) and redeclares the subscriptions; the flight goes on meanwhile on
        the threats already held."""
        had = None
        while True:
            await self.pause(ZENOH_WATCH_PERIOD_S)
            try:
                now = self.threats.bus.connected_peers() > 0
            except Exception as exc:  # noqa: BLE001 - the session is closing
                log.debug("zenoh session info: %s", exc)
                continue
            if had is not None and now != had:
                self.event("zenoh_back" if now else "zenoh_lost")
            had = now

    def _on_link_change(self, connected: bool) -> None:
        if not connected:
            self._link_lost_at = self.clock.now_s()
            self.event("link_lost")
        else:
            lost_s = self.clock.now_s() - (self._link_lost_at or self.clock.now_s())
            self.event("link_back", lost_s=round(lost_s, 2))
            if self.reference is not None and self.link.telemetry.pos_ned_m is not None:
                self.hold_here(self.link.telemetry.pos_ned_m, "link back: hold, then replan the leg")
                self._resume_needed = True

    def _start_background(self) -> None:
        loop = asyncio.get_running_loop()
        coros = [self._watch_local_position(), self._watch_servos(), self._record_samples(),
                 self._publish_status()]
        if self.settings.adsb.enabled:
            if self.threats is None:
                log.warning("ADS-B traffic is ignored: threats need zenoh (zenoh.enabled)")
            else:
                coros.append(self._watch_adsb())
        if self.threats is not None:
            coros.append(self._watch_zenoh())
        for coro in coros:
            self._tasks.append(loop.create_task(coro, name=coro.__name__))
        self._stop_link_listener = self.link.on_link_change(self._on_link_change)
