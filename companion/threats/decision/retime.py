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

# The ufunc that ``np.clip`` calls, without its Python wrappers (same results, NaN and signed
# zeros included).
try:  # numpy >= 2
    from numpy._core.umath import clip as clip_ufunc
except ImportError:  # numpy 1.26
    from numpy.core.umath import clip as clip_ufunc

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
        self._constants()
        warp_end = 2.0 * self.ramp_s + self.wait_s
        remaining = base.duration_s - self.tau0_s
        tau_warp = self._integral(np.array([warp_end]))[0]
        if tau_warp <= remaining:
            self.duration_s = warp_end + remaining - tau_warp
        else:  # the base ends during the warp: find the time by bisection
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

    def _constants(self) -> None:
        """Constants of the warp, each computed as ``_rate`` and ``_integral`` would compute it."""
        self._drop = 1.0 - self.rate
        self._half_drop = self._drop * 0.5
        self._w = math.pi / self.ramp_s
        self._dr_gain = self._drop * 0.5 * self._w  # |r'| = _dr_gain sin(w x)
        self._t2 = self.ramp_s + self.wait_s  # start of the way up
        self._t3 = self._t2 + self.ramp_s  # end of the warp

    def _rate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Progress rate r (K,) and its derivative r' (K,)."""
        if t.shape == (1,):
            return self._rate_at_one(t)
        half_drop, w, t2 = self._half_drop, self._w, self._t2
        r = np.ones_like(t)
        dr = np.zeros_like(t)
        down = t < self.ramp_s
        r[down] = 1.0 - half_drop * (1.0 - np.cos(w * t[down]))
        dr[down] = -self._dr_gain * np.sin(w * t[down])
        hold = (t >= self.ramp_s) & (t < t2)
        r[hold] = self.rate
        up = (t >= t2) & (t < self._t3)
        x = t[up] - t2
        r[up] = self.rate + half_drop * (1.0 - np.cos(w * x))
        dr[up] = self._dr_gain * np.sin(w * x)
        return r, dr

    def _rate_at_one(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``_rate`` at one time, t shape (1,): only the branch it falls in (the same operations)."""
        t0 = t[0]
        if t0 < self.ramp_s:
            wt = self._w * t
            return 1.0 - self._half_drop * (1.0 - np.cos(wt)), -self._dr_gain * np.sin(wt)
        if t0 < self._t2:
            return np.full(1, self.rate), np.zeros(1)
        if t0 < self._t3:
            wx = self._w * (t - self._t2)
            return self.rate + self._half_drop * (1.0 - np.cos(wx)), self._dr_gain * np.sin(wx)
        return np.ones(1), np.zeros(1)  # after the warp (or NaN, as ``_rate``)

    def _integral(self, t: np.ndarray) -> np.ndarray:
        """Base time advanced since t = 0: the integral of r (K,)."""
        half_drop, w = self._half_drop, self._w
        t1 = np.minimum(t, self.ramp_s)
        loss = half_drop * (t1 - np.sin(w * t1) / w)  # int of 1 - r on the way down
        since_ramp = t - self.ramp_s
        t_hold = clip_ufunc(since_ramp, 0.0, self.wait_s)
        loss = loss + self._drop * t_hold
        x = clip_ufunc(since_ramp - self.wait_s, 0.0, self.ramp_s)
        loss = loss + self._drop * x - half_drop * (x - np.sin(w * x) / w)  # and on the way up
        return t - loss

    def _clipped(self, t_s) -> np.ndarray:
        return clip_ufunc(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)

    def _tau(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = self._clipped(t_s)
        r, dr = self._rate(t)
        ended = t >= self.duration_s
        if ended.any():
            r[ended], dr[ended] = 0.0, 0.0
        return np.minimum(self.tau0_s + self._integral(t), self.base.duration_s), r, dr

    def _tau_only(self, t_s) -> np.ndarray:
        """The first output of ``_tau`` (which does not depend on r)."""
        return np.minimum(self.tau0_s + self._integral(self._clipped(t_s)), self.base.duration_s)

    def _innermost(self) -> tuple[list[RetimedTrajectory], object]:
        """The retimes nested in this one, outermost first, and the reference under them all."""
        levels, ref = [], self
        while isinstance(ref, RetimedTrajectory):
            levels.append(ref)
            ref = ref.base
        return levels, ref

    def tau_at(self, t_s) -> np.ndarray:
        """Base time (K,) at times ``t_s`` (K,)."""
        return self._tau_only(t_s)

    def sample(self, t_s):
        """Position, velocity, acceleration (K, D) at times ``t_s`` (K,).

        Nested retimes are composed in one loop: the times are warped level after level, the
        innermost reference is sampled once and its derivatives are scaled back out, level
        after level (the same operations as the recursion through every level's ``sample``).
        """
        levels, inner = self._innermost()
        tau, rates = t_s, []
        for level in levels:
            tau, r, dr = level._tau(tau)
            rates.append((r, dr))
        pos, vel, acc = (np.atleast_2d(v) for v in inner.sample(tau))
        for r, dr in reversed(rates):
            vel, acc = vel * r[:, None], acc * (r * r)[:, None] + vel * dr[:, None]
        return pos, vel, acc

    def yaw_rad(self, t_s) -> np.ndarray:
        levels, inner = self._innermost()
        tau = t_s
        for level in levels:
            tau = level._tau_only(tau)
        return inner.yaw_rad(tau)

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        levels, inner = self._innermost()
        tau, rates = t_s, []
        for level in levels:
            tau, r, _ = level._tau(tau)
            rates.append(r)
        out = inner.yaw_rate_rad_s(tau)
        for r in reversed(rates):
            out = out * r
        return out

    @property
    def length_m(self) -> float:
        return float(self.base.length_m)
