"""Traffic alerts for the ground station: who is predicted to lose well clear, when, and what
the companion does about it (DESIGN 7.5; after ArduPilot's ``AP_Avoidance``).

A threat is *predicted to lose well clear* when, flown at constant velocity from its last
report, it comes inside its well-clear volume around the reference the vehicle is flying
within ``AlertSettings.horizon_s``. The volumes are the validation campaign's
(``companion.campaign.judge.Volumes``), so what the operator is told is what the campaign
counts:

- *drone scale* (zenoh threats, ADS-B UAVs and surface emitters): spheres of the threat's
  radius plus ``drone_lowc_extra_m`` (well clear) and ``drone_nmac_extra_m`` (NMAC);
- *manned traffic* (``Threat.traffic == "manned"``: every other ADS-B emitter): cylinders of
  ``manned_wc_h_m`` / ``manned_wc_v_m`` (2000 ft / 250 ft, ASTM F3442) and ``manned_nmac_h_m``
  / ``manned_nmac_v_m`` (500 ft / 100 ft).

The threat level is MAVLink's ``MAV_COLLISION_THREAT_LEVEL``: LOW for a predicted loss of well
clear, HIGH for a predicted NMAC. The alert goes out as ArduPilot's AP_Avoidance sends it:
``COLLISION`` (src, id, action, threat level, time to and distances at the closest approach;
:func:`collision_fields`), and, when a threat is first alerted or its level rises, a STATUSTEXT
(:func:`alert_statustext`). The action is MAVLink's ``MAV_COLLISION_ACTION`` of the decision
that followed (:func:`collision_action`).

Pure: the owner of the alert state is ``companion.flight.alerting.TrafficAlerts``.
"""

from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError
from companion.threats.statustext import STATUSTEXT_MAX_CHARS
from heli_common.typed_config import require_numbers

__all__ = [
    "AlertSettings",
    "Approach",
    "closest_approach",
    "alert_level",
    "collision_action",
    "collision_fields",
    "alert_statustext",
    "collision_id",
    "LEVEL_NAMES",
    "NONE",
    "LOW",
    "HIGH",
    "REPORT",
]

FT_M = 0.3048
#: Another vehicle of the fleet as a threat (``companion.fleet.peers``).
_FLEET_ID = re.compile(r"uav(\d+)(?:-pending)?")
#: The threat levels and the action before any decision (pymavlink's values, for the callers).
NONE, LOW, HIGH = (
    mavlink.MAV_COLLISION_THREAT_LEVEL_NONE,
    mavlink.MAV_COLLISION_THREAT_LEVEL_LOW,
    mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH,
)
REPORT = mavlink.MAV_COLLISION_ACTION_REPORT
#: MAV_COLLISION_THREAT_LEVEL by value, as words for the STATUSTEXT and the record.
LEVEL_NAMES = {
    mavlink.MAV_COLLISION_THREAT_LEVEL_NONE: "none",
    mavlink.MAV_COLLISION_THREAT_LEVEL_LOW: "low",
    mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH: "high",
}


@dataclass(frozen=True)
class AlertSettings:
    """Traffic alerts to the ground station (``[alerts]``).

    Parameters
    ----------
    enabled : bool
        Alert the ground stations (COLLISION and STATUSTEXT). Default on.
    horizon_s : float
        How far ahead a loss of well clear is predicted (s; ArduPilot's ``AVD_W_TIME`` is 30).
    step_s : float
        Spacing of the prediction's samples (s).
    rate_hz : float
        How often an alerted threat is reported again while it lasts (ArduPilot: 1 Hz).
    cleared_report_s : float
        How long a threat no longer predicted to lose well clear is still reported, with threat
        level NONE (s; ArduPilot: 5).
    drone_lowc_extra_m, drone_nmac_extra_m : float
        Drone-scale volumes: metres beyond the threat's radius (the campaign's ``lowc_extra_m``
        and ``nmac_extra_m``).
    manned_wc_h_m, manned_wc_v_m, manned_nmac_h_m, manned_nmac_v_m : float
        Manned traffic: the well-clear and NMAC cylinders (m; 2000 ft, 250 ft, 500 ft, 100 ft).
    """

    enabled: bool = True
    horizon_s: float = 30.0
    step_s: float = 0.25
    rate_hz: float = 1.0
    cleared_report_s: float = 5.0
    drone_lowc_extra_m: float = 3.0
    drone_nmac_extra_m: float = 1.0
    manned_wc_h_m: float = 2000.0 * FT_M
    manned_wc_v_m: float = 250.0 * FT_M
    manned_nmac_h_m: float = 500.0 * FT_M
    manned_nmac_v_m: float = 100.0 * FT_M

    def __post_init__(self) -> None:
        require_numbers(
            ConfigError,
            "alerts",
            self,
            positive=(
                "horizon_s",
                "step_s",
                "rate_hz",
                "manned_wc_h_m",
                "manned_wc_v_m",
                "manned_nmac_h_m",
                "manned_nmac_v_m",
            ),
            non_negative=("cleared_report_s", "drone_lowc_extra_m", "drone_nmac_extra_m"),
        )
        if self.drone_nmac_extra_m > self.drone_lowc_extra_m:
            raise ConfigError("alerts: expected drone_nmac_extra_m <= drone_lowc_extra_m")
        if self.manned_nmac_h_m > self.manned_wc_h_m or self.manned_nmac_v_m > self.manned_wc_v_m:
            raise ConfigError("alerts: the manned NMAC cylinder must lie inside the well-clear one")
        if self.step_s > self.horizon_s:
            raise ConfigError(f"alerts.step_s: must be <= horizon_s ({self.horizon_s:g}), got {self.step_s!r}")


