"""Retime: the same path, slowed or paused so that a mover passes first (DESIGN 7.4).

A retimed reference follows its base trajectory through a time warp tau(t): the progress rate
r = dtau/dt eases from 1 down to ``rate`` over ``ramp_s`` (raised cosine), stays there for
``wait_s``, and eases back to 1. Then

    pos = base(tau),  vel = base'(tau) r,  acc = base''(tau) r^2 + base'(tau) r',

so the setpoint is continuous and the vehicle never leaves the path it was flying (which was
planned in free space). ``ramp_s = pi (1 - rate) v_max / (2 decel)`` keeps the along-track
deceleration within ``decel``. A pause (rate 0) with a long wait is a hold on the path.

Pure: numpy only.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

__all__ = ["RetimedTrajectory", "ramp_time_s"]


def ramp_time_s(rate: float, speed_m_s: float, decel_m_s2: float) -> float:
    """Duration (s) of the ease from rate 1 to ``rate`` at along-track deceleration <= decel."""
    return max(math.pi * (1.0 - rate) * speed_m_s / (2.0 * decel_m_s2), 1e-3)


class RetimedTrajectory:
    """``base`` from its time ``tau0_s`` on, through the time warp of the module docstring.

    Parameters
    ----------
    base : companion.flight.trajectory.FlyableReference
        Its ``sample``, ``yaw_rad``, ``yaw_rate_rad_s``, ``duration_s`` and ``length_m``.
    tau0_s : float
        Base time at this trajectory's t = 0.
    rate : float
        Progress rate while waiting, in [0, 1).
    wait_s : float
        Time spent at ``rate`` (s).
    ramp_s : float
        Duration of each ease (s).
    label : str

    Attributes
    ----------
    duration_s : float
        Time until the base's end is reached.
    delay_s : float
        ``duration_s`` minus the base's remaining time.
    end_pos_ned_m : ndarray
    """

    def __init__(self, base, tau0_s: float, rate: float, wait_s: float, ramp_s: float, label: str = ""):
        self.base = base
        self.tau0_s = float(tau0_s)
        self.rate = float(rate)
        self.wait_s = float(wait_s)
        self.ramp_s = float(ramp_s)
        self.label = label or f"retime x{rate:.1f} for {wait_s:.1f} s"
        warp_end = 2.0 * self.ramp_s + self.wait_s
        remaining = base.duration_s - self.tau0_s
        tau_warp = self._integral(np.array([warp_end]))[0]
        if tau_warp <= remaining:
            self.duration_s = warp_end + remaining - tau_warp
        else:                       # the base ends during the warp: find the time by bisection
            lo, hi = 0.0, warp_end
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if self._integral(np.array([mid]))[0] < remaining else (lo, mid)
            self.duration_s = hi
        self.delay_s = self.duration_s - remaining

    @cached_property
    def end_pos_ned_m(self) -> np.ndarray:
        """Where the retimed reference ends (the base's end), (D,)."""
        return np.atleast_2d(self.base.sample(np.array([self.base.duration_s]))[0])[0]

    def _rate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Progress rate r (K,) and its derivative r' (K,)."""
        drop = 1.0 - self.rate
        w = math.pi / self.ramp_s
        t2 = self.ramp_s + self.wait_s
        r = np.ones_like(t)
        dr = np.zeros_like(t)
        down = t < self.ramp_s
        r[down] = 1.0 - drop * 0.5 * (1.0 - np.cos(w * t[down]))
        dr[down] = -drop * 0.5 * w * np.sin(w * t[down])
        hold = (t >= self.ramp_s) & (t < t2)
        r[hold] = self.rate
        up = (t >= t2) & (t < t2 + self.ramp_s)
        x = t[up] - t2
        r[up] = self.rate + drop * 0.5 * (1.0 - np.cos(w * x))
        dr[up] = drop * 0.5 * w * np.sin(w * x)
        return r, dr

    def _integral(self, t: np.ndarray) -> np.ndarray:
        """Base time advanced since t = 0: the integral of r (K,)."""
        drop = 1.0 - self.rate
        w = math.pi / self.ramp_s
        ramp_loss = lambda x: drop * 0.5 * (x - np.sin(w * x) / w)   # noqa: E731 - int of 1 - r
        t1 = np.minimum(t, self.ramp_s)
        loss = ramp_loss(t1)
        t_hold = np.clip(t - self.ramp_s, 0.0, self.wait_s)
        loss = loss + drop * t_hold
        x = np.clip(t - self.ramp_s - self.wait_s, 0.0, self.ramp_s)
        loss = loss + drop * x - ramp_loss(x)     # int of (1 - r) on the way up
        return t - loss

    def _tau(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
        r, dr = self._rate(t)
        ended = t >= self.duration_s
        r[ended], dr[ended] = 0.0, 0.0
        return np.minimum(self.tau0_s + self._integral(t), self.base.duration_s), r, dr

    def tau_at(self, t_s) -> np.ndarray:
        """Base time (K,) at times ``t_s`` (K,)."""
        return self._tau(t_s)[0]

    def sample(self, t_s):
        """Position, velocity, acceleration (K, D) at times ``t_s`` (K,)."""
        tau, r, dr = self._tau(t_s)
        pos, vel, acc = (np.atleast_2d(v) for v in self.base.sample(tau))
        return pos, vel * r[:, None], acc * (r * r)[:, None] + vel * dr[:, None]

    def yaw_rad(self, t_s) -> np.ndarray:
        return self.base.yaw_rad(self._tau(t_s)[0])

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        tau, r, _ = self._tau(t_s)
        return self.base.yaw_rate_rad_s(tau) * r

    @property
    def length_m(self) -> float:
        return float(self.base.length_m)
