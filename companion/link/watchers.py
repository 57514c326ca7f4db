"""The link's telemetry subscriptions (``VehicleLink.watchers``): each received message kept in
the ``TelemetryState`` they own, and the vehicle's recent STATUSTEXTs.

Every message comes from the signing gate (a ``MessageSource``: ``companion.link.message_tap``,
parsed once on the gate's thread, handed over in batches), not through MAVSDK's Telemetry plugin,
whose callbacks cost a loop wake-up each. The armed state is the HEARTBEAT's. A message from
another system, or one with a missing, null or non-finite field (``finite_fields``), is dropped;
a subscription that fails is logged and restarted (``_guarded``), so a telemetry glitch never
stops the link.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import time
from collections.abc import Callable

import numpy as np

from companion.link.ports import MessageSource, StreamNotes, VehicleTarget
from companion.link.telemetry import TelemetryState, finite_fields
from heli_common.mavlink_ids import mavlink

log = logging.getLogger(__name__)

#: EXTENDED_SYS_STATE.landed_state values that mean "not on the ground" (MAV_LANDED_STATE).
LANDED_STATES_IN_AIR = (
    mavlink.MAV_LANDED_STATE_IN_AIR,
    mavlink.MAV_LANDED_STATE_TAKEOFF,
    mavlink.MAV_LANDED_STATE_LANDING,
)
#: SYS_STATUS sensor bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK).
MAV_SYS_STATUS_PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK


def degrees_lla(lla_int) -> tuple[float, float, float] | None:
    """(lat degE7, lon degE7, alt mm) as (lat deg, lon deg, alt m); None for the unset (0, 0)
    or an impossible position."""
    lat, lon = lla_int[0] / 1e7, lla_int[1] / 1e7
    if (lat, lon) == (0.0, 0.0) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return None
    return lat, lon, lla_int[2] / 1e3


#: How many recent STATUSTEXTs of the vehicle are kept (``TelemetryWatchers.statustexts``).
STATUSTEXT_KEEP = 64


class TelemetryWatchers:
    """The telemetry subscriptions of the link (``VehicleLink.watchers``).

    Parameters
    ----------
    target : VehicleTarget
        Whose messages count (``target_system``; HEARTBEAT and SYS_STATUS also ``target_component``).
    source : MessageSource
        The received messages (``messages(name)``).
    streams : callable() -> StreamNotes or None
        The link's stream keeper, told of every message that arrives (None: no streams asked for).

    Attributes
    ----------
    state : TelemetryState
        What the messages said (written here only; ``VehicleLink.telemetry`` snapshots it).
    statustexts : deque of (monotonic_s, severity, text)
        The vehicle's last ``STATUSTEXT_KEEP`` STATUSTEXTs.
    """

    def __init__(self, target: VehicleTarget, source: MessageSource, streams: Callable[[], StreamNotes | None]) -> None:
        self._target = target
        self._source = source
        self._streams = streams
        self.state = TelemetryState()
        self.statustexts: collections.deque = collections.deque(maxlen=STATUSTEXT_KEEP)

    def coroutines(self) -> list:
        """One subscription coroutine per message type (run each as a task until cancelled)."""
        return [
            self._watch_heartbeat(),
            self._watch_local_position(),
            self._watch_attitude(),
            self._watch_landed_state(),
            self._watch_home(),
            self._watch_origin(),
            self._watch_global_position(),
            self._watch_statustext(),
            self._watch_rpm(),
            self._watch_sys_status(),
        ]

    def heard_now(self) -> None:
        """The autopilot was just heard (``connect`` found it): it counts as a heartbeat."""
        self.state.heartbeat_t = time.monotonic()

    def statustexts_since(self, t_monotonic_s: float) -> list[str]:
        """The vehicle's STATUSTEXTs received since ``t_monotonic_s`` (oldest first)."""
        return [text for t, _, text in list(self.statustexts) if t >= t_monotonic_s]

    def _from_vehicle(self, fields: dict) -> bool:
        return fields.get("_sysid") == self._target.target_system

    def _note(self, name: str, boot_s: float | None = None) -> None:
        streams = self._streams()
        if streams is not None:
            streams.note(name, boot_s)

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
            if (
                fields.get("_sysid") != self._target.target_system
                or fields.get("_compid") != self._target.target_component
            ):
                return
            self.state.heartbeat_t = time.monotonic()
            values = finite_fields(fields, "base_mode", "custom_mode")
            if values is None:
                return
            base_mode, custom_mode = map(int, values)
            if base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self.state.values["mode"] = custom_mode
            self.state.values["armed"] = bool(base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

        await self._guarded("HEARTBEAT", lambda: self._source.messages("HEARTBEAT"), apply)

    async def _watch_local_position(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "x", "y", "z", "vx", "vy", "vz", "time_boot_ms")
            if not self._from_vehicle(fields) or values is None:
                return
            self.state.pos_origin = np.array(values[:3])
            self.state.values["vel_ned_m_s"] = np.array(values[3:6])
            boot_s = values[6] / 1000.0
            self.state.values["boot_s"] = boot_s
            self.state.position_t = time.monotonic()
            self._note("LOCAL_POSITION_NED", boot_s)

        await self._guarded("LOCAL_POSITION_NED", lambda: self._source.messages("LOCAL_POSITION_NED"), apply)

    async def _watch_attitude(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "roll", "pitch", "yaw")
            if not self._from_vehicle(fields) or values is None:
                return
            self.state.values["attitude_rad"] = np.array(values)
            self._note("ATTITUDE")

        await self._guarded("ATTITUDE", lambda: self._source.messages("ATTITUDE"), apply)

    async def _watch_landed_state(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "landed_state")
            if not self._from_vehicle(fields) or values is None:
                return
            state = int(values[0])
            self.state.values["landed_state"] = state
            self.state.values["in_air"] = None if state == 0 else state in LANDED_STATES_IN_AIR
            self._note("EXTENDED_SYS_STATE")

        await self._guarded("EXTENDED_SYS_STATE", lambda: self._source.messages("EXTENDED_SYS_STATE"), apply)

    async def _watch_origin(self) -> None:
        def apply(fields: dict) -> None:
            lla = finite_fields(fields, "latitude", "longitude", "altitude")
            if not self._from_vehicle(fields) or lla is None:
                return
            origin = degrees_lla(lla)
            if origin is not None:
                old = self.state.values.get("origin_lla")
                if old is not None and old != origin:
                    log.warning("the vehicle's EKF origin moved from %s to %s", old, origin)
                self.state.values["origin_lla"] = origin
            self._note("GPS_GLOBAL_ORIGIN")

        await self._guarded("GPS_GLOBAL_ORIGIN", lambda: self._source.messages("GPS_GLOBAL_ORIGIN"), apply)

    async def _watch_statustext(self) -> None:
        def apply(fields: dict) -> None:
            if not self._from_vehicle(fields):
                return
            text = str(fields.get("text", "")).rstrip("\x00")
            severity = int((finite_fields(fields, "severity") or [6])[0])
            self.statustexts.append((time.monotonic(), severity, text))
            log.log(logging.WARNING if severity <= 4 else logging.INFO, "vehicle: %s", text)

        await self._guarded("STATUSTEXT", lambda: self._source.messages("STATUSTEXT"), apply)

    async def _watch_sys_status(self) -> None:
        def apply(fields: dict) -> None:
            sensors = finite_fields(fields, "onboard_control_sensors_present", "onboard_control_sensors_health")
            if (
                not self._from_vehicle(fields)
                or fields.get("_compid") != self._target.target_component
                or sensors is None
            ):
                return
            present, health = map(int, sensors)
            self.state.values["prearm_ok"] = (
                bool(health & MAV_SYS_STATUS_PREARM_CHECK) if present & MAV_SYS_STATUS_PREARM_CHECK else None
            )
            self._note("SYS_STATUS")

        await self._guarded("SYS_STATUS", lambda: self._source.messages("SYS_STATUS"), apply)

    async def _watch_rpm(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "rpm1")
            if self._from_vehicle(fields) and values is not None:
                self.state.values["rotor_rpm"] = values[0]
                self._note("RPM")

        await self._guarded("RPM", lambda: self._source.messages("RPM"), apply)

    async def _watch_home(self) -> None:
        def apply(fields: dict) -> None:
            lla = finite_fields(fields, "latitude", "longitude", "altitude")
            if not self._from_vehicle(fields) or lla is None:
                return
            home = degrees_lla(lla)
            if home is not None:
                self.state.values["home_lla"] = home
            self._note("HOME_POSITION")

        await self._guarded("HOME_POSITION", lambda: self._source.messages("HOME_POSITION"), apply)

    async def _watch_global_position(self) -> None:
        def apply(fields: dict) -> None:
            values = finite_fields(fields, "lat", "lon", "alt", "relative_alt")
            if not self._from_vehicle(fields) or values is None:
                return
            lat, lon, alt_mm, rel_mm = values
            self.state.values.update(
                lat_deg=lat / 1e7, lon_deg=lon / 1e7, alt_amsl_m=alt_mm / 1e3, rel_alt_m=rel_mm / 1e3
            )
            self._note("GLOBAL_POSITION_INT")

        await self._guarded("GLOBAL_POSITION_INT", lambda: self._source.messages("GLOBAL_POSITION_INT"), apply)
