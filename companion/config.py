"""The companion's settings: one typed tree of frozen dataclasses, loaded from TOML.

Every default lives in code (the stage that uses a setting owns its dataclass); a TOML file only
overrides. A wrong key or value is a ``ConfigError`` that names it with its dotted key, e.g.
``smoothing.limits.speed_m_s: must be a finite number > 0, got -1``.

Tree (``companion run --config FILE``; ``companion run --print-config`` shows it whole)::

    seed        random seed of every planner run (logged; any flight can be replayed)
    link        vehicle connection, setpoint rate, time scale, timeouts; link.streams: the
                telemetry rates asked for (companion.link.streams.StreamSettings)
    startup     arming, motor interlock, rotor run-up, takeoff, joining a flying vehicle
                (companion.service.startup.StartupSettings)
    zenoh       session endpoints and the key prefix's system id
    mission     mission -> local NED + world (margin, padding, ceiling)
    flight      per-leg planning budget, planning slab, climb and descent, M-GART alternatives
    planning    GART (companion.planning.GartSettings)
    smoothing   G1/G2, K_max, speed/acceleration/jerk limits
    feasibility closed-loop check on the helicopter model
    threats     threat-manager policy (companion.threats.settings.ThreatSettings)
    adsb        ADS-B traffic as threats (companion.threats.transport.adsb.AdsbSettings)
    alerts      traffic alerts to the ground station: COLLISION, STATUSTEXT
                (companion.threats.alerts.AlertSettings)
    state       where the threat snapshot is kept for a resume after a crash (companion.threats.snapshot)
    view        the live Foxglove server (companion.view)
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from companion.errors import ConfigError
from companion.fleet.settings import FleetSettings
from companion.flight.plan import FlightPlanSettings
from companion.link.streams import StreamSettings
from companion.mission.convert import ConversionSettings
from companion.planning import GartSettings
from companion.service.startup import StartupSettings
from companion.smoothing import FeasibilitySettings, SmoothingSettings
from companion.threats.alerts import AlertSettings
from companion.threats.settings import ThreatSettings, ZenohSettings
from companion.threats.transport.adsb import AdsbSettings
from companion.view.sinks import parse_foxglove_address
from heli_common.typed_config import from_dict, load_toml, require_numbers


@dataclass(frozen=True)
class LinkSettings:
    """The vehicle link and the flight's timing.

    Parameters
    ----------
    connect : str
        MAVSDK connection URL (udpin://, udpout://, tcpin://, tcpout://, serial://).
    connect_timeout_s : float
        How long to wait for an autopilot at start (wall-clock seconds).
    setpoint_rate_hz : float
        GUIDED setpoint stream rate (default 50 Hz).
    time_scale : float or None
        Vehicle seconds per wall-clock second, so that the reference advances at the vehicle's
        pace. None (default): read from the vehicle at connection, its ``SIM_SPEEDUP``
        parameter (``sim-vehicle --speedup``, ArduPilot SITL's ``--speedup``), 1 for a vehicle
        without one (a real helicopter). ``--time-scale`` sets it.
    leg_timeout_margin_s : float
        A leg not reached this long (mission time) after its trajectory ended is an error: the
        vehicle is held and the flight ends.
    on_interrupt : str
        What SIGINT / SIGTERM do in flight: ``hold`` (LOITER where the vehicle is), ``land``
        (LAND where it is) or ``rtl``.
    record_rate_hz : float
        Rate of ``sample`` lines in the flight record.
    status_rate_hz : float
        Rate of ``uav/<sysid>/status`` messages (also sent on every change).
    origin_timeout_s : float
        How long to wait for the vehicle's EKF origin (GPS_GLOBAL_ORIGIN) before taking its
        local frame to be home's (wall clock).
    streams : StreamSettings
        The telemetry asked for (``companion.link.streams``).
    signing_key_file : str
        MAVLink 2 signing key file (64 hex digits or a passphrase; ``--signing-key``): sign
        everything sent, accept only frames signed with it. Empty: no signing.
    tlog_file : str
        Record the companion's MAVLink traffic with the vehicle, both ways, to this ``.tlog``
        file (``--tlog``; pymavlink, MAVExplorer and QGroundControl read it). Empty: none.
    """

    connect: str = "udpin://0.0.0.0:14540"
    connect_timeout_s: float = 30.0
    setpoint_rate_hz: float = 50.0
    time_scale: float | None = None
    leg_timeout_margin_s: float = 30.0
    on_interrupt: Literal["hold", "land", "rtl"] = "hold"
    record_rate_hz: float = 10.0
    status_rate_hz: float = 2.0
    origin_timeout_s: float = 5.0
    streams: StreamSettings = StreamSettings()
    signing_key_file: str = ""
    tlog_file: str = ""

    def __post_init__(self) -> None:
        require_numbers(
            ConfigError,
            "link",
            self,
            positive=(
                "connect_timeout_s",
                "setpoint_rate_hz",
                "leg_timeout_margin_s",
                "record_rate_hz",
                "status_rate_hz",
                "origin_timeout_s",
            )
            + (() if self.time_scale is None else ("time_scale",)),
        )
        if self.setpoint_rate_hz > 200:
            raise ConfigError(f"link.setpoint_rate_hz: at most 200, got {self.setpoint_rate_hz}")


@dataclass(frozen=True)
class ViewSettings:
    """The operator's live view (``companion.view``).

    Parameters
    ----------
    foxglove : str
        Serve the flight live over the Foxglove WebSocket protocol on ``[HOST:]PORT``
        (``--foxglove``; host 127.0.0.1 unless given, port 0 picks a free one): the 3D scene,
        the map, the record's channels. Empty (default): no server.
    """

    foxglove: str = ""

    def __post_init__(self) -> None:
        if self.foxglove:
            parse_foxglove_address(self.foxglove, "view.foxglove")


@dataclass(frozen=True)
class StateSettings:
    """The companion's state on disk (``companion.threats.snapshot``).

    Parameters
    ----------
    dir : str
        Directory of the threat snapshot ``threats-uav<sysid>.json``, written whenever the
        threats held change and read by ``companion run --resume``. Empty (default): no snapshot
        is written, and a resume starts without threats. ``--state-dir`` sets it.
    mission_current_timeout_s : float
        How long ``--resume`` waits for the vehicle's MISSION_CURRENT (wall clock, s).
    """

    dir: str = ""
    mission_current_timeout_s: float = 10.0

    def __post_init__(self) -> None:
        require_numbers(ConfigError, "state", self, positive=("mission_current_timeout_s",))


@dataclass(frozen=True)
class Settings:
    """The whole companion settings tree (see the module docstring).

    Parameters
    ----------
    seed : int
        Random seed of every planner run (logged, so that any flight can be replayed).
    link, startup, zenoh, mission, flight, planning, smoothing, feasibility, threats, adsb, alerts, state, view,
    fleet
        The tables of the tree (their keys are documented by their own classes).
    """

    seed: int = 0
    link: LinkSettings = LinkSettings()
    startup: StartupSettings = StartupSettings()
    zenoh: ZenohSettings = ZenohSettings()
    mission: ConversionSettings = ConversionSettings()
    flight: FlightPlanSettings = FlightPlanSettings()
    planning: GartSettings = GartSettings()
    smoothing: SmoothingSettings = SmoothingSettings()
    feasibility: FeasibilitySettings = FeasibilitySettings()
    threats: ThreatSettings = ThreatSettings()
    adsb: AdsbSettings = AdsbSettings()
    alerts: AlertSettings = AlertSettings()
    state: StateSettings = StateSettings()
    view: ViewSettings = ViewSettings()
    fleet: FleetSettings = FleetSettings()

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ConfigError(f"seed: must be >= 0, got {self.seed}")


def settings_from_dict(data: dict) -> Settings:
    """Build the settings tree from a mapping (unknown keys and bad values: ``ConfigError``)."""
    return from_dict(Settings, data, "", ConfigError)


def load_settings(path: str | Path | None = None, overrides: dict | None = None) -> Settings:
    """Defaults, then the TOML file ``path`` (if any), then ``overrides`` (nested mapping)."""
    data = load_toml(path, ConfigError) if path is not None else {}
    for key, value in (overrides or {}).items():
        if isinstance(value, dict):
            data.setdefault(key, {}).update(value)
        else:
            data[key] = value
    return settings_from_dict(data)


def settings_to_dict(settings) -> dict:
    """The settings tree as plain data (for logs, the flight record and ``--print-config``)."""
    return dataclasses.asdict(settings)


def settings_to_toml(settings) -> str:
    """The settings tree as a TOML file that ``--config`` reads back to the same settings.

    Unset keys (None) have no TOML value: they are written as comments.
    """
    return dict_to_toml(settings_to_dict(settings))


def dict_to_toml(data: dict) -> str:
    """Nested plain data as TOML text (tables for dicts; None values as comments)."""
    return "\n".join(_toml_table(data, "")).strip() + "\n"


def _toml_table(data: dict, name: str) -> list[str]:
    lines = [f"[{name}]"] if name else []
    tables = []
    for key, value in data.items():
        if isinstance(value, dict):
            tables.append((key, value))
        elif value is None:
            lines.append(f"# {key} = (unset)")
        else:
            lines.append(f"{key} = {_toml_value(value)}")
    for key, value in tables:
        lines += ["", *_toml_table(value, f"{name}.{key}" if name else key)]
    return lines


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")
