"""Waiting on the vehicle's telemetry: for a condition, for a fresh position, for its home and
its EKF origin (each a part of ``VehicleLink``; ``LinkError`` naming what timed out)."""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Callable

from heli_common.mavlink_ids import mavlink

from companion.errors import LinkError
from companion.link.streams import StreamKeeper
from companion.link.telemetry import Telemetry, TelemetryState

log = logging.getLogger(__name__)


class TelemetryWaits:
    """The waits of a ``VehicleLink`` (a part of it: it uses the link's ``telemetry``,
    ``command_result`` and ``request_home``)."""

    streams: StreamKeeper | None
    _state: TelemetryState

    async def wait_origin(self, timeout_s: float = 5.0) -> tuple | None:
        """Wait for the vehicle's EKF origin (GPS_GLOBAL_ORIGIN, asked for by the stream
        requests); None after ``timeout_s`` or as soon as the vehicle says it cannot send it."""
        start = time.monotonic()
        asked = False
        while self._state.values.get("origin_lla") is None:
            waited = time.monotonic() - start
            if waited > timeout_s or (
                    self.streams is not None and self.streams.unavailable("GPS_GLOBAL_ORIGIN")):
                return None
            if not asked and waited > timeout_s / 2.0:       # the stream is slow: ask once
                asked = True
                await self.command_result(mavlink.MAV_CMD_REQUEST_MESSAGE,
                                          (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,),
                                          what="request GPS_GLOBAL_ORIGIN", timeout_s=1.0)
            await asyncio.sleep(0.05)
        return self._state.values["origin_lla"]

    async def wait_position(self, timeout_s: float = 10.0) -> Telemetry:
        """Wait for a fresh position; raises ``LinkError`` on timeout."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.telemetry
            if snap.pos_ned_m is not None and snap.position_age_s < 1.0:
                return snap
            if time.monotonic() > deadline:
                raise LinkError(f"no position telemetry within {timeout_s:g} s")
            await asyncio.sleep(0.02)

    async def wait_home(self, timeout_s: float = 10.0) -> tuple[float, float, float]:
        """Request and wait for the vehicle's home position (lat_deg, lon_deg, alt_m AMSL)."""
        deadline = time.monotonic() + timeout_s
        next_request = 0.0
        while self._state.values.get("home_lla") is None:
            now = time.monotonic()
            if now > deadline:
                raise LinkError(f"the vehicle reported no home position within {timeout_s:g} s")
            if now >= next_request:
                next_request = now + 1.0
                try:
                    await self.request_home()
                except LinkError as exc:
                    log.debug("home request: %s", exc)
            await asyncio.sleep(0.05)
        return self._state.values["home_lla"]

    async def wait_ready(self, timeout_s: float = 10.0) -> Telemetry:
        """Wait until position, flight mode and armed state are known."""
        return await self.wait_for(lambda t: t.pos_ned_m is not None and t.mode is not None
                                   and t.armed is not None, timeout_s, "telemetry")

    async def wait_for(self, predicate: Callable[[Telemetry], bool], timeout_s: float,
                       what: str = "condition") -> Telemetry:
        """Wait until ``predicate(telemetry)`` holds; ``LinkError`` naming ``what`` on timeout."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.telemetry
            if predicate(snap):
                return snap
            if time.monotonic() > deadline:
                raise LinkError(f"timed out after {timeout_s:g} s waiting for {what}")
            await asyncio.sleep(0.02)
