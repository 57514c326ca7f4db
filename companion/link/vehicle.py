"""The vehicle link: MAVSDK 4.x (ctypes ``mavsdk.asyncio``) to an ArduPilot-like helicopter.

Implements the companion side of the MAVLink contract of DESIGN.md section 5:

- connection by MAVSDK URL (``udpin://``, ``udpout://``, ``tcpin://``, ``tcpout://``,
  ``serial://``), waiting for the first autopilot;
- telemetry streams requested, never assumed (``companion.link.streams.StreamKeeper``: ArduCopter
  sends only HEARTBEAT until asked), and requested again after a reboot or a link loss;
- telemetry as an always-fresh snapshot (``VehicleLink.telemetry``) kept up to date by
  background subscriptions (raw LOCAL_POSITION_NED, EXTENDED_SYS_STATE, HOME_POSITION,
  GPS_GLOBAL_ORIGIN, RPM, STATUSTEXT and HEARTBEAT through MavlinkDirect; MAVSDK's Telemetry
  plugin for attitude, armed and global position);
- the two local frames (``companion.link.frames``): positions in and out of the link are about
  the planning home, the vehicle's LOCAL_NED messages about its EKF origin; the link converts;
- mission, fence and rally upload and download with MissionRaw (MISSION_ITEM_INT, ArduPilot's
  home at mission seq 0), with rollback so a failed upload leaves the vehicle's lists as they
  were;
- commands (COMMAND_LONG through MavlinkDirect.send_command, each checked against its
  COMMAND_ACK; a refusal is ``VehicleRefused``): DO_SET_MODE with ArduCopter custom modes
  (GUIDED 4 ...), arm/disarm, takeoff, land, RTL, mission start, DO_AUX_FUNCTION (the motor
  interlock); parameters read with PARAM_REQUEST_READ;
- GUIDED setpoints: SET_POSITION_TARGET_LOCAL_NED (position + velocity + acceleration + yaw,
  type_mask from what is given) sent without blocking the event loop
  (``MavlinkDirect.send_message`` of the synchronous plugin: a ~20 us ctypes call);
- STATUSTEXT to the ground stations (``send_statustext``, broadcast, routed by the autopilot).

MAVSDK 4.x note: ``Configuration`` is built with ``Configuration.create_with_component_type``
(its constructor takes a raw handle).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import json
import logging
import math
import time
from typing import AsyncIterator, Callable

import numpy as np

from heli_common.mavlink_ids import (COPTER_MODE_NAMES, COPTER_MODES, MAV_RESULT_NAMES,
                                     TYPEMASK_IGNORE_ACCELERATION, TYPEMASK_IGNORE_POSITION,
                                     TYPEMASK_IGNORE_VELOCITY, enum_names, mavlink)

from companion.errors import LinkError, MissionError, VehicleRefused
from companion.link.frames import LinkFrames
from companion.link.gate import SigningKey, silence_reason
from companion.link.transport import GateThread, open_gate
from companion.link.streams import StreamKeeper, StreamSettings
from companion.mission.model import MissionPlan
from companion.mission.raw import (RawItem, fence_to_raw, mission_to_raw, rally_to_raw,
                                   raw_to_plan)

log = logging.getLogger(__name__)

DEFAULT_URL = "udpin://0.0.0.0:14540"
URL_SCHEMES = ("udpin://", "udpout://", "udp://", "tcpin://", "tcpout://", "tcp://", "serial://")

# ArduCopter flight modes (custom_mode of HEARTBEAT) and MAVLink numbers: from pymavlink
# (``heli_common.mavlink_ids``), re-exported under the names the companion has always used.
MAV_CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
MAV_CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
MAV_CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
MAV_CMD_DO_SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
MAV_CMD_MISSION_START = mavlink.MAV_CMD_MISSION_START
MAV_CMD_COMPONENT_ARM_DISARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
MAV_CMD_SET_MESSAGE_INTERVAL = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
MAV_CMD_REQUEST_MESSAGE = mavlink.MAV_CMD_REQUEST_MESSAGE
MAV_CMD_DO_AUX_FUNCTION = mavlink.MAV_CMD_DO_AUX_FUNCTION
MAVLINK_MSG_ID_HOME_POSITION = mavlink.MAVLINK_MSG_ID_HOME_POSITION
MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN = mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
MAV_MODE_FLAG_SAFETY_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
FORCE_DISARM_MAGIC = 21196.0
#: EXTENDED_SYS_STATE.landed_state values that mean "not on the ground" (MAV_LANDED_STATE).
LANDED_STATES_IN_AIR = (mavlink.MAV_LANDED_STATE_IN_AIR, mavlink.MAV_LANDED_STATE_TAKEOFF,
                        mavlink.MAV_LANDED_STATE_LANDING)
#: SYS_STATUS sensor bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK).
MAV_SYS_STATUS_PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK
#: How many recent STATUSTEXTs of the vehicle are kept (``VehicleLink.statustexts``).
STATUSTEXT_KEEP = 64

MAV_FRAME_LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
# SET_POSITION_TARGET type_mask bits (POSITION_TARGET_TYPEMASK)
IGNORE_POS = TYPEMASK_IGNORE_POSITION
IGNORE_VEL = TYPEMASK_IGNORE_VELOCITY
IGNORE_ACC = TYPEMASK_IGNORE_ACCELERATION
IGNORE_YAW = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
IGNORE_YAW_RATE = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

HEARTBEAT_TIMEOUT_S = 3.0

#: MAV_SEVERITY names by value (MAVLink common.xml: pymavlink's ``mavutil.mavlink.MAV_SEVERITY_*``).
MAV_SEVERITY_NAMES = tuple(enum_names("MAV_SEVERITY").values())
#: STATUSTEXT.text is char[50].
STATUSTEXT_MAX_CHARS = 50


def setpoint_type_mask(pos, vel, acc, yaw, yaw_rate=None) -> int:
    """SET_POSITION_TARGET type_mask: a field group is ignored when it is None."""
    mask = 0
    if pos is None:
        mask |= IGNORE_POS
    if vel is None:
        mask |= IGNORE_VEL
    if acc is None:
        mask |= IGNORE_ACC
    if yaw is None:
        mask |= IGNORE_YAW
    if yaw_rate is None:
        mask |= IGNORE_YAW_RATE
    return mask


def setpoint_fields(time_boot_ms: int, target_system: int, target_component: int,
                    pos_ned_m=None, vel_ned_m_s=None, acc_ned_m_s2=None, yaw_rad=None,
                    yaw_rate_rad_s=None) -> dict:
    """Fields of a SET_POSITION_TARGET_LOCAL_NED message (frame LOCAL_NED).

    Parameters
    ----------
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : (3,) array_like or None
    yaw_rad, yaw_rate_rad_s : float or None

    Raises
    ------
    LinkError
        A given vector is not 3 finite numbers, or yaw is not finite.
    """
    fields = {"time_boot_ms": int(time_boot_ms) & 0xFFFFFFFF, "target_system": target_system,
              "target_component": target_component, "coordinate_frame": MAV_FRAME_LOCAL_NED,
              "type_mask": setpoint_type_mask(pos_ned_m, vel_ned_m_s, acc_ned_m_s2, yaw_rad,
                                              yaw_rate_rad_s)}
    for name, value, keys in (("pos_ned_m", pos_ned_m, ("x", "y", "z")),
                              ("vel_ned_m_s", vel_ned_m_s, ("vx", "vy", "vz")),
                              ("acc_ned_m_s2", acc_ned_m_s2, ("afx", "afy", "afz"))):
        if value is None:
            fields.update({k: 0.0 for k in keys})
            continue
        vec = np.asarray(value, dtype=np.float64).reshape(-1)
        if vec.shape != (3,) or not np.all(np.isfinite(vec)):
            raise LinkError(f"setpoint {name} must be 3 finite numbers, got {value!r}")
        fields.update({k: float(v) for k, v in zip(keys, vec)})
    for name, value, key in (("yaw_rad", yaw_rad, "yaw"),
                             ("yaw_rate_rad_s", yaw_rate_rad_s, "yaw_rate")):
        if value is None:
            fields[key] = 0.0
        elif not math.isfinite(float(value)):
            raise LinkError(f"setpoint {name} must be finite, got {value!r}")
        else:
            fields[key] = float(value)
    return fields


#: How long ``aclose`` waits for MAVSDK command calls still running before releasing MAVSDK.
IN_FLIGHT_WAIT_S = 10.0


def finite_fields(fields, *names: str) -> list[float] | None:
    """The named fields of a message (a MavlinkDirect dict or a MAVSDK struct) as floats, or
    None when one is missing, null or not finite: such a message is dropped, never applied."""
    get = fields.get if isinstance(fields, dict) else lambda name: getattr(fields, name, None)
    try:
        values = [float(get(name)) for name in names]
    except (TypeError, ValueError):
        return None
    return values if all(map(math.isfinite, values)) else None


def check_url(url: str) -> str:
    """Raise ``LinkError`` naming ``url`` unless it is a MAVSDK connection URL."""
    if not isinstance(url, str) or not url.startswith(URL_SCHEMES):
        raise LinkError(f"--connect {url!r}: not a MAVSDK URL; use e.g. udpin://0.0.0.0:14540, "
                        f"udpout://127.0.0.1:14555, tcpout://127.0.0.1:5760 or "
                        f"serial:///dev/ttyUSB0:57600")
    return url


def mode_number(mode) -> int:
    """ArduCopter mode number from a name (``"GUIDED"``) or a number."""
    if isinstance(mode, str):
        try:
            return COPTER_MODES[mode.upper()]
        except KeyError:
            raise LinkError(f"unknown flight mode {mode!r}; known: "
                            f"{', '.join(COPTER_MODES)}") from None
    return int(mode)


@dataclasses.dataclass(frozen=True)
class Telemetry:
    """A snapshot of the vehicle state (None: not received yet).

    Attributes
    ----------
    pos_ned_m, vel_ned_m_s : ndarray (3,) or None
        LOCAL_POSITION_NED converted to the planning home's frame (``VehicleLink.frames``;
        before ``set_planning_home`` the vehicle's own local frame).
    attitude_rad : ndarray (3,) or None
        Roll, pitch, yaw.
    lat_deg, lon_deg, alt_amsl_m, rel_alt_m : float or None
        GLOBAL_POSITION_INT (``rel_alt_m``: above the vehicle's home).
    home_lla : (lat_deg, lon_deg, alt_m AMSL) or None
        The vehicle's home now (HOME_POSITION).
    origin_lla : (lat_deg, lon_deg, alt_m AMSL) or None
        The vehicle's EKF origin (GPS_GLOBAL_ORIGIN): its local frame.
    mode : int or None
        ArduCopter custom mode (``COPTER_MODES``); ``mode_name`` its name.
    armed, in_air : bool or None
        ``in_air`` from EXTENDED_SYS_STATE (``landed_state`` IN_AIR, TAKEOFF or LANDING).
    landed_state : int or None
        MAV_LANDED_STATE (0 undefined, 1 on ground, 2 in air, 3 takeoff, 4 landing).
    rotor_rpm : float or None
        RPM.rpm1 (ArduPilot's rotor speed sensor), when the vehicle sends it.
    prearm_ok : bool or None
        SYS_STATUS: the vehicle's pre-arm checks pass (MAV_SYS_STATUS_PREARM_CHECK healthy);
        None when the vehicle does not report them.
    boot_s : float or None
        ``time_boot_ms`` of the last LOCAL_POSITION_NED, in seconds (vehicle time).
    connected : bool
        A heartbeat arrived in the last ``HEARTBEAT_TIMEOUT_S``.
    heartbeat_age_s, position_age_s : float
        Seconds since the last HEARTBEAT / position update (inf if never).
    """

    pos_ned_m: np.ndarray | None = None
    vel_ned_m_s: np.ndarray | None = None
    attitude_rad: np.ndarray | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    alt_amsl_m: float | None = None
    rel_alt_m: float | None = None
    home_lla: tuple[float, float, float] | None = None
    origin_lla: tuple[float, float, float] | None = None
    mode: int | None = None
    armed: bool | None = None
    in_air: bool | None = None
    landed_state: int | None = None
    rotor_rpm: float | None = None
    prearm_ok: bool | None = None
    boot_s: float | None = None
    connected: bool = False
    heartbeat_age_s: float = math.inf
    position_age_s: float = math.inf

    @property
    def mode_name(self) -> str:
        if self.mode is None:
            return "UNKNOWN"
        return COPTER_MODE_NAMES.get(self.mode, f"MODE{self.mode}")

    @property
    def height_m(self) -> float | None:
        """Height above home (m): GLOBAL_POSITION_INT's relative altitude, else -down."""
        if self.rel_alt_m is not None:
            return self.rel_alt_m
        return None if self.pos_ned_m is None else -float(self.pos_ned_m[2])


class TelemetryState:
    """The mutable state behind ``Telemetry`` snapshots (owned by the link's event loop).

    Positions are kept in the vehicle's local frame (``pos_origin``) and converted by the
    snapshot with the link's current ``LinkFrames``.
    """

    def __init__(self) -> None:
        self.values: dict = {}
        self.pos_origin: np.ndarray | None = None
        self.heartbeat_t = -math.inf
        self.position_t = -math.inf

    def snapshot(self, now: float, frames: LinkFrames | None = None) -> Telemetry:
        hb_age = now - self.heartbeat_t
        values = self.values
        if self.pos_origin is not None:
            pos = self.pos_origin if frames is None else frames.to_home(self.pos_origin)
            values = {**values, "pos_ned_m": pos}
        return Telemetry(**values, connected=hb_age < HEARTBEAT_TIMEOUT_S,
                         heartbeat_age_s=hb_age, position_age_s=now - self.position_t)


class VehicleLink:
    """MAVLink link to one autopilot through MAVSDK 4.x (asyncio).

    Parameters
    ----------
    role : str
        ``"companion"`` (MAVSDK ComponentType.COMPANION_COMPUTER) or ``"gcs"``
        (GROUND_STATION, as ``companion upload/download``).
    streams : StreamSettings, optional
        The telemetry the link asks for (``companion.link.streams``). Default: the defaults
        for a companion, nothing for a ground station (mission transfers need no streams).
    adsb : bool
        Also ask for ADSB_VEHICLE (ADS-B traffic as threats).

    Examples
    --------
    >>> link = VehicleLink()                                    # doctest: +SKIP
    >>> await link.connect("udpin://0.0.0.0:14540", timeout_s=10)
    >>> await link.wait_position(5.0); link.telemetry.pos_ned_m
    >>> await link.set_mode("GUIDED"); await link.arm(); await link.takeoff(10.0)
    >>> link.send_setpoint(pos_ned_m=[0, 0, -10], vel_ned_m_s=[0, 0, 0], yaw_rad=0.0)
    """

    def __init__(self, role: str = "companion", *, streams: StreamSettings | None = None,
                 adsb: bool = False, signing_key: SigningKey | None = None) -> None:
        if role not in ("companion", "gcs"):
            raise LinkError(f"role must be 'companion' or 'gcs', got {role!r}")
        self.role = role
        self.url: str | None = None
        self.target_system = 1
        self.target_component = 1
        self.frames = LinkFrames()
        if streams is None and role == "companion":
            streams = StreamSettings()
        self.stream_settings = streams
        self.adsb = bool(adsb)
        self.signing_key = signing_key
        self.gate: GateThread | None = None
        self.streams: StreamKeeper | None = None
        self.statustexts: collections.deque = collections.deque(maxlen=STATUSTEXT_KEEP)
        self._mavsdk = None
        self._system = None
        self._direct = None        # MavlinkDirectAsync (commands, subscriptions)
        self._direct_sync = None   # MavlinkDirect (non-blocking sends from the loop)
        self._mission = None
        self._telemetry_plugin = None
        self._state = TelemetryState()
        self._tasks: list[asyncio.Task] = []
        self._t0 = time.monotonic()
        self._link_listeners: list[Callable[[bool], None]] = []
        self._was_connected = False
        self._command_lock: asyncio.Lock | None = None
        self._in_flight: set[asyncio.Future] = set()      # MAVSDK command calls still running
        self._mission_lock: asyncio.Lock | None = None

    # ----------------------------------------------------------------- connection

    async def connect(self, url: str = DEFAULT_URL, timeout_s: float = 10.0) -> None:
        """Open ``url`` and wait up to ``timeout_s`` for an autopilot, then start telemetry.

        Raises
        ------
        LinkError
            Bad URL, the URL cannot be opened, or no autopilot within ``timeout_s``.
        """
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk, MavsdkConnectionError
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
        from mavsdk.plugins.mavlink_direct import MavlinkDirect

        check_url(url)
        route_mavsdk_logs()
        kind = (ComponentType.COMPANION_COMPUTER if self.role == "companion"
                else ComponentType.GROUND_STATION)
        self.gate = open_gate(url, self.signing_key)
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(kind))
        self._command_lock = asyncio.Lock()
        self._mission_lock = asyncio.Lock()
        try:
            await self._mavsdk.add_any_connection(self.gate.mavsdk_url)
        except MavsdkConnectionError as exc:
            self.close()
            raise LinkError(f"cannot open {url}: {exc}") from None
        system = await self._mavsdk.first_autopilot(timeout_s=float(timeout_s))
        if system is None:
            why = silence_reason(self.gate.inbound.counts, self.signing_key)
            self.close()
            raise LinkError(f"no autopilot heard on {url} within {timeout_s:g} s ({why})")
        self.url = url
        self._system = system
        self.target_system = await system.get_system_id()
        self._direct = MavlinkDirectAsync(system)
        self._direct_sync = MavlinkDirect(system._system)
        self._mission = MissionRawAsync(system)
        self._telemetry_plugin = TelemetryAsync(system)
        self._state.heartbeat_t = time.monotonic()
        self._was_connected = True
        if self.stream_settings is not None:
            self.streams = StreamKeeper(self, self.stream_settings, adsb=self.adsb)
        self._start_subscriptions()
        log.info("connected to system %d on %s", self.target_system, url)

    def close(self) -> None:
        """Stop the subscriptions and release MAVSDK (idempotent)."""
        for task in self._tasks:
            task.cancel()
        self._tasks.clear()
        # MAVSDK aborts the process if it is destroyed while a plugin or a System it handed out
        # is alive: release them first, newest first
        for owned in (self._telemetry_plugin, self._mission, self._direct_sync, self._direct,
                      getattr(self._system, "_system", None)):
            if owned is not None:
                with contextlib.suppress(Exception):
                    owned.destroy()
        self._telemetry_plugin = self._mission = self._direct_sync = self._direct = self._system = None
        if self._mavsdk is not None:
            with contextlib.suppress(Exception):
                self._mavsdk.destroy()
        self._mavsdk = None
        if self.gate is not None:
            self.gate.close()
        self.gate = None

    async def aclose(self) -> None:
        """Cancel the subscriptions, let them unsubscribe, then release MAVSDK (idempotent)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.gather(*tasks, return_exceptions=True)
        if self._in_flight:              # MAVSDK ends each within its own retries (a few seconds)
            await asyncio.wait(set(self._in_flight), timeout=IN_FLIGHT_WAIT_S)
        self.close()

    async def __aenter__(self) -> "VehicleLink":
        return self

    async def __aexit__(self, *exc) -> None:
        await self.aclose()

    def on_link_change(self, callback: Callable[[bool], None]) -> None:
        """Call ``callback(connected)`` on the loop when the heartbeat is lost or is back."""
        self._link_listeners.append(callback)

    @property
    def connected(self) -> bool:
        """True while heartbeats arrive (within ``HEARTBEAT_TIMEOUT_S``)."""
        return time.monotonic() - self._state.heartbeat_t < HEARTBEAT_TIMEOUT_S

    async def wait_connected(self, timeout_s: float | None = None) -> bool:
        """Wait until heartbeats arrive again (MAVSDK keeps the connection open meanwhile)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.connected:
            if deadline is not None and time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.05)
        return True

    # ----------------------------------------------------------------- telemetry

    @property
    def telemetry(self) -> Telemetry:
        """The latest vehicle state (a new immutable snapshot on every access)."""
        return self._state.snapshot(time.monotonic(), self.frames)

    def set_planning_home(self, home_lla) -> LinkFrames:
        """Freeze the home frame: positions in and out of the link are about ``home_lla`` from
        now on, converted with the vehicle's EKF origin if it reported one
        (``companion.link.frames``). Returns the frames."""
        origin = self._state.values.get("origin_lla")
        self.frames = LinkFrames.build(home_lla, origin)
        if origin is None:
            log.info("the vehicle reports no EKF origin (GPS_GLOBAL_ORIGIN): its local frame is "
                     "taken to be home's")
        else:
            log.info("home %.7f, %.7f, %.2f m; EKF origin %.7f, %.7f, %.2f m; home in the "
                     "vehicle's local frame: %s m", *self.frames.home_lla, *origin,
                     np.round(self.frames.home_in_origin_ned_m, 3).tolist())
        return self.frames

    def to_home_frame(self, pos_origin_ned_m) -> np.ndarray:
        """A LOCAL_POSITION_NED position (vehicle frame) in the planning home's frame."""
        return self.frames.to_home(pos_origin_ned_m)

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
                await self.command_result(MAV_CMD_REQUEST_MESSAGE, (MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,),
                                          what="request GPS_GLOBAL_ORIGIN", timeout_s=1.0)
            await asyncio.sleep(0.05)
        return self._state.values["origin_lla"]

    def statustexts_since(self, t_monotonic_s: float) -> list[str]:
        """The vehicle's STATUSTEXTs received since ``t_monotonic_s`` (oldest first)."""
        return [text for t, _, text in list(self.statustexts) if t >= t_monotonic_s]

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

    async def messages(self, name: str) -> AsyncIterator[dict]:
        """Raw MAVLink messages named ``name`` (e.g. ``"SERVO_OUTPUT_RAW"``) as field dicts.

        Each dict has the message fields plus ``"_sysid"``, ``"_compid"`` and ``"_t_s"``
        (monotonic arrival time).
        """
        self._require_connected()
        async for msg in self._direct.subscribe_message(name):
            try:
                fields = json.loads(msg.fields_json)
            except json.JSONDecodeError:
                continue
            fields["_sysid"] = msg.system_id
            fields["_compid"] = msg.component_id
            fields["_t_s"] = time.monotonic()
            yield fields

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

    def _from_vehicle(self, fields: dict) -> bool:
        return fields.get("_sysid") == self.target_system

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
            if base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self._state.values["mode"] = custom_mode
            self._state.values["armed"] = bool(base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
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
            lat, lon = lla[0] / 1e7, lla[1] / 1e7
            if (lat, lon) != (0.0, 0.0) and abs(lat) <= 90.0 and abs(lon) <= 180.0:
                origin = (lat, lon, lla[2] / 1e3)
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
            lat, lon = lla[0] / 1e7, lla[1] / 1e7
            if (lat, lon) != (0.0, 0.0) and abs(lat) <= 90.0 and abs(lon) <= 180.0:
                self._state.values["home_lla"] = (lat, lon, lla[2] / 1e3)
            self._note("HOME_POSITION")
        await self._guarded("HOME_POSITION", lambda: self.messages("HOME_POSITION"), apply)

    async def request_home(self) -> None:
        """Ask for HOME_POSITION (REQUEST_MESSAGE 242); the answer updates the telemetry."""
        await self.command_long(MAV_CMD_REQUEST_MESSAGE, (MAVLINK_MSG_ID_HOME_POSITION,),
                                what="request HOME_POSITION", timeout_s=3.0)

    async def _watch_global_position(self) -> None:
        def apply(pos) -> None:
            values = finite_fields(pos, "latitude_deg", "longitude_deg", "absolute_altitude_m",
                                   "relative_altitude_m")
            if values is None:
                return
            self._state.values.update(zip(("lat_deg", "lon_deg", "alt_amsl_m", "rel_alt_m"), values))
            self._note("GLOBAL_POSITION_INT")
        await self._guarded("position", self._telemetry_plugin.subscribe_position, apply)

    # ----------------------------------------------------------------- commands

    def _require_connected(self) -> None:
        if self._system is None or self._mavsdk is None:
            raise LinkError("the link is not connected (call connect() first)")

    def _command_message(self, command: int, params):
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        # MavlinkDirect takes strict JSON, which has no NaN: unset parameters travel as 0
        values = [float(p) if math.isfinite(float(p)) else 0.0 for p in params]
        values += [0.0] * (7 - len(values))
        fields = {"target_system": self.target_system, "target_component": self.target_component,
                  "command": int(command), "confirmation": 0}
        fields.update({f"param{k + 1}": v for k, v in enumerate(values)})
        return MavlinkMessage("COMMAND_LONG", 0, 0, self.target_system, self.target_component,
                              json.dumps(fields))

    async def command_result(self, command: int, params=(), *, what: str | None = None,
                             timeout_s: float = 10.0) -> int | None:
        """Send COMMAND_LONG and return the MAV_RESULT of its COMMAND_ACK (None: no final ack
        within ``timeout_s``). Never raises for a refusal: see ``command_long``."""
        from mavsdk.plugins.mavlink_direct import MavlinkDirectError

        self._require_connected()
        message = self._command_message(command, params)
        label = what or f"command {command}"
        async with self._command_lock:
            # MAVSDK's blocking call runs in a thread we keep track of: releasing MAVSDK while it
            # waits would leave that thread blocked for good (see ``aclose``)
            call = asyncio.get_running_loop().run_in_executor(None, self._direct_sync.send_command, message)
            self._in_flight.add(call)
            call.add_done_callback(self._command_call_done)
            try:
                ack = await asyncio.wait_for(asyncio.shield(call), timeout_s)
            except asyncio.TimeoutError:
                log.info("%s: no COMMAND_ACK within %g s", label, timeout_s)
                return None
            except MavlinkDirectError as exc:
                log.info("%s: no COMMAND_ACK (%s)", label, exc.result.name)
                return None
        try:
            result = int(json.loads(ack.fields_json).get("result", -1))
        except (json.JSONDecodeError, TypeError, ValueError, AttributeError):
            log.info("%s: unreadable COMMAND_ACK", label)
            return None
        log.log(logging.INFO if result == 0 else logging.DEBUG, "%s: %s", label,
                MAV_RESULT_NAMES.get(result, result))
        return result

    def _command_call_done(self, call: asyncio.Future) -> None:
        self._in_flight.discard(call)
        if not call.cancelled():
            call.exception()             # retrieved: a late failure after our timeout is no error

    async def command_long(self, command: int, params=(), *, what: str | None = None,
                           timeout_s: float = 10.0) -> None:
        """Send COMMAND_LONG and check its COMMAND_ACK.

        Parameters
        ----------
        command : int
            MAV_CMD.
        params : sequence of up to 7 floats
            param1..param7 (missing ones are 0).

        Raises
        ------
        LinkError
            No final ack (naming ``what``).
        VehicleRefused
            The vehicle answered anything but ACCEPTED (naming the MAV_RESULT and the
            vehicle's last STATUSTEXT, e.g. ``PreArm: Motor Interlock Enabled``).
        """
        label = what or f"command {command}"
        sent_t = time.monotonic()
        result = await self.command_result(command, params, what=label, timeout_s=timeout_s)
        if result is None:
            raise LinkError(f"{label}: no COMMAND_ACK within {timeout_s:g} s")
        if result != 0:
            raise VehicleRefused(self.refusal_text(label, result, sent_t), result)

    def refusal_text(self, label: str, result: int | None, since_monotonic_s: float) -> str:
        """``"<label> refused by the vehicle: FAILED (PreArm: ...)"``: the MAV_RESULT and the
        vehicle's most telling STATUSTEXT since ``since_monotonic_s`` (a PreArm/Arm line first)."""
        texts = self.statustexts_since(since_monotonic_s - 0.5)
        telling = [t for t in texts if t.startswith(("PreArm", "Arm"))] or texts
        why = f" ({telling[-1]})" if telling else ""
        name = "no answer" if result is None else MAV_RESULT_NAMES.get(result, result)
        return f"{label} refused by the vehicle: {name}{why}"

    async def set_mode(self, mode) -> None:
        """Switch to an ArduCopter mode (name or number) with DO_SET_MODE and wait to see it."""
        number = mode_number(mode)
        name = COPTER_MODE_NAMES.get(number, str(number))
        await self.command_long(MAV_CMD_DO_SET_MODE,
                                (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, number),
                                what=f"set mode {name}")
        await self.wait_for(lambda t: t.mode == number, 5.0, f"mode {name} in the heartbeat")

    async def arm(self) -> None:
        """Arm (COMPONENT_ARM_DISARM 1); ``LinkError`` if the vehicle refuses."""
        await self.command_long(MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), what="arm")
        await self.wait_for(lambda t: bool(t.armed), 5.0, "armed state")

    async def disarm(self, force: bool = False) -> None:
        """Disarm (``force``: even in the air, ArduPilot's 21196 magic)."""
        await self.command_long(MAV_CMD_COMPONENT_ARM_DISARM,
                                (0.0, FORCE_DISARM_MAGIC if force else 0.0), what="disarm")

    async def takeoff(self, alt_m: float) -> None:
        """GUIDED takeoff to ``alt_m`` above home (NAV_TAKEOFF param7); vehicle must be armed."""
        if not (math.isfinite(alt_m) and alt_m > 0.0):
            raise LinkError(f"takeoff altitude alt_m must be > 0, got {alt_m}")
        await self.command_long(MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, float(alt_m)),
                                what=f"takeoff to {alt_m:g} m")

    async def land(self) -> None:
        """Land here (NAV_LAND)."""
        await self.command_long(MAV_CMD_NAV_LAND, (), what="land")

    async def return_to_launch(self) -> None:
        """Return to launch (NAV_RETURN_TO_LAUNCH)."""
        await self.command_long(MAV_CMD_NAV_RETURN_TO_LAUNCH, (), what="return to launch")

    async def start_mission(self) -> None:
        """AUTO: fly the stored mission (mode AUTO, then MISSION_START)."""
        await self.set_mode("AUTO")
        await self.command_long(MAV_CMD_MISSION_START, (0, 0), what="mission start")

    async def set_message_interval(self, message_id: int, rate_hz: float) -> None:
        """SET_MESSAGE_INTERVAL for one message id (rate 0 = stop)."""
        interval_us = -1.0 if rate_hz <= 0 else 1e6 / rate_hz
        await self.command_long(MAV_CMD_SET_MESSAGE_INTERVAL, (message_id, interval_us),
                                what=f"message interval of {message_id}")

    async def aux_function(self, function: int, switch: int, *, timeout_s: float = 3.0) -> int | None:
        """MAV_CMD_DO_AUX_FUNCTION (an RC switch function, e.g. 32 MOTOR_INTERLOCK) at switch
        position ``switch`` (0 low, 1 middle, 2 high); returns the MAV_RESULT (None: no ack)."""
        return await self.command_result(MAV_CMD_DO_AUX_FUNCTION, (function, switch),
                                         what=f"aux function {function} switch {switch}",
                                         timeout_s=timeout_s)

    async def read_params(self, names, timeout_s: float = 2.0) -> dict[str, float]:
        """Read parameters with PARAM_REQUEST_READ (sent twice, all at once).

        Returns
        -------
        dict
            Name -> value (ArduPilot encoding: the value as a float) of those the vehicle
            answered within ``timeout_s``; a parameter the vehicle does not have is absent.
        """
        self._require_connected()
        wanted = {str(n) for n in names}
        got: dict[str, float] = {}

        async def collect() -> None:
            async for fields in self.messages("PARAM_VALUE"):
                name = str(fields.get("param_id", "")).rstrip("\x00")
                if self._from_vehicle(fields) and name in wanted:
                    got[name] = float(fields.get("param_value", math.nan))
                    if len(got) == len(wanted):
                        return

        waiter = asyncio.ensure_future(collect())
        await asyncio.sleep(0)                    # subscribed before the requests go out
        try:
            for attempt in range(2):
                for name in sorted(wanted - set(got)):
                    self.send_message("PARAM_REQUEST_READ", {
                        "target_system": self.target_system, "target_component": self.target_component,
                        "param_id": name, "param_index": -1})
                done, _ = await asyncio.wait({waiter}, timeout=timeout_s / 2.0)
                if done:
                    break
        finally:
            waiter.cancel()
            await asyncio.gather(waiter, return_exceptions=True)
        log.info("parameters read: %s%s", ", ".join(f"{k}={v:g}" for k, v in sorted(got.items())) or "none",
                 "" if len(got) == len(wanted) else f"; not on the vehicle: {', '.join(sorted(wanted - set(got)))}")
        return got

    def send_message(self, name: str, fields: dict) -> None:
        """Send one MAVLink message ``name`` with ``fields`` now (non-blocking)."""
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        self._require_connected()
        self._direct_sync.send_message(MavlinkMessage(name, 0, 0, self.target_system,
                                                      self.target_component, json.dumps(fields)))

    # ----------------------------------------------------------------- setpoints

    def send_setpoint(self, pos_ned_m=None, vel_ned_m_s=None, acc_ned_m_s2=None, yaw_rad=None,
                      yaw_rate_rad_s=None) -> None:
        """Send one SET_POSITION_TARGET_LOCAL_NED now (non-blocking; call from the loop thread).

        ``None`` fields are masked out in ``type_mask``. Raises ``LinkError`` for non-finite
        values (nothing is sent then). ``pos_ned_m`` is about the planning home and is sent
        in the vehicle's local frame (``frames.to_origin``).
        """
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        self._require_connected()
        if pos_ned_m is not None:
            pos_ned_m = self.frames.to_origin(pos_ned_m)
        time_boot_ms = int((time.monotonic() - self._t0) * 1000.0)
        fields = setpoint_fields(time_boot_ms, self.target_system, self.target_component,
                                 pos_ned_m, vel_ned_m_s, acc_ned_m_s2, yaw_rad, yaw_rate_rad_s)
        message = MavlinkMessage("SET_POSITION_TARGET_LOCAL_NED", 0, 0, self.target_system,
                                 self.target_component, json.dumps(fields))
        self._direct_sync.send_message(message)

    def send_statustext(self, text: str, severity: int | str = "NOTICE") -> None:
        """Send one STATUSTEXT to the ground stations (non-blocking; call from the loop thread).

        STATUSTEXT has no target: the autopilot forwards it to its other links (ArduPilot's
        MAVLink routing; ``sim-vehicle`` does the same), so QGroundControl and MAVProxy show it.

        Parameters
        ----------
        text : str
            Cut to ``STATUSTEXT_MAX_CHARS`` (50) characters; non-ASCII characters become ``?``.
        severity : int or str
            A MAV_SEVERITY value (pymavlink's ``mavutil.mavlink.MAV_SEVERITY_NOTICE`` ...) or its
            name with or without the prefix (``"NOTICE"``, ``"MAV_SEVERITY_WARNING"``).

        Raises
        ------
        LinkError
            Not connected, or an unknown severity (nothing is sent then).
        """
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        self._require_connected()
        name = severity.upper().removeprefix("MAV_SEVERITY_") if isinstance(severity, str) else None
        level = MAV_SEVERITY_NAMES.index(name) if name in MAV_SEVERITY_NAMES else severity
        if not (isinstance(level, int) and not isinstance(level, bool) and 0 <= level < len(MAV_SEVERITY_NAMES)):
            raise LinkError(f"severity: expected a MAV_SEVERITY value 0..7 or one of "
                            f"{', '.join(MAV_SEVERITY_NAMES)}, got {severity!r}")
        body = str(text).encode("ascii", "replace").decode("ascii")[:STATUSTEXT_MAX_CHARS]
        fields = {"severity": level, "text": body, "id": 0, "chunk_seq": 0}
        self._direct_sync.send_message(MavlinkMessage("STATUSTEXT", 0, 0, 0, 0, json.dumps(fields)))
        log.debug("STATUSTEXT %d %r sent", level, body)

    # ----------------------------------------------------------------- missions

    async def download_raw(self) -> tuple[list[RawItem], list[RawItem], list[RawItem]]:
        """Download the mission, fence and rally lists as ``RawItem`` lists."""
        from mavsdk.plugins.mission_raw import MissionRawError, MissionRawResult

        self._require_connected()
        lists = []
        for name, fetch in (("mission", self._mission.download_mission),
                            ("fence", self._mission.download_geofence),
                            ("rally", self._mission.download_rallypoints)):
            try:
                items = await fetch()
            except MissionRawError as exc:
                if exc.result == MissionRawResult.NO_MISSION_AVAILABLE:
                    items = []
                else:
                    raise LinkError(f"{name} download failed: {exc.result.name}") from None
            lists.append([from_mavsdk_item(i) for i in (items or [])])
        return lists[0], lists[1], lists[2]

    async def download_plan(self) -> MissionPlan:
        """Download mission + fence + rally as a ``MissionPlan`` (seq 0 = home, ArduPilot)."""
        async with self._mission_lock:
            mission, fence, rally = await self.download_raw()
        try:
            return raw_to_plan(mission, fence, rally)
        except MissionError as exc:
            raise LinkError(f"the vehicle's lists cannot be read: {exc}") from None

    async def upload_plan(self, plan: MissionPlan, home_lla=None) -> None:
        """Upload mission, fence and rally like a ground station; all or nothing.

        The plan is validated first (a bad plan uploads nothing). The vehicle replaces each
        list only when its transfer completes; if a later list fails, the lists already replaced
        are restored from a download taken before the upload.

        Raises
        ------
        MissionError
            The plan is invalid (nothing sent).
        LinkError
            A transfer failed (the previous lists are restored when possible).
        """
        plan.validate()
        lists = (("mission", mission_to_raw(plan, home_lla)), ("fence", fence_to_raw(plan)),
                 ("rally", rally_to_raw(plan)))
        async with self._mission_lock:
            backup = await self.download_raw()
            done: list[int] = []
            for k, (name, raw) in enumerate(lists):
                try:
                    await self._upload_list(name, raw)
                except LinkError as exc:
                    await self._restore(backup, done)
                    outcome = ("the lists already replaced were restored" if done
                               else "nothing was changed")
                    raise LinkError(f"{exc}; {outcome}") from None
                done.append(k)
        log.info("uploaded %d mission items, %d fence items, %d rally points",
                 len(plan.items), len(lists[1][1]), len(plan.rally))

    async def _upload_list(self, name: str, raw: list[RawItem]) -> None:
        from mavsdk.plugins.mission_raw import MissionRawError

        upload = {"mission": self._mission.upload_mission,
                  "fence": self._mission.upload_geofence,
                  "rally": self._mission.upload_rally_points}[name]
        try:
            if raw:
                await upload([to_mavsdk_item(r) for r in raw])
            else:
                await self._clear_list(name)
        except MissionRawError as exc:
            raise LinkError(f"{name} upload failed: {exc.result.name}") from None

    async def clear_plan(self) -> None:
        """Clear the vehicle's mission, fence and rally lists (each confirmed by MISSION_ACK)."""
        self._require_connected()
        async with self._mission_lock:
            for name in ("mission", "fence", "rally"):
                await self._clear_list(name)

    async def _clear_list(self, name: str, attempts: int = 3, timeout_s: float = 1.5) -> None:
        """Clear one list: MISSION_CLEAR_ALL for its mission type, confirmed by MISSION_ACK.

        (MAVSDK's MissionRaw refuses to upload an empty list, so clearing is done directly.)
        """
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        mission_type = {"mission": 0, "fence": 1, "rally": 2}[name]
        fields = {"target_system": self.target_system, "target_component": self.target_component,
                  "mission_type": mission_type}
        message = MavlinkMessage("MISSION_CLEAR_ALL", 0, 0, self.target_system,
                                 self.target_component, json.dumps(fields))

        async def wait_ack() -> int:
            async for ack in self.messages("MISSION_ACK"):
                if ack.get("_sysid") == self.target_system and \
                        int(ack.get("mission_type", 0)) == mission_type:
                    return int(ack.get("type", -1))
            return -1

        for _ in range(attempts):
            waiter = asyncio.ensure_future(wait_ack())
            await asyncio.sleep(0)               # subscribed before the request goes out
            self._direct_sync.send_message(message)
            try:
                result = await asyncio.wait_for(waiter, timeout_s)
            except asyncio.TimeoutError:
                continue
            if result != 0:
                raise LinkError(f"{name} clear refused: MAV_MISSION_RESULT {result}")
            return
        raise LinkError(f"{name} clear: no MISSION_ACK after {attempts} attempts")

    async def _restore(self, backup, done: list[int]) -> None:
        names = ("mission", "fence", "rally")
        for k in done:
            try:
                await self._upload_list(names[k], backup[k])
            except LinkError as exc:
                log.error("could not restore the previous %s: %s", names[k], exc)


