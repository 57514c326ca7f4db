"""MAVLink parameters of ``sim-vehicle``: ArduPilot names and units mapped onto the settings tree.

Parameter protocol: https://mavlink.io/en/services/parameter.html. Values travel as float32
with ArduPilot's encoding (an integer parameter is sent as its value *cast* to float with
``param_type`` INT8/INT16/INT32, not as the bytes of an int), which is what MAVProxy, QGC and
MAVSDK expect from an ArduPilot vehicle. Each parameter has a range; a value outside it, NaN or
infinity is refused: the setting keeps its value, the reply ``PARAM_VALUE`` echoes it and a
warning is logged. Pure: no I/O.
"""

from __future__ import annotations

import dataclasses
import logging
import math

from heli_common.mavlink_ids import mavlink
from sim_vehicle.config import VehicleSettings, get_path, replace_path

log = logging.getLogger(__name__)

MAV_PARAM_TYPE_INT8 = mavlink.MAV_PARAM_TYPE_INT8
MAV_PARAM_TYPE_INT16 = mavlink.MAV_PARAM_TYPE_INT16
MAV_PARAM_TYPE_INT32 = mavlink.MAV_PARAM_TYPE_INT32
MAV_PARAM_TYPE_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One parameter.

    Attributes
    ----------
    name : str
        MAVLink name (at most 16 characters).
    path : str
        Dotted path in :class:`~sim_vehicle.config.VehicleSettings`.
    scale : float
        Parameter value = setting * scale (e.g. 100 for cm/s over m/s).
    minimum, maximum : float
        Accepted range of the parameter value.
    param_type : int
        ``MAV_PARAM_TYPE``.
    description : str
        One line with units.
    """

    name: str
    path: str
    scale: float
    minimum: float
    maximum: float
    param_type: int = MAV_PARAM_TYPE_REAL32
    description: str = ""

    @property
    def is_integer(self) -> bool:
        """True for INT8/16/32 parameters."""
        return self.param_type in (MAV_PARAM_TYPE_INT8, MAV_PARAM_TYPE_INT16, MAV_PARAM_TYPE_INT32)


def _weights(prefix: str, field: str, first_index: int, names: tuple[str, ...], what: str) -> list[ParamSpec]:
    return [
        ParamSpec(
            f"{prefix}{n.upper()}",
            f"controller.{field}#{first_index + i}",
            1.0,
            1e-4,
            1e4,
            description=f"LQI weight on {what} {n}",
        )
        for i, n in enumerate(names)
    ]


def _stream_rates(link: int) -> list[ParamSpec]:
    """ArduPilot 4.7's per-link stream-rate parameters ``MAVn_<group>`` (n = 1..3)."""
    groups = ("RAW_SENS", "EXT_STAT", "RC_CHAN", "RAW_CTRL", "POSITION", "EXTRA1", "EXTRA2", "EXTRA3", "PARAMS", "ADSB")
    return [
        ParamSpec(
            f"MAV{link}_{g}",
            f"link.mav{link}.{g.lower()}",
            1.0,
            0.0,
            50.0,
            MAV_PARAM_TYPE_INT16,
            description=f"out address {link}: {g} stream rate at start, Hz (as ArduPilot: read at boot)",
        )
        for g in groups
    ]