@dataclass(frozen=True)
class Approach:
    """A threat's predicted closest approach to the vehicle's reference.

    Attributes
    ----------
    time_to_cpa_s : float
        From now to the closest approach (s; 0 when it is now).
    horizontal_m, vertical_m : float
        Horizontal and vertical distance between centres there (m).
    time_to_lowc_s : float or None
        From now to the first predicted sample inside the well-clear volume (None: none).
    level : int
        ``MAV_COLLISION_THREAT_LEVEL``: NONE, LOW (loss of well clear), HIGH (NMAC).
    """

    time_to_cpa_s: float
    horizontal_m: float
    vertical_m: float
    time_to_lowc_s: float | None
    level: int


def _inside(
    dh: np.ndarray, dv: np.ndarray, radius_m: float, manned: bool, extra_m: float, h_m: float, v_m: float
) -> np.ndarray:
    if manned:
        return (dh < h_m) & (dv < v_m)
    return np.hypot(dh, dv) < radius_m + extra_m


def closest_approach(
    own_ned_m: np.ndarray,
    threat_ned_m: np.ndarray,
    radius_m: float,
    manned: bool,
    settings: AlertSettings,
    step_s: float,
) -> Approach:
    """The closest approach of two predicted tracks sampled at the same times.

    Parameters
    ----------
    own_ned_m, threat_ned_m : ndarray, shape (K, 3)
        The vehicle's reference and the threat's predicted centre, NED metres, at the times
        ``0, step_s, 2 step_s ...`` from now.
    radius_m : float
        The threat's radius (drone-scale volumes are about it).
    manned : bool
        Manned traffic (cylinders) or drone scale (spheres).
    settings : AlertSettings
    step_s : float

    Returns
    -------
    Approach
        At the sample of least 3D distance, as the campaign's judge takes miss distances.
    """
    rel = np.asarray(threat_ned_m, dtype=float) - np.asarray(own_ned_m, dtype=float)
    dh = np.hypot(rel[:, 0], rel[:, 1])
    dv = np.abs(rel[:, 2])
    k = int(np.argmin(dh * dh + dv * dv))
    s = settings
    lowc = _inside(dh, dv, radius_m, manned, s.drone_lowc_extra_m, s.manned_wc_h_m, s.manned_wc_v_m)
    nmac = _inside(dh, dv, radius_m, manned, s.drone_nmac_extra_m, s.manned_nmac_h_m, s.manned_nmac_v_m)
    first = int(np.argmax(lowc)) if lowc.any() else None
    return Approach(
        k * step_s,
        float(dh[k]),
        float(dv[k]),
        None if first is None else first * step_s,
        alert_level(bool(lowc.any()), bool(nmac.any())),
    )


def alert_level(lowc: bool, nmac: bool) -> int:
    """``MAV_COLLISION_THREAT_LEVEL`` of a predicted loss of well clear / NMAC."""
    if nmac:
        return mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH
    return mavlink.MAV_COLLISION_THREAT_LEVEL_LOW if lowc else mavlink.MAV_COLLISION_THREAT_LEVEL_NONE