def to_mavsdk_item(raw: RawItem):
    """``RawItem`` -> ``mavsdk.plugins.mission_raw.MissionItem``."""
    from mavsdk.plugins.mission_raw import MissionItem

    return MissionItem(raw.seq, raw.frame, raw.command, raw.current, raw.autocontinue,
                       raw.param1, raw.param2, raw.param3, raw.param4, raw.x, raw.y, raw.z,
                       raw.mission_type)


def from_mavsdk_item(item) -> RawItem:
    """``mavsdk.plugins.mission_raw.MissionItem`` -> ``RawItem``."""
    return RawItem(int(item.seq), int(item.frame), int(item.command), int(item.current),
                   int(item.autocontinue), float(item.param1), float(item.param2),
                   float(item.param3), float(item.param4), int(item.x), int(item.y),
                   float(item.z), int(item.mission_type))


def route_mavsdk_logs() -> None:
    """Send MAVSDK's C++ log lines to Python logging (logger ``mavsdk``) instead of stderr."""
    from mavsdk import logging as mavsdk_logging

    mav_log = logging.getLogger("mavsdk")
    # MAVSDK info chatter (version, discovery) is debug for us; warnings and errors stay
    levels = {0: logging.DEBUG, 1: logging.DEBUG, 2: logging.WARNING, 3: logging.ERROR}

    def forward(level, message, file, line) -> bool:
        mav_log.log(levels.get(int(level), logging.INFO), "%s", message)
        return True

    mavsdk_logging.log_subscribe(forward)