PARAM_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("SIM_SPEEDUP", "timing.speedup", 1.0, 0.1, 1000.0, description="simulation speed-up, x real time"),
    ParamSpec(
        "GUID_TIMEOUT",
        "flight.guided_timeout_s",
        1.0,
        0.1,
        120.0,
        description="GUIDED setpoint timeout before braking, s",
    ),
    ParamSpec("WPNAV_SPEED", "flight.wp_speed_m_s", 100.0, 20.0, 1500.0, description="waypoint speed, cm/s"),
    ParamSpec("WPNAV_SPEED_UP", "flight.wp_speed_up_m_s", 100.0, 10.0, 1000.0, description="climb speed, cm/s"),
    ParamSpec("WPNAV_SPEED_DN", "flight.wp_speed_down_m_s", 100.0, 10.0, 500.0, description="descent speed, cm/s"),
    ParamSpec("WPNAV_ACCEL", "flight.wp_accel_m_s2", 100.0, 50.0, 500.0, description="leg acceleration, cm/s/s"),
    ParamSpec("WPNAV_RADIUS", "flight.wp_radius_m", 100.0, 5.0, 1000.0, description="waypoint radius, cm"),
    ParamSpec("PILOT_SPEED_UP", "flight.takeoff_speed_m_s", 100.0, 10.0, 500.0, description="takeoff climb, cm/s"),
    ParamSpec("LAND_SPEED", "flight.land_speed_m_s", 100.0, 30.0, 200.0, description="final descent, cm/s"),
    ParamSpec(
        "LAND_SPEED_HIGH",
        "flight.land_speed_high_m_s",
        100.0,
        30.0,
        500.0,
        description="descent above the slow-down height, cm/s",
    ),
    ParamSpec("RTL_ALT", "flight.rtl_alt_m", 100.0, 200.0, 30000.0, description="RTL return height, cm"),
    ParamSpec(
        "DISARM_DELAY",
        "flight.disarm_delay_s",
        1.0,
        0.0,
        127.0,
        MAV_PARAM_TYPE_INT8,
        description="disarm after landed this long, s (0 = never)",
    ),
    ParamSpec(
        "FENCE_ENABLE",
        "flight.fence_enable",
        1.0,
        0.0,
        1.0,
        MAV_PARAM_TYPE_INT8,
        description="enforce the uploaded fence (0/1)",
    ),
    ParamSpec(
        "FENCE_ACTION",
        "flight.fence_action",
        1.0,
        0.0,
        4.0,
        MAV_PARAM_TYPE_INT8,
        description="fence breach: 0 report, 1 RTL, 2 LAND, 4 BRAKE",
    ),
    ParamSpec("FENCE_ALT_MAX", "flight.fence_alt_max_m", 1.0, 10.0, 1000.0, description="fence ceiling, m"),
    ParamSpec(
        "SIM_PREARM_FAIL",
        "flight.prearm_fail",
        1.0,
        0.0,
        1.0,
        MAV_PARAM_TYPE_INT8,
        description="fault injection: pre-arm checks fail (0/1)",
    ),
    ParamSpec(
        "H_RSC_MODE",
        "rsc.mode",
        1.0,
        1.0,
        4.0,
        MAV_PARAM_TYPE_INT8,
        description="rotor speed control mode 1..4 (all run up alike here)",
    ),
    ParamSpec(
        "H_RSC_RUNUP_TIME", "rsc.runup_time_s", 1.0, 1.0, 60.0, MAV_PARAM_TYPE_INT8, description="rotor run-up time, s"
    ),
    ParamSpec(
        "H_RSC_RAMP_TIME", "rsc.ramp_time_s", 1.0, 0.0, 60.0, MAV_PARAM_TYPE_INT8, description="RSC output ramp time, s"
    ),
    ParamSpec(
        "H_RSC_CRITICAL",
        "rsc.critical_pct",
        1.0,
        0.0,
        100.0,
        MAV_PARAM_TYPE_INT16,
        description="critical rotor speed, percent",
    ),
    ParamSpec(
        "H_RSC_SETPOINT",
        "rsc.setpoint_pct",
        1.0,
        0.0,
        100.0,
        MAV_PARAM_TYPE_INT16,
        description="RSC output at full speed, percent",
    ),
    ParamSpec(
        "MAV_GCS_SYSID",
        "link.gcs_sysid",
        1.0,
        1.0,
        255.0,
        MAV_PARAM_TYPE_INT16,
        description="system id allowed to override RC channels",
    ),
    *_stream_rates(1),
    *_stream_rates(2),
    *_stream_rates(3),
    ParamSpec(
        "SIM_ADSB_COUNT", "adsb.count", 1.0, 0.0, 100.0, MAV_PARAM_TYPE_INT16, description="simulated ADS-B aircraft"
    ),
    ParamSpec(
        "SIM_ADSB_RADIUS", "adsb.radius_m", 1.0, 50.0, 100000.0, description="radius of the area the traffic crosses, m"
    ),
    ParamSpec("SIM_ADSB_ALT", "adsb.alt_m", 1.0, -100.0, 10000.0, description="mean traffic height above home, m"),
    ParamSpec("SIM_WIND_SPD", "wind.speed_m_s", 1.0, 0.0, 40.0, description="steady wind, m/s"),
    ParamSpec("SIM_WIND_DIR", "wind.from_deg", 1.0, 0.0, 360.0, description="wind from, degrees"),
    ParamSpec("SIM_WIND_TURB", "wind.gust_m_s", 1.0, 0.0, 20.0, description="gust std per axis, m/s"),
    *_weights("LQI_QI_", "q_weights", 14, ("u", "v", "w", "psi"), "the integral of"),
    *_weights("LQI_Q_", "q_weights", 0, ("u", "v", "w"), "the velocity error"),
    *_weights("LQI_R_", "r_weights", 0, ("lat", "lon", "ped", "col"), "the input"),
    ParamSpec("POS_KP_XY", "controller.kp_xy_1_s", 1.0, 0.0, 10.0, description="PID position P, 1/s"),
    ParamSpec("POS_KP_Z", "controller.kp_z_1_s", 1.0, 0.0, 10.0, description="PID altitude P, 1/s"),
)


