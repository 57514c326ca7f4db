"""The vehicle state as the link knows it: the immutable ``Telemetry`` snapshot, the mutable
``TelemetryState`` behind it (owned and kept up to date by ``companion.link.watchers``), and
``finite_fields``, the check every received message passes before it is applied.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from companion.link.frames import LinkFrames
from heli_common.mavlink_ids import COPTER_MODE_NAMES

#: Seconds without a HEARTBEAT after which the link counts as lost.
HEARTBEAT_TIMEOUT_S = 3.0


def finite_fields(fields, *names: str) -> list[float] | None:
    """The named fields of a message (a MavlinkDirect dict or a MAVSDK struct) as floats, or
    None when one is missing, null or not finite: such a message is dropped, never applied."""
    get = fields.get if isinstance(fields, dict) else lambda name: getattr(fields, name, None)
    try:
        values = [float(get(name)) for name in names]
    except (TypeError, ValueError):
        return None
    return values if all(map(math.isfinite, values)) else None


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
        return Telemetry(
            **values,
            connected=hb_age < HEARTBEAT_TIMEOUT_S,
            heartbeat_age_s=hb_age,
            position_age_s=now - self.position_t,
        )
