"""Waiting on the vehicle's telemetry (``VehicleLink.waits``): for a condition, for a fresh
position, for its home and its EKF origin (``LinkError`` naming what timed out).

``wait_for`` is also a plain function of a telemetry source, for the parts of the link that
wait for what they commanded (``companion.link.vehicle_commands``).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

from companion.errors import LinkError
from companion.link.ports import CommandSender, StreamNotes
from companion.link.telemetry import Telemetry
from heli_common.mavlink_ids import mavlink

log = logging.getLogger(__name__)


async def wait_for(
    telemetry: Callable[[], Telemetry],
    predicate: Callable[[Telemetry], bool],
    timeout_s: float,
    what: str = "condition",
) -> Telemetry:
    """Wait until ``predicate(telemetry())`` holds; ``LinkError`` naming ``what`` on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        snap = telemetry()
        if predicate(snap):
            return snap
        if time.monotonic() > deadline:
            raise LinkError(f"timed out after {timeout_s:g} s waiting for {what}")
        await asyncio.sleep(0.02)


class TelemetryWaits:
    """The waits of the link (``VehicleLink.waits``).

    Parameters
    ----------
    telemetry : callable() -> Telemetry
        The latest snapshot (``VehicleLink.telemetry``).
    commands : CommandSender
        Asks for HOME_POSITION and GPS_GLOBAL_ORIGIN when they are slow to come.
    streams : callable() -> StreamNotes or None
        The link's stream keeper: a message it knows the vehicle cannot send is not waited for.
    """

    def __init__(
        self, telemetry: Callable[[], Telemetry], commands: CommandSender, streams: Callable[[], StreamNotes | None]
    ) -> None:
        self._telemetry = telemetry
        self._commands = commands
        self._streams = streams

    async def wait_origin(self, timeout_s: float = 5.0) -> tuple | None:
        """Wait for the vehicle's EKF origin (GPS_GLOBAL_ORIGIN, asked for by the stream
        requests); None after ``timeout_s`` or as soon as the vehicle says it cannot send it."""
        start = time.monotonic()
        asked = False
        while (origin := self._telemetry().origin_lla) is None:
            waited = time.monotonic() - start
            streams = self._streams()
            if waited > timeout_s or (streams is not None and streams.unavailable("GPS_GLOBAL_ORIGIN")):
                return None
            if not asked and waited > timeout_s / 2.0:  # the stream is slow: ask once
                asked = True
                await self._commands.command_result(
                    mavlink.MAV_CMD_REQUEST_MESSAGE,
                    (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,),
                    what="request GPS_GLOBAL_ORIGIN",
                    timeout_s=1.0,
                )
            await asyncio.sleep(0.05)
        return origin

    async def wait_position(self, timeout_s: float = 10.0) -> Telemetry:
        """Wait for a fresh position; raises ``LinkError`` on timeout."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self._telemetry()
            if snap.pos_ned_m is not None and snap.position_age_s < 1.0:
                return snap
            if time.monotonic() > deadline:
                raise LinkError(f"no position telemetry within {timeout_s:g} s")
            await asyncio.sleep(0.02)

    async def wait_home(self, timeout_s: float = 10.0) -> tuple[float, float, float]:
        """Request and wait for the vehicle's home position (lat_deg, lon_deg, alt_m AMSL)."""
        deadline = time.monotonic() + timeout_s
        next_request = 0.0
        while (home := self._telemetry().home_lla) is None:
            now = time.monotonic()
            if now > deadline:
                raise LinkError(f"the vehicle reported no home position within {timeout_s:g} s")
            if now >= next_request:
                next_request = now + 1.0
                try:
                    await self._commands.request_home()
                except LinkError as exc:
                    log.debug("home request: %s", exc)
            await asyncio.sleep(0.05)
        return home

    async def wait_ready(self, timeout_s: float = 10.0) -> Telemetry:
        """Wait until position, flight mode and armed state are known."""
        return await self.wait_for(
            lambda t: t.pos_ned_m is not None and t.mode is not None and t.armed is not None, timeout_s, "telemetry"
        )

    async def wait_for(
        self, predicate: Callable[[Telemetry], bool], timeout_s: float, what: str = "condition"
    ) -> Telemetry:
        """Wait until ``predicate(telemetry)`` holds; ``LinkError`` naming ``what`` on timeout."""
        return await wait_for(self._telemetry, predicate, timeout_s, what)