def _encode(spec: ParamSpec, setting: object) -> float:
    value = float(setting) * spec.scale
    return float(round(value)) if spec.is_integer else value


class ParameterTable:
    """The parameters as a view of a :class:`VehicleSettings` tree.

    Parameters
    ----------
    settings : VehicleSettings
        The current tree; :meth:`set` returns a new one (trees are immutable).
    """

    def __init__(self, settings: VehicleSettings) -> None:
        self.specs: tuple[ParamSpec, ...] = PARAM_SPECS
        self._by_name = {s.name: s for s in self.specs}
        self.settings = settings

    def __len__(self) -> int:
        return len(self.specs)

    def index(self, name: str) -> int:
        """Index of ``name`` in the list (``PARAM_VALUE.param_index``), -1 if unknown."""
        spec = self._by_name.get(name)
        return self.specs.index(spec) if spec is not None else -1

    def lookup(self, name: str | None = None, index: int = -1) -> ParamSpec | None:
        """The spec by name or, with ``index >= 0`` as in PARAM_REQUEST_READ, by index."""
        if index >= 0:
            return self.specs[index] if index < len(self.specs) else None
        return self._by_name.get(name or "")

    def value(self, spec: ParamSpec) -> float:
        """Current parameter value (ArduPilot units)."""
        return _encode(spec, get_path(self.settings, spec.path))

    def set(self, name: str, value: float) -> tuple[bool, str]:
        """Set a parameter; returns ``(accepted, reason)``. Refused values change nothing.

        On success ``self.settings`` is the new tree.
        """
        spec = self._by_name.get(name)
        if spec is None:
            return False, f"unknown parameter {name!r}"
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            reason = f"{name}: {value!r} is not a finite number"
            log.warning("PARAM_SET refused: %s", reason)
            return False, reason
        if not spec.minimum <= value <= spec.maximum:
            reason = f"{name}: {value:g} outside {spec.minimum:g}..{spec.maximum:g} ({spec.description})"
            log.warning("PARAM_SET refused: %s; keeps %g", reason, self.value(spec))
            return False, reason
        if spec.is_integer:
            value = float(round(value))
        setting = value / spec.scale
        if spec.is_integer and isinstance(get_path(self.settings, spec.path), int):
            setting = int(round(setting))
        try:
            new_settings = replace_path(self.settings, spec.path, setting)
            if spec.path.startswith("wind."):
                new_settings = replace_path(new_settings, "wind.enabled", True)
        except ValueError as exc:
            reason = f"{name}: {value:g} refused ({exc})"
            log.warning("PARAM_SET refused: %s", reason)
            return False, reason
        self.settings = new_settings
        log.info("parameter %s set to %g", name, value)
        return True, ""
