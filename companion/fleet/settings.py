"""Settings of the fleet stage: sharing committed trajectories with other vehicles (DESIGN 6, 7).

Table ``[fleet]`` of the settings tree. Why these defaults (R-50-class helicopters at 6-8 m/s,
companions meeting through a zenoh router on a local network):

- the required separation is two rotor radii plus ``margin_m``: 2 x 1.6 + 1.0 = 4.2 m. Another
  vehicle's tube has radius ``rotor_radius_m + tracking_m + margin_m`` (its body, its tracking
  error, the margin) and the threat layer adds its own ``threats.inflation_m`` (this vehicle's
  rotor and tracking error): 5.1 m in all.
- ``publish_period_s = 0.5``: the committed trajectory, ``horizon_s = 30`` s of it every
  ``sample_step_s = 0.5`` s, goes out twice a second and at once when it changes: the message
  is also the heartbeat that says the vehicle is alive.
- ``delay_check_s = 0.2``: the least wait between publishing a new trajectory and flying it
  (RMADER's delay check); the wait is longer when the measured delay of the others' messages is.
- ``yield_s = 4``: a vehicle keeps its path against one with a higher system id, which must
  give way, unless a conflict comes within 4 s (then it acts too).
- ``stale_after_s = 2``: a vehicle not heard from for that long becomes a growing threat
  (``stale_growth_m_s`` up to ``stale_max_m``); after ``forget_after_s`` it is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

from companion.errors import ConfigError
from heli_common.typed_config import require_numbers

__all__ = ["FLEET_DELAY_ENV", "FleetSettings"]

FLEET_DELAY_ENV = "HELI_COMPANION_TEST_FLEET_DELAY_MS"
"""Fault injection for tests and ``companion fleet up --trajectory-delay-ms``: a companion started
with this environment variable holds every trajectory message that many ms before publishing it
(``inject_delay_s``; read by ``companion.commands.run.injected_fleet_delay_s``). Not a user option."""


@dataclass(frozen=True)
class FleetSettings:
    """Trajectory sharing between companions (``companion.fleet``).

    Parameters
    ----------
    enabled : bool
        Publish this vehicle's committed trajectory on ``uav/<sysid>/trajectory`` and avoid the
        others' (``--no-fleet`` turns it off). Needs zenoh.
    publish_period_s : float
        Wall-clock period of the trajectory message (it is also sent at every change).
    horizon_s, sample_step_s : float
        How far ahead the committed trajectory is published, and its sample spacing (vehicle s).
    rotor_radius_m : float
        This vehicle's rotor radius (m), carried in its messages.
    tracking_m : float
        Allowance for a vehicle's tracking error around its published trajectory (m).
    margin_m : float
        Separation kept beyond two rotor radii (m).
    growth_m_s, growth_max_m : float
        Growth of another vehicle's tube with the age of its message (m per vehicle s), and cap.
    stale_after_s, stale_growth_m_s, stale_max_m : float
        Without a message for ``stale_after_s`` (wall s), the tube grows at ``stale_growth_m_s``
        from the last message's time, up to ``stale_max_m``.
    forget_after_s : float
        A vehicle not heard from for this long (wall s) is dropped.
    delay_check_s : float
        Least wait (wall s) between publishing a new trajectory and flying it; the wait is the
        larger of this and the largest delay measured on the others' messages plus 50 ms.
    yield_s : float
        Against a vehicle with a higher system id, only conflicts within this time (vehicle s)
        are acted on: that vehicle gives way.
    inject_delay_s : float
        Testing: hold every trajectory message this long (wall s) before publishing it.
    """

    enabled: bool = True
    publish_period_s: float = 0.5
    horizon_s: float = 30.0
    sample_step_s: float = 0.5
    rotor_radius_m: float = 1.6
    tracking_m: float = 0.5
    margin_m: float = 1.0
    growth_m_s: float = 0.1
    growth_max_m: float = 2.0
    stale_after_s: float = 2.0
    stale_growth_m_s: float = 3.0
    stale_max_m: float = 20.0
    forget_after_s: float = 120.0
    delay_check_s: float = 0.2
    yield_s: float = 4.0
    inject_delay_s: float = 0.0

    def __post_init__(self) -> None:
        require_numbers(
            ConfigError,
            "fleet",
            self,
            positive=(
                "publish_period_s",
                "horizon_s",
                "sample_step_s",
                "rotor_radius_m",
                "stale_after_s",
                "forget_after_s",
            ),
            non_negative=(
                "tracking_m",
                "margin_m",
                "growth_m_s",
                "growth_max_m",
                "stale_growth_m_s",
                "stale_max_m",
                "delay_check_s",
                "yield_s",
                "inject_delay_s",
            ),
        )
        if self.forget_after_s <= self.stale_after_s:
            raise ConfigError(
                f"fleet.forget_after_s: must exceed stale_after_s ({self.stale_after_s}), got {self.forget_after_s}"
            )

    @property
    def separation_m(self) -> float:
        """The separation two vehicles must keep: two rotor radii plus the margin (m)."""
        return 2.0 * self.rotor_radius_m + self.margin_m
