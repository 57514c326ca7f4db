"""What the vehicle flies: straight legs with a trapezoidal speed profile, the stages of a manoeuvre, GUIDED setpoints.

AUTO waypoints, takeoff, RTL and GUIDED position-only targets are flown as straight legs with a
trapezoidal speed profile (WPNAV_SPEED horizontally, WPNAV_SPEED_UP/DN vertically,
WPNAV_ACCEL): position, velocity and acceleration references for the controller. This is the
straight-leg baseline the companion's smoothed paths must beat. Pure numerics.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from heli_model.control import Setpoint


class Leg:
    """A straight leg flown with a trapezoidal (or triangular) speed profile.

    Parameters
    ----------
    start_ned_m, end_ned_m : (3,) array_like
        End points, m NED.
    speed_xy_m_s, speed_up_m_s, speed_down_m_s : float
        Limits of the horizontal, climb and descent components of the leg speed.
    accel_m_s2 : float
        Acceleration and deceleration along the leg.
    t0_s : float
        Simulated time at which the leg starts.
    """

    def __init__(
        self,
        start_ned_m: Any,
        end_ned_m: Any,
        speed_xy_m_s: float,
        speed_up_m_s: float,
        speed_down_m_s: float,
        accel_m_s2: float,
        t0_s: float,
    ) -> None:
        self.start = np.asarray(start_ned_m, dtype=float).copy()
        self.end = np.asarray(end_ned_m, dtype=float).copy()
        delta = self.end - self.start
        self.length_m = float(np.linalg.norm(delta))
        self.t0_s = float(t0_s)
        self.dir = delta / self.length_m if self.length_m > 1e-9 else np.zeros(3)
        speed = math.inf
        horizontal = math.hypot(delta[0], delta[1])
        if horizontal > 1e-9:
            speed = min(speed, speed_xy_m_s * self.length_m / horizontal)
        if delta[2] < -1e-9:
            speed = min(speed, speed_up_m_s * self.length_m / -delta[2])
        elif delta[2] > 1e-9:
            speed = min(speed, speed_down_m_s * self.length_m / delta[2])
        if not math.isfinite(speed):
            speed = speed_xy_m_s
        self.accel_m_s2 = float(accel_m_s2)
        if self.length_m * self.accel_m_s2 < speed * speed:  # triangular: never reaches cruise speed
            speed = math.sqrt(self.length_m * self.accel_m_s2)
        self.speed_m_s = float(speed)
        self.t_acc_s = self.speed_m_s / self.accel_m_s2 if self.accel_m_s2 > 0 else 0.0
        cruise_m = self.length_m - self.speed_m_s * self.t_acc_s
        self.t_cruise_s = cruise_m / self.speed_m_s if self.speed_m_s > 1e-9 else 0.0
        self.duration_s = 2.0 * self.t_acc_s + self.t_cruise_s

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference at simulated time ``t_s``: position (3,), velocity (3,), acceleration (3,)."""
        tau = t_s - self.t0_s
        a, v, ta, tc = self.accel_m_s2, self.speed_m_s, self.t_acc_s, self.t_cruise_s
        if tau <= 0.0 or self.length_m <= 1e-9:
            s, sd, sdd = 0.0, 0.0, 0.0
        elif tau < ta:
            s, sd, sdd = 0.5 * a * tau * tau, a * tau, a
        elif tau < ta + tc:
            s, sd, sdd = 0.5 * a * ta * ta + v * (tau - ta), v, 0.0
        elif tau < self.duration_s:
            rem = self.duration_s - tau
            s, sd, sdd = self.length_m - 0.5 * a * rem * rem, a * rem, -a
        else:
            s, sd, sdd = self.length_m, 0.0, 0.0
        if self.length_m <= 1e-9:
            return self.end.copy(), np.zeros(3), np.zeros(3)
        return self.start + self.dir * s, self.dir * sd, self.dir * sdd

    def finished(self, t_s: float) -> bool:
        """True once the reference has arrived at the end."""
        return t_s >= self.t0_s + self.duration_s


@dataclasses.dataclass
class Stage:
    """One step of what the vehicle is doing.

    kind: ``leg`` (fly to ``target``), ``hold`` (stay at ``target``, for ``duration_s`` or
    forever when None), ``land`` (descend until touchdown), ``direct`` (GUIDED setpoint).
    ``leg`` is built when the stage starts (``started_s``, simulated s).
    """

    kind: str
    target: np.ndarray | None = None
    duration_s: float | None = None
    radius_m: float = 0.0
    speed_xy_m_s: float | None = None
    vertical_only: bool = False
    leg: Leg | None = None
    started_s: float | None = None
    arrived_s: float | None = None


@dataclasses.dataclass
class GuidedCommand:
    """A direct GUIDED setpoint and when it arrived (simulated s)."""

    setpoint: Setpoint
    received_s: float
