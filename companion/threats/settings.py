"""Settings of the threat stage: the zenoh session and the threat-manager policy (DESIGN 6, 7).

Every default lives here and is documented; ``companion/config.py`` composes these frozen
dataclasses into the settings tree (tables ``[zenoh]`` and ``[threats]``).

Why these defaults (paper section 3.3, Fig. 5 and Fig. 8; R-50-class helicopter at 8 m/s):

- ``horizon_s = 30``: the conflict check looks 30 s (240 m at 8 m/s) ahead, beyond the
  distance a pop-up threat is usually reported at, so a far pop-up is answered by a replan.
- ``replan_budget_s = 0.25``: the initial estimate of the replanning time (GART with a short
  budget, G2 smoothing and the speed profile); the measured times update the estimate.
- ``replan_margin_s = 3``: extra time kept on top of the budget; with the 2 m/s^2
  deceleration limit, 3 s is the time to stop from 6 m/s, so a replan that comes late can still
  be followed by a hold.
- ``switch_range_m = 20``: the paper's switching range (Fig. 5).
- ``inflation_m = 2``: added to every threat radius: half the rotor span (1.8 m) plus a
  few tenths for tracking error.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from companion.errors import ConfigError
from sim_vehicle.typed_config import require_int, require_numbers

__all__ = ["ThreatSettings", "ZenohSettings"]

_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/\S+$")


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
    sysid : int
        System id of the key prefix ``uav/<sysid>``. Default 1 (``sim-vehicle`` instance 0).
    mode : str
        ``peer`` (default) or ``client`` (through a zenoh router only).
    listen : tuple of str
        Endpoints this session listens on. Default ``("tcp/127.0.0.1:7447",)``; empty to only
        connect.
    connect : tuple of str
        Endpoints (peers or a router) this session connects to. Default none.
    """

    enabled: bool = True
    sysid: int = 1
    mode: str = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        require_int(ConfigError, "zenoh", "sysid", self.sysid, 1, 255)
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"zenoh.mode: expected 'peer' or 'client', got {self.mode!r}")
        object.__setattr__(self, "listen", tuple(self.listen))
        object.__setattr__(self, "connect", tuple(self.connect))
        for i, ep in enumerate(self.listen):
            check_endpoint(ep, f"zenoh.listen[{i}]")
        for i, ep in enumerate(self.connect):
            check_endpoint(ep, f"zenoh.connect[{i}]")
        if self.enabled and not self.listen and not self.connect:
            raise ConfigError("zenoh.listen: give at least one listen or connect endpoint")
        if self.mode == "client" and not self.connect:
            raise ConfigError("zenoh.connect: client mode needs a router endpoint to connect to")


@dataclass(frozen=True)
class ThreatSettings:
    """Policy of the emergency threat manager (DESIGN section 7, paper section 3.3).

    Parameters
    ----------
    horizon_s : float
        How far ahead in time the remaining trajectory is checked against the predicted
        threats (s). Default 30.
    check_step_s : float
        Time step of the space-time conflict check (s); the check is exact for each sample and
        the step is further refined so that neither the vehicle nor a threat moves more than a
        quarter of the smallest inflated radius between samples. Default 0.1.
    replan_budget_s : float
        Initial estimate of the replanning time (s), refined by the measured times. Default 0.25.
    replan_margin_s : float
        Margin added to the replanning estimate (s): replan when the first conflict is further
        away than estimate + margin, switch otherwise. Default 3.
    switch_range_m : float
        Entry nodes of the alternatives must be within this distance of the current reference
        position (m). Default 20.
    inflation_m : float
        Added to every threat radius (m): vehicle half-size plus tracking error. Default 2.
    sensor_range_m : float
        Threats farther than this from the vehicle (now) are tracked but ignored by the decision
        (m). Default 1000.
    sweep_horizon_s : float
        For a replan, a moving threat is replaced by the volume it sweeps over this time (s).
        Default 12.
    replan_turn_rad : float
        The replan's lead (straight along the current velocity, before GART's path starts) is
        long enough for a first corner of at least this turn (rad). Default 1.0 (57 deg).
    gart_budget_s : float
        Wall-clock budget of the replanning GART after its first solution (s). Default 0.08.
    gart_first_budget_s : float
        Wall-clock budget to find the first solution (s). Default 0.15.
    entry_spacing_m : float
        Alternatives are resampled so that their entry nodes are at most this far apart (m).
        Default 2.
    max_candidates : int
        Most switch candidates (entry nodes) smoothed and checked per decision. Default 8.
    switch_budget_s : float
        Wall-clock time after which no further switch candidate is tried (s), so a switch
        decision stays bounded; the hold is the fallback. Default 0.15.
    hold_decel_m_s2 : float
        Largest deceleration of the hold (brake to a hover along the path) (m/s^2). Default 2.5,
        the lateral acceleration limit of the smoothing settings.
    estimate_gain : float
        Weight of a new measurement in the running estimate of the replanning time. Default 0.2.
    seed : int
        Seed of the manager's random generator when none is given. Default 0.
    """

    horizon_s: float = 30.0
    check_step_s: float = 0.1
    replan_budget_s: float = 0.25
    replan_margin_s: float = 3.0
    switch_range_m: float = 20.0
    inflation_m: float = 2.0
    sensor_range_m: float = 1000.0
    sweep_horizon_s: float = 12.0
    replan_turn_rad: float = 1.0
    gart_budget_s: float = 0.08
    gart_first_budget_s: float = 0.15
    entry_spacing_m: float = 2.0
    max_candidates: int = 8
    switch_budget_s: float = 0.15
    hold_decel_m_s2: float = 2.5
    estimate_gain: float = 0.2
    seed: int = 0

    def __post_init__(self) -> None:
        require_numbers(ConfigError, "threats", self, positive=(
            "horizon_s", "check_step_s", "replan_budget_s", "switch_range_m", "sensor_range_m",
            "switch_budget_s", "sweep_horizon_s", "gart_budget_s", "entry_spacing_m",
            "gart_first_budget_s", "hold_decel_m_s2", "estimate_gain"),
            non_negative=("replan_margin_s", "inflation_m", "replan_turn_rad"))
        if self.replan_turn_rad >= math.pi:
            raise ConfigError(f"threats.replan_turn_rad: must be < pi, got {self.replan_turn_rad!r}")
        if self.estimate_gain > 1:
            raise ConfigError(f"threats.estimate_gain: must be in (0, 1], got {self.estimate_gain!r}")
        require_int(ConfigError, "threats", "max_candidates", self.max_candidates, 1, 1000)
        require_int(ConfigError, "threats", "seed", self.seed, 0, 2**63 - 1)
