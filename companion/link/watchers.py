"""The link's telemetry subscriptions: each received message kept in the ``TelemetryState``.

Raw LOCAL_POSITION_NED, EXTENDED_SYS_STATE, HOME_POSITION, GPS_GLOBAL_ORIGIN, RPM, SYS_STATUS,
STATUSTEXT and HEARTBEAT come through MavlinkDirect (``messages``); attitude, armed and global
position through MAVSDK's Telemetry plugin. A message from another system, or one with a
missing, null or non-finite field (``finite_fields``), is dropped; a subscription that fails is
logged and restarted (``_guarded``), so a telemetry glitch never stops the link.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import time
from typing import Callable

import numpy as np

from heli_common.mavlink_ids import mavlink

from companion.link.streams import StreamKeeper
from companion.link.telemetry import HEARTBEAT_TIMEOUT_S, TelemetryState, finite_fields

log = logging.getLogger(__name__)

#: EXTENDED_SYS_STATE.landed_state values that mean "not on the ground" (MAV_LANDED_STATE).
LANDED_STATES_IN_AIR = (mavlink.MAV_LANDED_STATE_IN_AIR, mavlink.MAV_LANDED_STATE_TAKEOFF,
                        mavlink.MAV_LANDED_STATE_LANDING)
#: SYS_STATUS sensor bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK).
MAV_SYS_STATUS_PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK



def degrees_lla(lla_int) -> tuple[float, float, float] | None:
    """(lat degE7, lon degE7, alt mm) as (lat deg, lon deg, alt m); None for the unset (0, 0)
    or an impossible position."""
    lat, lon = lla_int[0] / 1e7, lla_int[1] / 1e7
    if (lat, lon) == (0.0, 0.0) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return None
    return lat, lon, lla_int[2] / 1e3

class TelemetryWatchers:
    """The subscriptions of a ``VehicleLink`` (a part of it: it uses the link's ``messages``,
    ``_from_vehicle``, ``connected`` and telemetry plugin)."""

    url: str | None
    target_system: int
    target_component: int
    streams: StreamKeeper | None
    statustexts: collections.deque
    _state: TelemetryState
    _tasks: list[asyncio.Task]
    _telemetry_plugin: object
    _link_listeners: list[Callable[[bool], None]]
    _was_connected: bool

    def _start_subscriptions(self) -> None:
        loop = asyncio.get_running_loop()
        coros = [self._watch_heartbeat(), self._watch_link(), self._watch_local_position(),
                 self._watch_attitude(), self._watch_armed(), self._watch_landed_state(),
                 self._watch_home(), self._watch_origin(), self._watch_global_position(),
                 self._watch_statustext(), self._watch_rpm(), self._watch_sys_status()]
        if self.streams is not None:
            coros.append(self.streams.run())
        self._tasks = [loop.create_task(coro, name=f"link-{coro.__name__}") for coro in coros]

    def _note(self, name: str, boot_s: float | None = None) -> None:
        if self.streams is not None:
            self.streams.note(name, boot_s)

    async def _guarded(self, what: str, agen, apply: Callable) -> None:
        """Run one subscription forever; a failure is logged and the subscription restarted."""
        while True:
            try:
                async for value in agen():
                    apply(value)
            except asyncio.CancelledError:
                raise
            except Exception:  # noqa: BLE001 - a telemetry glitch must not stop the link
                log.exception("telemetry subscription %s failed; restarting", what)
            await asyncio.sleep(0.5)

    async def _watch_heartbeat(self) -> None:
        def apply(fields: dict) -> None:
            if fields.get("_sysid") != self.target_system or fields.get("_compid") != \
                    self.target_component:
                return
            self._state.heartbeat_t = time.monotonic()
            values = finite_fields(fields, "base_mode", "custom_mode")
            if values is None:
                return
            base_mode, custom_mode = map(int, values)
            if base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self._state.values["mode"] = custom_mode
            self._state.values["armed"] = bool(base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        await self._guarded("HEARTBEAT", lambda: self.messages("HEARTBEAT"), apply)

    async def _watch_link(self) -> None:
        """Detect heartbeat loss and return; tell the listeners."""
        while True:
            await asyncio.sleep(0.2)
            now_connected = self.connected
            if now_connected != self._was_connected:
                self._was_connected = now_connected
                if now_connected:
                    log.warning("link to system %d is back", self.target_system)
                    if self.streams is not None:
                        self.streams.request_again("link back")
                else:
                    log.warning("link to system %d lost: no heartbeat for %.1f s; still "
                                "listening on %s", self.target_system, HEARTBEAT_TIMEOUT_S,
                                self.url)
                for callback in list(self._link_listeners):
                    try:
                        callback(now_connected)
                    except Exception:  # noqa: BLE001
                        log.exception("link listener failed")

    async def _watch_local_position(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "x", "y", "z", "vx", "vy", "vz", "time_boot_ms")
            if not self._from_vehicle(fields) or values is None:
                return
            self._state.pos_origin = np.array(values[:3])
            self._state.values["vel_ned_m_s"] = np.array(values[3:6])
            boot_s = values[6] / 1000.0
            self._state.values["boot_s"] = boot_s
            self._state.position_t = time.monotonic()
            self._note("LOCAL_POSITION_NED", boot_s)
        await self._guarded("LOCAL_POSITION_NED", lambda: self.messages("LOCAL_POSITION_NED"), apply)

    async def _watch_attitude(self) -> None:
        def apply(att) -> None:
            values = finite_fields(att, "roll_deg", "pitch_deg", "yaw_deg")
            if values is None:
                return
            self._state.values["attitude_rad"] = np.radians(values)
            self._note("ATTITUDE")
        await self._guarded("attitude", self._telemetry_plugin.subscribe_attitude_euler, apply)

    async def _watch_armed(self) -> None:
        def apply(armed) -> None:
            self._state.values["armed"] = bool(armed)
        await self._guarded("armed", self._telemetry_plugin.subscribe_armed, apply)

    async def _watch_landed_state(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "landed_state")
            if not self._from_vehicle(fields) or values is None:
                return
            state = int(values[0])
            self._state.values["landed_state"] = state
            self._state.values["in_air"] = None if state == 0 else state in LANDED_STATES_IN_AIR
            self._note("EXTENDED_SYS_STATE")
        await self._guarded("EXTENDED_SYS_STATE", lambda: self.messages("EXTENDED_SYS_STATE"), apply)

    async def _watch_origin(self) -> None:
        def apply(fields: dict) -> None:
            lla = finite_fields(fields, "latitude", "longitude", "altitude")
            if not self._from_vehicle(fields) or lla is None:
                return
            origin = degrees_lla(lla)
            if origin is not None:
                old = self._state.values.get("origin_lla")
                if old is not None and old != origin:
                    log.warning("the vehicle's EKF origin moved from %s to %s", old, origin)
                self._state.values["origin_lla"] = origin
            self._note("GPS_GLOBAL_ORIGIN")
        await self._guarded("GPS_GLOBAL_ORIGIN", lambda: self.messages("GPS_GLOBAL_ORIGIN"), apply)

    async def _watch_statustext(self) -> None:
        def apply(fields: dict) -> None:
            if not self._from_vehicle(fields):
                return
            text = str(fields.get("text", "")).rstrip("\x00")
            severity = int((finite_fields(fields, "severity") or [6])[0])
            self.statustexts.append((time.monotonic(), severity, text))
            log.log(logging.WARNING if severity <= 4 else logging.INFO, "vehicle: %s", text)
        await self._guarded("STATUSTEXT", lambda: self.messages("STATUSTEXT"), apply)

    async def _watch_sys_status(self) -> None:
        def apply(fields: dict) -> None:
            sensors = finite_fields(fields, "onboard_control_sensors_present",
                                    "onboard_control_sensors_health")
            if not self._from_vehicle(fields) or fields.get("_compid") != self.target_component \
                    or sensors is None:
                return
            present, health = map(int, sensors)
            self._state.values["prearm_ok"] = (bool(health & MAV_SYS_STATUS_PREARM_CHECK)
                                               if present & MAV_SYS_STATUS_PREARM_CHECK else None)
            self._note("SYS_STATUS")
        await self._guarded("SYS_STATUS", lambda: self.messages("SYS_STATUS"), apply)

    async def _watch_rpm(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "rpm1")
            if self._from_vehicle(fields) and values is not None:
                self._state.values["rotor_rpm"] = values[0]
                self._note("RPM")
        await self._guarded("RPM", lambda: self.messages("RPM"), apply)

    async def _watch_home(self) -> None:
        def apply(fields: dict) -> None:
            lla = finite_fields(fields, "latitude", "longitude", "altitude")
            if not self._from_vehicle(fields) or lla is None:
                return
            home = degrees_lla(lla)
            if home is not None:
                self._state.values["home_lla"] = home
            self._note("HOME_POSITION")
        await self._guarded("HOME_POSITION", lambda: self.messages("HOME_POSITION"), apply)

    async def _watch_global_position(self) -> None:
        def apply(pos) -> None:
            values = finite_fields(pos, "latitude_deg", "longitude_deg", "absolute_altitude_m",
                                   "relative_altitude_m")
            if values is None:
                return
            self._state.values.update(zip(("lat_deg", "lon_deg", "alt_amsl_m", "rel_alt_m"), values))
            self._note("GLOBAL_POSITION_INT")
        await self._guarded("position", self._telemetry_plugin.subscribe_position, apply)