def collision_action(kind: str, label: str = "") -> int:
    """``MAV_COLLISION_ACTION`` of a decision (its kind and label).

    - an evasion that only climbs or descends: ASCEND_OR_DESCEND; one that brakes: HOVER; any
      other (a sidestep or a swerve, with or without a climb): MOVE_PERPENDICULAR;
    - a hold (brake to a hover) and a retime (slow down or wait on the path for the threat to
      pass): HOVER;
    - a switch to an alternative and a replan: MOVE_HORIZONTALLY;
    - anything else (the reference is kept): REPORT.

    Examples
    --------
    >>> collision_action("evade", "evade climb") == mavlink.MAV_COLLISION_ACTION_ASCEND_OR_DESCEND
    True
    """
    kind = str(kind)
    if kind == "evade":
        manoeuvre = str(label).removeprefix("evade ").removesuffix(" (refined)")
        if manoeuvre in ("climb", "descend"):
            return mavlink.MAV_COLLISION_ACTION_ASCEND_OR_DESCEND
        if manoeuvre == "brake":
            return mavlink.MAV_COLLISION_ACTION_HOVER
        return mavlink.MAV_COLLISION_ACTION_MOVE_PERPENDICULAR
    if kind in ("hold", "retime"):
        return mavlink.MAV_COLLISION_ACTION_HOVER
    if kind in ("switch", "replan"):
        return mavlink.MAV_COLLISION_ACTION_MOVE_HORIZONTALLY
    return mavlink.MAV_COLLISION_ACTION_REPORT


def collision_id(threat_id: str) -> tuple[int, int]:
    """COLLISION's ``(src, id)`` of a threat: ADSB and the ICAO address for ``adsb-<hex>``;
    otherwise MAVLINK_GPS_GLOBAL_INT and, for another vehicle of the fleet (``uav<sysid>``,
    ``uav<sysid>-pending``), its system id, for any other threat the CRC-32 of its id (a stable
    uint32)."""
    if threat_id.startswith("adsb-"):
        try:
            return mavlink.MAV_COLLISION_SRC_ADSB, int(threat_id[5:], 16) & 0xFFFFFFFF
        except ValueError:
            pass
    fleet = _FLEET_ID.fullmatch(threat_id)
    if fleet:
        return mavlink.MAV_COLLISION_SRC_MAVLINK_GPS_GLOBAL_INT, int(fleet.group(1)) & 0xFFFFFFFF
    return mavlink.MAV_COLLISION_SRC_MAVLINK_GPS_GLOBAL_INT, zlib.crc32(threat_id.encode())


def collision_fields(threat_id: str, approach: Approach, action: int) -> dict:
    """The fields of one ``COLLISION`` message (MAVLink common, id 247), as
    ``AP_Avoidance::send_collision_all`` fills them."""
    src, ident = collision_id(threat_id)
    return {
        "src": int(src),
        "id": int(ident),
        "action": int(action),
        "threat_level": int(approach.level),
        "time_to_minimum_delta": float(approach.time_to_cpa_s),
        "altitude_minimum_delta": float(approach.vertical_m),
        "horizontal_minimum_delta": float(approach.horizontal_m),
    }


def alert_statustext(threat_id: str, approach: Approach) -> tuple[str, str]:
    """The STATUSTEXT of a new or raised alert and its severity (CRITICAL for a predicted NMAC,
    WARNING for a loss of well clear, INFO when cleared).

    Examples
    --------
    >>> a = Approach(12.0, 40.2, 5.1, 9.5, mavlink.MAV_COLLISION_THREAT_LEVEL_LOW)
    >>> alert_statustext("adsb-a00001", a)
    ('TRAFFIC adsb-a00001 LoWC in 10s, 40 m / 5 m', 'WARNING')
    """
    if approach.level == mavlink.MAV_COLLISION_THREAT_LEVEL_NONE:
        return _fit(f"TRAFFIC {threat_id}", " clear"), "INFO"
    what = "NMAC" if approach.level == mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH else "LoWC"
    when = approach.time_to_lowc_s if approach.time_to_lowc_s is not None else approach.time_to_cpa_s
    tail = f" {what} in {math.ceil(when - 1e-9):.0f}s, {approach.horizontal_m:.0f} m / {approach.vertical_m:.0f} m"
    head = _fit(f"TRAFFIC {threat_id}", tail)
    severity = "CRITICAL" if approach.level == mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH else "WARNING"
    return head, severity


def _fit(head: str, tail: str) -> str:
    """``head + tail`` in one STATUSTEXT (50 characters), the head cut first."""
    return head[: max(STATUSTEXT_MAX_CHARS - len(tail), 0)] + tail
