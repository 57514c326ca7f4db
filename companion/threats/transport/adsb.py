"""ADS-B traffic as moving threats (DESIGN section 7; ArduPilot's AP_Avoidance feeds on the same).

An ADSB_VEHICLE message (from the vehicle's ADS-B receiver, forwarded by the autopilot) becomes
a moving threat with

- id ``adsb-<ICAO address, hex>`` (e.g. ``adsb-4b1805``), so every report of one aircraft
  replaces the last;
- frame ``global`` (latitude, longitude, altitude AMSL; the threat table converts it about
  home), stamped ``tslc`` seconds (the report's "time since last communication") before receipt;
- velocity NED from the course over ground (``heading``), the horizontal speed and the vertical
  speed (positive up in ADSB_VEHICLE), each used only when its validity flag is set;
- a radius by emitter type (:class:`AdsbSettings`: a light aircraft is smaller than an airliner's
  wake), and a ttl of a few seconds, refreshed by every report: a target no longer heard
  disappears by itself;
- traffic ``manned`` for every emitter but a UAV and a surface vehicle or point obstacle (and
  for an unknown emitter: ADS-B Out is what manned aircraft carry), so that it is judged with the
  aviation volumes (``companion.threats.alerts``).

Reports without valid coordinates or altitude, or farther than ``max_range_m`` from home, are
ignored. The conversion is pure; ``companion.daemon`` feeds the messages to the threat reactor,
which treats each threat exactly as a zenoh PUT and republishes it on
``uav/<sysid>/threats/adsb-...`` for other consumers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError
from companion.threats.model import Threat
from companion.threats.transport.codec import MAX_SPEED_M_S
from heli_common.typed_config import require_numbers

__all__ = ["AdsbSettings", "threat_from_adsb", "adsb_threat_id", "emitter_radius_m", "emitter_traffic"]

FLAG_COORDS = mavlink.ADSB_FLAGS_VALID_COORDS
FLAG_ALTITUDE = mavlink.ADSB_FLAGS_VALID_ALTITUDE
FLAG_HEADING = mavlink.ADSB_FLAGS_VALID_HEADING
FLAG_VELOCITY = mavlink.ADSB_FLAGS_VALID_VELOCITY
FLAG_VERTICAL_VELOCITY = mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID

#: Emitter types (ADSB_EMITTER_TYPE) by radius class.
EMITTER_CLASSES = {
    "light": (
        mavlink.ADSB_EMITTER_TYPE_LIGHT,
        mavlink.ADSB_EMITTER_TYPE_ULTRA_LIGHT,
        mavlink.ADSB_EMITTER_TYPE_GLIDER,
        mavlink.ADSB_EMITTER_TYPE_PARACHUTE,
        mavlink.ADSB_EMITTER_TYPE_LIGHTER_AIR,
    ),
    "small": (mavlink.ADSB_EMITTER_TYPE_SMALL,),
    "large": (
        mavlink.ADSB_EMITTER_TYPE_LARGE,
        mavlink.ADSB_EMITTER_TYPE_HIGH_VORTEX_LARGE,
        mavlink.ADSB_EMITTER_TYPE_HEAVY,
        mavlink.ADSB_EMITTER_TYPE_HIGHLY_MANUV,
        mavlink.ADSB_EMITTER_TYPE_SPACE,
    ),
    "rotorcraft": (mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT,),
    "uav": (mavlink.ADSB_EMITTER_TYPE_UAV,),
    "surface": (
        mavlink.ADSB_EMITTER_TYPE_EMERGENCY_SURFACE,
        mavlink.ADSB_EMITTER_TYPE_SERVICE_SURFACE,
        mavlink.ADSB_EMITTER_TYPE_POINT_OBSTACLE,
    ),
}


@dataclass(frozen=True)
class AdsbSettings:
    """ADS-B traffic as threats (``[adsb]``; ``companion run --adsb``).

    Parameters
    ----------
    enabled : bool
        Ask the vehicle for ADSB_VEHICLE and turn every report into a threat. Default off.
    ttl_s : float
        A target not heard for this long (vehicle seconds) is dropped.
    max_range_m : float
        Reports farther than this from home are ignored (a receiver hears aircraft 100 km
        away; they cannot matter to a mission and would only cost checks).
    radius_m : float
        Radius of a target of unknown type (no info, unassigned).
    radius_light_m, radius_small_m, radius_large_m, radius_rotorcraft_m, radius_uav_m,
    radius_surface_m : float
        Radius by emitter class: light (light, ultralight, glider, parachute, balloon), small,
        large (large, high vortex, heavy, highly manoeuvrable, space), rotorcraft, UAV, surface
        (surface vehicles, point obstacles). Not inflated: the threat policy adds the rotor
        radius and its margin (``threats.inflation_m``).
    """

    enabled: bool = False
    ttl_s: float = 5.0
    max_range_m: float = 5000.0
    radius_m: float = 30.0
    radius_light_m: float = 20.0
    radius_small_m: float = 30.0
    radius_large_m: float = 100.0
    radius_rotorcraft_m: float = 25.0
    radius_uav_m: float = 5.0
    radius_surface_m: float = 10.0

    def __post_init__(self) -> None:
        require_numbers(
            ConfigError,
            "adsb",
            self,
            positive=(
                "ttl_s",
                "max_range_m",
                "radius_m",
                "radius_light_m",
                "radius_small_m",
                "radius_large_m",
                "radius_rotorcraft_m",
                "radius_uav_m",
                "radius_surface_m",
            ),
        )


def adsb_threat_id(icao_address: int) -> str:
    """``adsb-<ICAO address in lower-case hex, 6 digits at least>``."""
    return f"adsb-{int(icao_address):06x}"


def emitter_radius_m(emitter_type: int, settings: AdsbSettings) -> float:
    """The threat radius (m) of an ADSB_EMITTER_TYPE."""
    for name, types in EMITTER_CLASSES.items():
        if int(emitter_type) in types:
            return float(getattr(settings, f"radius_{name}_m"))
    return float(settings.radius_m)


def emitter_traffic(emitter_type: int) -> str:
    """``drone`` for a UAV and a surface emitter, else ``manned`` (``Threat.traffic``)."""
    drone = EMITTER_CLASSES["uav"] + EMITTER_CLASSES["surface"]
    return "drone" if int(emitter_type) in drone else "manned"


def threat_from_adsb(fields: dict, settings: AdsbSettings, now_t_s: float, home=None) -> Threat | None:
    """The threat of one ADSB_VEHICLE report, or None when it cannot or need not be one.

    Parameters
    ----------
    fields : dict
        The message's fields (``ICAO_address``, ``lat``, ``lon`` in 1e-7 deg, ``altitude`` mm,
        ``heading`` cdeg, ``hor_velocity`` and ``ver_velocity`` cm/s, ``emitter_type``,
        ``tslc`` s, ``flags``).
    settings : AdsbSettings
    now_t_s : float
        Receive time on the threat table's clock (the mission clock, vehicle seconds).
    home : companion.geo.LocalFrame, optional
        For the range check (no check without it).

    Returns
    -------
    Threat or None
        ``moving``, ``global`` frame, stamped ``now_t_s - tslc``; None without valid
        coordinates or altitude, or beyond ``max_range_m``.
    """
    flags = int(fields.get("flags", 0))
    if not (flags & FLAG_COORDS and flags & FLAG_ALTITUDE):
        return None
    lat = float(fields.get("lat", 0)) / 1e7
    lon = float(fields.get("lon", 0)) / 1e7
    alt_m = float(fields.get("altitude", 0)) / 1e3
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and abs(alt_m) <= 100_000.0):
        return None
    if home is not None:
        n, e, d = home.to_ned(lat, lon, alt_m)
        if math.sqrt(float(n) ** 2 + float(e) ** 2 + float(d) ** 2) > settings.max_range_m:
            return None
    vn = ve = vd = 0.0
    if flags & FLAG_HEADING and flags & FLAG_VELOCITY:
        speed = min(float(fields.get("hor_velocity", 0)) / 100.0, MAX_SPEED_M_S)
        course = math.radians(float(fields.get("heading", 0)) / 100.0)
        vn, ve = speed * math.cos(course), speed * math.sin(course)
    if flags & FLAG_VERTICAL_VELOCITY:
        vd = float(np.clip(-float(fields.get("ver_velocity", 0)) / 100.0, -MAX_SPEED_M_S, MAX_SPEED_M_S))
    age_s = min(max(float(fields.get("tslc", 0)), 0.0), settings.ttl_s)
    return Threat(
        id=adsb_threat_id(fields.get("ICAO_address", 0)),
        kind="moving",
        frame="global",
        position=(lat, lon, alt_m),
        velocity_ned_m_s=(vn, ve, vd),
        radius_m=emitter_radius_m(fields.get("emitter_type", 0), settings),
        ttl_s=settings.ttl_s,
        received_t_s=now_t_s - age_s,
        traffic=emitter_traffic(fields.get("emitter_type", 0)),
    )
