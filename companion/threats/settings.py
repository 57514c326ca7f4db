"""Settings of the threat stage: the zenoh session and the threat policy (DESIGN 6, 7).

Every default lives here and is documented; ``companion/config.py`` composes these frozen
dataclasses into the settings tree (tables ``[zenoh]`` and ``[threats]``).

Why these defaults (paper section 3.3, Fig. 5 and Fig. 8; R-50-class helicopter at 6-8 m/s):

- ``horizon_s = 15``: candidates are checked 15 s (90-120 m) ahead in space and time; a
  conflict further away is met again by the 10 Hz monitor as it comes closer.
- ``inflation_m = 2``: half the rotor span (1.8 m) plus a few tenths for tracking error, added to
  every threat radius; ``uncertainty_m_s = 0.3`` grows a moving threat's tube with the time
  since its last update (capped at ``uncertainty_max_m = 4``).
- ``replan_budget_s = 0.15``: a replan's time budget: its searches (every round) share it, and
  it is the first estimate of its duration (then measured), so that with the fast candidates
  before it and the escapes judged after it, a decision that replans puts its first setpoint on
  the wire within the 250 ms goal; a replan is attempted only when no fast candidate (evade,
  retime, switch: milliseconds) keeps going to the goal clear and the conflict is further away
  than that estimate plus the time to stop plus ``urgency_margin_s = 3``; closer conflicts are
  answered in milliseconds.
- ``switch_range_m = 20``: the paper's switching range (Fig. 5).
- escape manoeuvres at 2.5 m/s^2 horizontally and 1.5 m/s^2 vertically: the lateral limit of
  the smoothing settings, which the LQI tracks within a few decimetres.

Manned traffic (``Threat.traffic == "manned"``: ADS-B) is another scale: a 50 m/s helicopter
heard at 1 Hz from 2-3 km away, judged by the aviation volumes (well clear 2000 ft / 250 ft).
Its tube is the well-clear cylinder (``manned_h_m`` across, ``manned_v_m`` up and down; in its
clearance a metre of height counts as eight of distance), checked ``manned_horizon_s = 45`` s ahead
from ``manned_range_m = 5000`` m away; its escapes coast for ``manned_coasts_s`` (10-30 s) and
may use ``manned_vertical_room_m = 60`` above and below the leg, never below
``min_altitude_m``. A drone-scale threat's decision is the same with or without these.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

from companion.errors import ConfigError
from heli_common.typed_config import require_int, require_numbers

__all__ = ["ThreatSettings", "ZenohSettings"]

_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/\S+$")


#: The system id of the prefix when neither the settings nor a vehicle give one.
DEFAULT_SYSID = 1
#: zenoh's own default port: a zenoh router (``companion router``) listens on it.
ZENOH_ROUTER_PORT = 7447


def default_listen(sysid: int) -> tuple[str, ...]:
    """A companion's zenoh endpoint when none is given: loopback port ``7447 + sysid`` (7448 for
    system 1), so a router on 7447 and the companions of other systems on the same machine
    never collide; ``companion threat --sysid N`` connects there by default."""
    return (f"tcp/127.0.0.1:{ZENOH_ROUTER_PORT + int(sysid)}",)


def check_endpoint(endpoint: str, name: str = "endpoint") -> str:
    """Return ``endpoint`` if it looks like a zenoh locator (``tcp/HOST:PORT`` ...).

    Raises
    ------
    ConfigError
        Naming ``name`` when it does not.
    """
    if not isinstance(endpoint, str) or not _ENDPOINT.match(endpoint):
        raise ConfigError(f"{name}: expected a zenoh endpoint like tcp/127.0.0.1:7447, got {endpoint!r}")
    return endpoint


@dataclass(frozen=True)
class ZenohSettings:
    """The zenoh session (DESIGN section 6).

    Parameters
    ----------
    enabled : bool
        Open a zenoh session (threats, status, events, path). Default True.
    sysid : int or None
        System id of the key prefix ``uav/<sysid>``. Default None: the vehicle's MAVLink system
        id, read when ``companion run`` connects (``companion serve``, whose session opens before
        any vehicle answers, and tools without a vehicle use 1).
    mode : str
        ``peer`` (default) or ``client`` (through a zenoh router only).
    listen : tuple of str or None
        Endpoints this session listens on; empty to only connect. Default None:
        ``tcp/127.0.0.1:<7447 + sysid>`` (``default_listen``; 7448 for system 1: a zenoh
        router keeps 7447).
    connect : tuple of str
        Endpoints (peers or a router) this session connects to. Default none.
    config : str or None
        A zenoh configuration file (JSON5), e.g. ``companion keys init``'s ``companion.json5``
        (mutual TLS and access control: threats only from authenticated sources, on
        ``uav/<sysid>/threats/<source>/<id>``). When set, the file's mode and endpoints are
        used and ``mode``, ``listen``, ``connect`` are ignored. Default None: the plain
        session above.
    """

    enabled: bool = True
    sysid: int | None = None
    mode: str = "peer"
    listen: tuple[str, ...] | None = None
    connect: tuple[str, ...] = ()
    config: str | None = None

    def __post_init__(self) -> None:
        if self.config is not None and (not isinstance(self.config, str) or not self.config.strip()):
            raise ConfigError(f"zenoh.config: expected the path of a zenoh configuration file, got {self.config!r}")
        if self.sysid is not None:
            require_int(ConfigError, "zenoh", "sysid", self.sysid, 1, 255)
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"zenoh.mode: expected 'peer' or 'client', got {self.mode!r}")
        if self.listen is not None:
            object.__setattr__(self, "listen", tuple(self.listen))
        object.__setattr__(self, "connect", tuple(self.connect))
        for i, ep in enumerate(self.listen_endpoints):
            check_endpoint(ep, f"zenoh.listen[{i}]")
        for i, ep in enumerate(self.connect):
            check_endpoint(ep, f"zenoh.connect[{i}]")
        if self.enabled and not self.listen_endpoints and not self.connect:
            raise ConfigError("zenoh.listen: give at least one listen or connect endpoint")
        if self.mode == "client" and not self.connect:
            raise ConfigError("zenoh.connect: client mode needs a router endpoint to connect to")

    @property
    def listen_endpoints(self) -> tuple[str, ...]:
        """``listen``, or ``default_listen(sysid)`` when it is not set."""
        return default_listen(self.prefix_sysid) if self.listen is None else self.listen

    @property
    def prefix_sysid(self) -> int:
        """The system id of the prefix: ``sysid``, or ``DEFAULT_SYSID`` while it is unresolved."""
        return DEFAULT_SYSID if self.sysid is None else self.sysid

    def for_vehicle(self, vehicle_sysid: int) -> ZenohSettings:
        """These settings with ``sysid`` resolved to ``vehicle_sysid`` when it was not set."""
        return self if self.sysid is not None else dataclasses.replace(self, sysid=int(vehicle_sysid))


@dataclass(frozen=True)
class ThreatSettings:
    """Policy of the threat manager (DESIGN section 7, paper section 3.3).

    Parameters
    ----------
    horizon_s : float
        How far ahead in time every candidate, and the active reference, is checked against
        the tubes (s): one horizon, so that a chosen candidate stays clear when the monitor
        re-checks it. Default 15.
    check_step_s : float
        Sample step of the space-time check of planned references (s); the check is exact
        between samples up to ``a dt^2 / 8`` (2 cm at 0.2 s). Default 0.2.
    evade_step_s : float
        Sample step of the escape library's check (s). Default 0.25.
    inflation_m : float
        Added to every threat radius (m): rotor radius plus tracking error. Default 2.
    static_slack_m : float
        How far into the static world's safety margin a candidate may go (m, capped at half
        the margin): planned references keep all of it; an escape may use this much.
        Default 0.5.
    uncertainty_m_s, uncertainty_max_m : float
        Growth of a moving threat's radius per second since its last update (m/s), and its
        cap (m). Defaults 0.3 and 4.
    sensor_range_m : float
        Threats farther than this from the vehicle (now) are ignored by the decision (m).
    replan_budget_s : float
        Budget of a replan's searches, its rounds together (s), and the initial estimate of the
        replanning time, refined by the measured times. Default 0.15.
    urgency_margin_s : float
        A conflict closer than the replanning estimate + the time to stop + this margin (s) is
        urgent: only the fast candidates are judged. Default 3.
    replan_iterations : int
        Rounds of replan -> space-time check -> the mover placed where it would be met.
    replan_turn_rad : float
        The replan's straight lead is long enough for a first corner of this turn (rad).
    gart_budget_s, gart_first_budget_s : float
        Budgets of one round's GART after / until its first solution (s), each cut to what is
        left of ``replan_budget_s``.
    switch_range_m : float
        Entry nodes of the alternatives must be within this distance (m). Default 20.
    entry_spacing_m : float
        Entry nodes of an alternative are at most this far apart (m). Default 2.
    max_candidates : int
        Most switch entries smoothed and checked per decision. Default 4.
    switch_budget_s : float
        Wall-clock time after which no further switch entry is tried (s). Default 0.02.
    vertical_room_m : float
        Room above and below the leg's planning slab for escapes and alternatives (m).
        Default 8.
    min_altitude_m : float
        Escapes and alternatives stay at least this high above home (m). Default 5.
    vertical_offsets_m : tuple of float
        Alternatives above and below the cheapest one, by these offsets (m, 3D only).
    retime_rates : tuple of float
        Progress rates of the retime candidates (0: pause on the path), each in [0, 1).
    retime_waits_s : tuple of float
        How long each retime candidate stays at its rate (s).
    hold_decel_m_s2 : float
        Along-track deceleration of retimes and pauses (m/s^2). Default 2.5.
    evade_speed_m_s : float
        Horizontal speed of the escape manoeuvres (m/s), at most 1.2 times the planned
        trajectories' speed limit. Default 7.
    evade_accel_m_s2, evade_vertical_accel_m_s2 : float
        Acceleration limits of the escape manoeuvres (m/s^2).
    evade_climb_m_s, evade_descent_m_s : float
        Vertical speeds of the escape manoeuvres (m/s).
    evade_coasts_s : tuple of float
        Coast durations of the escape manoeuvres (s).
    restart_s : float
        Cost of coming back to the mission after a manoeuvre that ends in a hover (s): stop,
        plan back, accelerate again. Default 10, so that a clear way that keeps going wins
        unless it is much longer.
    clearance_weight_s_m, clearance_cap_m : float
        Clearance bonus of the cost (s per m, up to the cap in m).
    estimate_gain : float
        Weight of a new measurement in the running estimate of the replanning time.
    manned_h_m, manned_v_m : float
        Radius and half-height of a manned aircraft's tube, a cylinder (m). Defaults 609.6 and
        76.2 (well clear, 2000 ft and 250 ft; the inflation is added to the radius).
    manned_horizon_s : float
        Horizon of every check while a manned aircraft is within ``manned_range_m`` (s), at
        least ``horizon_s``. Default 45.
    manned_range_m : float
        Manned aircraft farther than this (m) are ignored by the decision. Default 5000.
    manned_step_s : float
        Sample step of every check while a manned aircraft is near (s), when longer than
        ``check_step_s`` and ``evade_step_s``: over a 45 s horizon, against a 610 m cylinder, a
        chord error of a few decimetres costs nothing. Default 0.5.
    manned_coasts_s : tuple of float
        Coast durations of the escapes while a manned aircraft is near (s), with
        ``evade_coasts_s``. Default (10, 20, 30).
    manned_vertical_room_m : float
        Room above and below the leg for escapes from a manned aircraft (m). Default 60.
    seed : int
        Seed of the manager's random generator when none is given.
    """

    horizon_s: float = 15.0
    check_step_s: float = 0.2
    evade_step_s: float = 0.25
    inflation_m: float = 2.0
    static_slack_m: float = 0.5
    uncertainty_m_s: float = 0.3
    uncertainty_max_m: float = 4.0
    sensor_range_m: float = 1000.0
    replan_budget_s: float = 0.15
    urgency_margin_s: float = 3.0
    replan_iterations: int = 3
    replan_turn_rad: float = 1.0
    gart_budget_s: float = 0.08
    gart_first_budget_s: float = 0.15
    switch_range_m: float = 20.0
    entry_spacing_m: float = 2.0
    max_candidates: int = 4
    switch_budget_s: float = 0.02
    vertical_room_m: float = 8.0
    min_altitude_m: float = 5.0
    vertical_offsets_m: tuple[float, ...] = (6.0,)
    retime_rates: tuple[float, ...] = (0.0, 0.4)
    retime_waits_s: tuple[float, ...] = (0.0, 1.5, 3.0, 5.0, 8.0, 12.0)
    hold_decel_m_s2: float = 2.5
    evade_speed_m_s: float = 7.0
    evade_accel_m_s2: float = 2.5
    evade_vertical_accel_m_s2: float = 1.5
    evade_climb_m_s: float = 2.5
    evade_descent_m_s: float = 1.5
    evade_coasts_s: tuple[float, ...] = (1.0, 2.5, 5.0)
    restart_s: float = 10.0
    clearance_weight_s_m: float = 1.0
    clearance_cap_m: float = 3.0
    estimate_gain: float = 0.2
    manned_h_m: float = 609.6
    manned_v_m: float = 76.2
    manned_horizon_s: float = 45.0
    manned_range_m: float = 5000.0
    manned_step_s: float = 0.5
    manned_coasts_s: tuple[float, ...] = (10.0, 20.0, 30.0)
    manned_vertical_room_m: float = 60.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("vertical_offsets_m", "retime_rates", "retime_waits_s", "evade_coasts_s", "manned_coasts_s"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
            for i, v in enumerate(getattr(self, name)):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                    raise ConfigError(f"threats.{name}[{i}]: must be a finite number >= 0, got {v!r}")
        if any(r >= 1.0 for r in self.retime_rates):
            raise ConfigError(f"threats.retime_rates: every rate must be in [0, 1), got {self.retime_rates!r}")
        if not self.evade_coasts_s:
            raise ConfigError("threats.evade_coasts_s: give at least one coast duration")
        require_numbers(
            ConfigError,
            "threats",
            self,
            positive=(
                "horizon_s",
                "check_step_s",
                "evade_step_s",
                "replan_budget_s",
                "switch_range_m",
                "sensor_range_m",
                "switch_budget_s",
                "gart_budget_s",
                "entry_spacing_m",
                "gart_first_budget_s",
                "hold_decel_m_s2",
                "estimate_gain",
                "evade_speed_m_s",
                "evade_accel_m_s2",
                "evade_vertical_accel_m_s2",
                "evade_climb_m_s",
                "evade_descent_m_s",
                "manned_h_m",
                "manned_v_m",
                "manned_horizon_s",
                "manned_range_m",
                "manned_step_s",
            ),
            non_negative=(
                "inflation_m",
                "urgency_margin_s",
                "static_slack_m",
                "replan_turn_rad",
                "uncertainty_m_s",
                "uncertainty_max_m",
                "restart_s",
                "vertical_room_m",
                "manned_vertical_room_m",
                "min_altitude_m",
                "clearance_weight_s_m",
                "clearance_cap_m",
            ),
        )
        if self.horizon_s < 10.0:
            raise ConfigError(f"threats.horizon_s: must be >= 10 s (DESIGN 7.2), got {self.horizon_s!r}")
        if self.manned_horizon_s < self.horizon_s:
            raise ConfigError(
                f"threats.manned_horizon_s: must be >= horizon_s ({self.horizon_s!r}), got {self.manned_horizon_s!r}"
            )
        if self.replan_turn_rad >= math.pi:
            raise ConfigError(f"threats.replan_turn_rad: must be < pi, got {self.replan_turn_rad!r}")
        if self.estimate_gain > 1:
            raise ConfigError(f"threats.estimate_gain: must be in (0, 1], got {self.estimate_gain!r}")
        require_int(ConfigError, "threats", "max_candidates", self.max_candidates, 1, 1000)
        require_int(ConfigError, "threats", "replan_iterations", self.replan_iterations, 1, 10)
        require_int(ConfigError, "threats", "seed", self.seed, 0, 2**63 - 1)
