"""The settings tree of ``sim-vehicle``: frozen dataclasses, every default here, TOML overrides.

Loaded with :func:`heli_common.typed_config.from_dict`; a wrong key or value raises
:class:`SimConfigError` naming the dotted key (e.g. ``flight.wp_speed_m_s: expected a number``).
The MAVLink parameters (``sim_vehicle.params``) are views onto this tree, in ArduPilot units.

Example ``--config`` file::

    [timing]
    speedup = 5.0
    [flight]
    wp_speed_m_s = 8.0
    guided_timeout_s = 2.0
    [wind]
    speed_m_s = 4.0
    from_deg = 270.0
    [rsc]
    runup_time_s = 5.0
    [adsb]
    count = 3
    [link.mav1]          # the first --out address streams positions at 4 Hz from the start
    position = 4
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from heli_common.ports import GCS_PORT, companion_port
from heli_common.typed_config import from_dict, load_toml
from heli_model.control import ControllerSettings
from sim_vehicle.adsb import AdsbSettings
from sim_vehicle.rsc import RscSettings


class SimConfigError(ValueError):
    """A ``sim-vehicle`` setting is wrong; the message names the dotted key."""


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


@dataclasses.dataclass(frozen=True)
class TimingSettings:
    """Simulated time.

    Attributes
    ----------
    speedup : float
        Simulated seconds per wall-clock second (``--speedup``), in (0, 1000].
    physics_rate_hz : float
        RK4 physics rate, simulated Hz (default 400).
    control_rate_hz : float
        Flight-controller rate, simulated Hz (default 100); the physics rate must be a
        whole multiple of it.
    max_lag_s : float
        If the simulation falls this far (wall-clock seconds) behind, it stops catching up and
        slips (logged) instead of running in a burst.
    """

    speedup: float = 1.0
    physics_rate_hz: float = 400.0
    control_rate_hz: float = 100.0
    max_lag_s: float = 0.5

    def __post_init__(self) -> None:
        _require(0.0 < self.speedup <= 1000.0, f"speedup: expected a number in (0, 1000], got {self.speedup!r}")
        _require(
            10.0 <= self.physics_rate_hz <= 5000.0, f"physics_rate_hz: expected 10..5000, got {self.physics_rate_hz!r}"
        )
        _require(
            1.0 <= self.control_rate_hz <= self.physics_rate_hz,
            f"control_rate_hz: expected 1..physics_rate_hz, got {self.control_rate_hz!r}",
        )
        ratio = self.physics_rate_hz / self.control_rate_hz
        _require(
            abs(ratio - round(ratio)) < 1e-9,
            f"control_rate_hz: physics_rate_hz ({self.physics_rate_hz:g}) must be a whole multiple of it",
        )
        _require(self.max_lag_s > 0.0, f"max_lag_s: expected > 0, got {self.max_lag_s!r}")

    @property
    def physics_dt_s(self) -> float:
        """Physics step, simulated s."""
        return 1.0 / self.physics_rate_hz

    @property
    def physics_steps_per_control(self) -> int:
        """Physics steps per flight-controller update."""
        return int(round(self.physics_rate_hz / self.control_rate_hz))


@dataclasses.dataclass(frozen=True)
class FlightSettings:
    """Vehicle behaviour (ArduCopter parameter in brackets).

    Attributes
    ----------
    guided_timeout_s : float
        GUIDED: no setpoint for this long (simulated s) -> brake to a hover [GUID_TIMEOUT].
    wp_speed_m_s : float
        Horizontal speed of AUTO legs, RTL and GUIDED position targets [WPNAV_SPEED].
    wp_speed_up_m_s, wp_speed_down_m_s : float
        Climb and descent speed on legs [WPNAV_SPEED_UP, WPNAV_SPEED_DN].
    wp_accel_m_s2 : float
        Acceleration of the leg speed profile [WPNAV_ACCEL].
    wp_radius_m : float
        Default waypoint acceptance radius [WPNAV_RADIUS].
    takeoff_speed_m_s : float
        Climb speed of a takeoff [PILOT_SPEED_UP].
    land_speed_m_s : float
        Final descent speed below ``land_slow_alt_m`` [LAND_SPEED].
    land_speed_high_m_s : float
        Descent speed above ``land_slow_alt_m`` [LAND_SPEED_HIGH].
    land_slow_alt_m : float
        Height where a landing slows down.
    rtl_alt_m : float
        Minimum height of the return leg of RTL [RTL_ALT].
    disarm_delay_s : float
        Armed and landed for this long without a takeoff -> disarm; 0 = never [DISARM_DELAY].
    brake_accel_m_s2 : float
        Deceleration assumed when braking to a hover (BRAKE, LOITER entry, GUIDED timeout).
    max_speed_m_s : float
        Largest commanded horizontal speed accepted from any source.
    fence_enable : int
        1: enforce the uploaded fence (polygons, circles) and ``fence_alt_max_m`` [FENCE_ENABLE];
        0 (default, as in ArduPilot): the fence is stored but not enforced.
    fence_action : int
        On a breach: 0 report only, 1 RTL, 2 LAND, 4 BRAKE [FENCE_ACTION].
    fence_alt_max_m : float
        Maximum height above home while the fence is enabled [FENCE_ALT_MAX].
    prearm_fail : int
        1: every arming attempt fails its pre-arm check, as a real vehicle with a failing
        sensor would (fault injection for tests, like ArduPilot SITL's SIM_* failures)
        [SIM_PREARM_FAIL].
    """

    guided_timeout_s: float = 3.0
    wp_speed_m_s: float = 5.0
    wp_speed_up_m_s: float = 2.5
    wp_speed_down_m_s: float = 1.5
    wp_accel_m_s2: float = 2.0
    wp_radius_m: float = 2.0
    takeoff_speed_m_s: float = 2.5
    land_speed_m_s: float = 0.5
    land_speed_high_m_s: float = 1.5
    land_slow_alt_m: float = 5.0
    rtl_alt_m: float = 15.0
    disarm_delay_s: float = 10.0
    brake_accel_m_s2: float = 2.5
    max_speed_m_s: float = 15.0
    fence_enable: int = 0
    fence_action: int = 1
    fence_alt_max_m: float = 100.0
    prearm_fail: int = 0

    def __post_init__(self) -> None:
        _require(self.prearm_fail in (0, 1), f"prearm_fail: expected 0 or 1, got {self.prearm_fail!r}")
        _require(self.fence_enable in (0, 1), f"fence_enable: expected 0 or 1, got {self.fence_enable!r}")
        _require(self.fence_action in (0, 1, 2, 4), f"fence_action: expected 0, 1, 2 or 4, got {self.fence_action!r}")
        _require(
            10.0 <= self.fence_alt_max_m <= 1000.0,
            f"fence_alt_max_m: expected 10..1000 m, got {self.fence_alt_max_m!r}",
        )
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            _require(math.isfinite(value), f"{f.name}: expected a finite number, got {value!r}")
        _require(
            0.1 <= self.guided_timeout_s <= 120.0, f"guided_timeout_s: expected 0.1..120 s, got {self.guided_timeout_s}"
        )
        for name in (
            "wp_speed_m_s",
            "wp_speed_up_m_s",
            "wp_speed_down_m_s",
            "takeoff_speed_m_s",
            "land_speed_m_s",
            "land_speed_high_m_s",
        ):
            value = getattr(self, name)
            _require(
                0.1 <= value <= self.max_speed_m_s, f"{name}: expected 0.1..{self.max_speed_m_s:g} m/s, got {value}"
            )
        _require(0.1 <= self.wp_accel_m_s2 <= 10.0, f"wp_accel_m_s2: expected 0.1..10, got {self.wp_accel_m_s2}")
        _require(0.05 <= self.wp_radius_m <= 100.0, f"wp_radius_m: expected 0.05..100 m, got {self.wp_radius_m}")
        _require(
            0.0 <= self.land_slow_alt_m <= 100.0, f"land_slow_alt_m: expected 0..100 m, got {self.land_slow_alt_m}"
        )
        _require(0.0 <= self.rtl_alt_m <= 300.0, f"rtl_alt_m: expected 0..300 m, got {self.rtl_alt_m}")
        _require(0.0 <= self.disarm_delay_s <= 127.0, f"disarm_delay_s: expected 0..127 s, got {self.disarm_delay_s}")
        _require(
            0.1 <= self.brake_accel_m_s2 <= 10.0, f"brake_accel_m_s2: expected 0.1..10, got {self.brake_accel_m_s2}"
        )
        _require(1.0 <= self.max_speed_m_s <= 50.0, f"max_speed_m_s: expected 1..50 m/s, got {self.max_speed_m_s}")


@dataclasses.dataclass(frozen=True)
class WindConfig:
    """Wind of the simulation (overrides the profile's wind when ``enabled``).

    Attributes
    ----------
    enabled : bool
        False: use the wind of the vehicle profile.
    speed_m_s : float
        Steady wind speed, m/s [SIM_WIND_SPD].
    from_deg : float
        Direction the wind blows *from*, degrees clockwise from north [SIM_WIND_DIR].
    gust_m_s : float
        Gust standard deviation per axis, m/s [SIM_WIND_TURB].
    gust_tau_s : float
        Gust correlation time, s.
    """

    enabled: bool = False
    speed_m_s: float = 0.0
    from_deg: float = 0.0
    gust_m_s: float = 0.0
    gust_tau_s: float = 2.0

    def __post_init__(self) -> None:
        _require(
            math.isfinite(self.speed_m_s) and 0.0 <= self.speed_m_s <= 40.0,
            f"speed_m_s: expected 0..40 m/s, got {self.speed_m_s!r}",
        )
        _require(
            math.isfinite(self.from_deg) and -360.0 <= self.from_deg <= 360.0,
            f"from_deg: expected -360..360 degrees, got {self.from_deg!r}",
        )
        _require(
            math.isfinite(self.gust_m_s) and 0.0 <= self.gust_m_s <= 20.0,
            f"gust_m_s: expected 0..20 m/s, got {self.gust_m_s!r}",
        )
        _require(
            math.isfinite(self.gust_tau_s) and 0.05 <= self.gust_tau_s <= 100.0,
            f"gust_tau_s: expected 0.05..100 s, got {self.gust_tau_s!r}",
        )

    def steady_ned_m_s(self) -> tuple[float, float, float]:
        """Velocity of the air in NED, m/s (blowing *towards* ``from_deg + 180``)."""
        to_rad = math.radians(self.from_deg + 180.0)
        return (self.speed_m_s * math.cos(to_rad), self.speed_m_s * math.sin(to_rad), 0.0)


@dataclasses.dataclass(frozen=True)
class StreamGroupRates:
    """Stream group rates a link starts with, Hz (ArduPilot's ``MAVn_*`` parameters; 0 = off).

    ArduCopter's defaults are 0 for every group: nothing but HEARTBEAT until a ground station
    asks (see :mod:`sim_vehicle.streams`). REQUEST_DATA_STREAM writes the rate it sets here.

    Parameters
    ----------
    raw_sens, ext_stat, rc_chan, raw_ctrl, position, extra1, extra2, extra3, params, adsb : int
        Rate (Hz) of the group of that name (``MAVn_RAW_SENS`` ... ``MAVn_ADSB``); 0: off.
    """

    raw_sens: int = 0
    ext_stat: int = 0
    rc_chan: int = 0
    raw_ctrl: int = 0
    position: int = 0
    extra1: int = 0
    extra2: int = 0
    extra3: int = 0
    params: int = 0
    adsb: int = 0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            _require(isinstance(value, int) and 0 <= value <= 1000, f"{f.name}: expected 0..1000 Hz, got {value!r}")

    def as_groups(self) -> dict[str, int]:
        """Group name (``RAW_SENS``, ``EXT_STAT``, ...) -> rate, Hz."""
        return {f.name.upper(): getattr(self, f.name) for f in dataclasses.fields(self)}


def instance_out(instance: int) -> tuple[str, ...]:
    """The default telemetry addresses of vehicle ``instance``: the ground station on
    127.0.0.1:14550 and its companion on 127.0.0.1:<14540 + instance> (as PX4 SITL numbers
    them; ``companion run --instance N`` listens there)."""
    return (f"127.0.0.1:{GCS_PORT}", f"127.0.0.1:{companion_port(instance)}")


@dataclasses.dataclass(frozen=True)
class LinkSettings:
    """The MAVLink endpoint.

    Attributes
    ----------
    port : int
        UDP port to bind; 0 = ``14555 + 10 * instance``.
    bind_host : str
        Address to bind (``0.0.0.0`` = every interface).
    out : tuple of str
        ``HOST:PORT`` telemetry destinations besides the peers heard recently.
    peer_timeout_s : float
        A peer not heard for this long (wall clock) no longer gets telemetry.
    mission_upload_timeout_s : float
        A mission upload with no item for this long (wall clock) is abandoned (old list kept).
    mav1, mav2, mav3 : StreamGroupRates
        Stream rates the first, second and third ``out`` address start with [MAV1_*, MAV2_*,
        MAV3_*]; other peers start with every stream off.
    gcs_sysid : int
        Only this system id may override RC channels (RC_CHANNELS_OVERRIDE) [MAV_GCS_SYSID].
    """

    port: int = 0
    bind_host: str = "0.0.0.0"
    out: tuple[str, ...] = instance_out(0)  # instance N: ``instance_out(N)``
    peer_timeout_s: float = 10.0
    mission_upload_timeout_s: float = 5.0
    mav1: StreamGroupRates = dataclasses.field(default_factory=StreamGroupRates)
    mav2: StreamGroupRates = dataclasses.field(default_factory=StreamGroupRates)
    mav3: StreamGroupRates = dataclasses.field(default_factory=StreamGroupRates)
    gcs_sysid: int = 255

    def __post_init__(self) -> None:
        _require(
            isinstance(self.gcs_sysid, int) and 1 <= self.gcs_sysid <= 255,
            f"gcs_sysid: expected 1..255, got {self.gcs_sysid!r}",
        )
        _require(0 <= self.port <= 65535, f"port: expected 0..65535, got {self.port!r}")
        for address in self.out:
            parse_host_port(address, "out")
        _require(self.peer_timeout_s > 0.0, f"peer_timeout_s: expected > 0, got {self.peer_timeout_s!r}")
        _require(
            self.mission_upload_timeout_s > 0.0,
            f"mission_upload_timeout_s: expected > 0, got {self.mission_upload_timeout_s!r}",
        )


@dataclasses.dataclass(frozen=True)
class VehicleSettings:
    """The whole ``sim-vehicle`` settings tree.

    ``rsc`` is the rotor speed controller and motor interlock (:mod:`sim_vehicle.rsc`), ``adsb``
    the simulated ADS-B traffic (:mod:`sim_vehicle.adsb`). ``controller`` is the flight controller's own settings (:class:`heli_model.control.
    ControllerSettings`: LQI weights, PID gains, limits); its ``control_dt_s`` is replaced by
    ``1 / timing.control_rate_hz`` when the vehicle is built.

    Parameters
    ----------
    seed : int
        Seed of the simulated disturbances (wind gusts, ADS-B traffic): a run can be replayed.
    """

    seed: int = 0
    timing: TimingSettings = dataclasses.field(default_factory=TimingSettings)
    flight: FlightSettings = dataclasses.field(default_factory=FlightSettings)
    wind: WindConfig = dataclasses.field(default_factory=WindConfig)
    link: LinkSettings = dataclasses.field(default_factory=LinkSettings)
    rsc: RscSettings = dataclasses.field(default_factory=RscSettings)
    adsb: AdsbSettings = dataclasses.field(default_factory=AdsbSettings)
    controller: ControllerSettings = dataclasses.field(default_factory=ControllerSettings)


def parse_host_port(text: str, what: str = "address") -> tuple[str, int]:
    """``"HOST:PORT"`` -> ``(host, port)``; raises ``ValueError`` naming ``what``."""
    host, sep, port_text = str(text).rpartition(":")
    if not sep or not host:
        raise ValueError(f"{what}: expected HOST:PORT, got {text!r}")
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"{what}: expected HOST:PORT with a numeric port, got {text!r}") from None
    if not 1 <= port <= 65535:
        raise ValueError(f"{what}: port must be 1..65535, got {text!r}")
    return host, port


def settings_from_dict(data: dict[str, Any] | None) -> VehicleSettings:
    """Build the tree from a mapping; raises :class:`SimConfigError` naming the key."""
    return from_dict(VehicleSettings, data or {}, error=SimConfigError)


def load_settings(path: str | Path | None) -> VehicleSettings:
    """Defaults, overridden by the TOML file ``path`` (if given)."""
    if path is None:
        return VehicleSettings()
    data = load_toml(path, error=SimConfigError)
    try:
        return settings_from_dict(data)
    except SimConfigError as exc:
        raise SimConfigError(f"{path}: {exc}") from None


def replace_path(settings: Any, dotted: str, value: Any) -> Any:
    """A copy of the frozen tree ``settings`` with the field at ``dotted`` set to ``value``.

    ``name#i`` addresses element ``i`` of a tuple field (e.g. ``controller.r_weights#3``).
    Raises ``ValueError`` (from the dataclass checks) if the value is not allowed.
    """
    head, _, rest = dotted.partition(".")
    if not rest:
        name, sep, index = head.partition("#")
        if sep:
            items = list(getattr(settings, name))
            items[int(index)] = value
            value = tuple(items)
        return dataclasses.replace(settings, **{name: value})
    return dataclasses.replace(settings, **{head: replace_path(getattr(settings, head), rest, value)})


def get_path(settings: Any, dotted: str) -> Any:
    """The value of the field at ``dotted`` (``name#i``: tuple element) in the tree ``settings``."""
    for part in dotted.split("."):
        name, sep, index = part.partition("#")
        settings = getattr(settings, name)
        if sep:
            settings = settings[int(index)]
    return settings
