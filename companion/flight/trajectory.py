"""Trajectory: a smoothed curve flown along a speed profile, sampled by time.

The speed profile (built by ``companion.smoothing.timing``) is stored as a *raw* profile:
knots tau_k of time, arc length s_k and speed v_k with a constant acceleration a_k between
knots, plus constant-speed extensions before the start and after the end. The flown profile is
the raw one smoothed by a moving average of width T (a box filter):

    s(t) = (1/T) int_{t-T/2}^{t+T/2} s_raw,   v(t) = (s_raw(t+T/2) - s_raw(t-T/2)) / T,
    a(t) = (v_raw(t+T/2) - v_raw(t-T/2)) / T,

evaluated in closed form from the antiderivative of the piecewise-quadratic s_raw. With
|a_raw| <= a_max and T = 2 a_max / j_max the jerk is bounded by j_max, and the acceleration is
continuous (it starts and ends at zero). The position, velocity and acceleration then follow
from the curve by the chain rule (r_s, r_ss are the arc-length derivatives):

    pos = r(s),   vel = r_s v,   acc = r_ss v^2 + r_s a,

so the velocity is the exact derivative of the position and the acceleration that of the
velocity (up to the curve's arc-length table). Sampling K times costs a few vectorised numpy
operations (two ``searchsorted`` and one Bernstein evaluation).

A 2D trajectory (north-east) is lifted to 3D NED at a fixed altitude with ``to_ned(down_m)``.

``FlyableReference`` is what every reference the companion flies offers (``Trajectory``, the
``TrajectoryChain`` of a leg, a ``RetimedTrajectory`` and its holds, an ``EscapeManoeuvre``):
what ``ActiveReference``, the retimer and the chains use of it, and nothing more.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from companion.errors import TrajectoryError

# The ufunc that ``np.clip`` calls, without its Python wrappers: the same results (NaN and signed
# zeros included) for a fraction of the cost. Not imported from ``companion.smoothing`` (which
# imports this module).
if TYPE_CHECKING:  # numpy's stubs do not declare the private umath.clip
    clip_ufunc: np.ufunc
else:
    try:  # numpy >= 2
        from numpy._core.umath import clip as clip_ufunc
    except ImportError:  # numpy 1.26
        from numpy.core.umath import clip as clip_ufunc

__all__ = ["Trajectory", "RawProfile", "FlyableReference"]

logger = logging.getLogger(__name__)


@runtime_checkable
class FlyableReference(Protocol):
    """A reference the companion can fly: sampled by time from t = 0 to ``duration_s``.

    Used by ``companion.flight.reference.ActiveReference`` (the setpoint stream), by
    ``companion.flight.plan.TrajectoryChain`` (its pieces) and by
    ``companion.threats.decision.retime.RetimedTrajectory`` (its base). Implementations clip ``t_s`` to
    [0, duration_s] (or hover after the end).

    Attributes
    ----------
    duration_s : float
        Time from the start to the end (s).
    length_m : float
        Length of the path flown (m).
    end_pos_ned_m : ndarray, shape (D,)
        Where it ends (where the vehicle holds after ``duration_s``).
    """

    duration_s: float
    length_m: float

    @property
    def end_pos_ned_m(self) -> np.ndarray: ...

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at times ``t_s`` (K,) -> three (K, D) arrays."""
        ...

    def yaw_rad(self, t_s) -> np.ndarray:
        """Yaw reference (rad) at times ``t_s`` (K,) -> (K,)."""
        ...

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        """Yaw-rate reference (rad/s) at times ``t_s`` (K,) -> (K,)."""
        ...


@dataclass(frozen=True)
class RawProfile:
    """Piecewise-constant-acceleration speed profile along arc length, before smoothing.

    Attributes
    ----------
    tau_s : ndarray, shape (N+1,)
        Knot times, tau_s[0] = 0, non-decreasing.
    s_m : ndarray, shape (N+1,)
        Arc length at the knots.
    v_m_s : ndarray, shape (N+1,)
        Speed at the knots.
    a_m_s2 : ndarray, shape (N,)
        Constant acceleration on each interval.
    window_s : float
        Width T of the box filter (s).
    start_speed_m_s, end_speed_m_s : float
        Speeds of the constant-speed extensions before tau_s[0] and after tau_s[-1].
    """

    tau_s: np.ndarray
    s_m: np.ndarray
    v_m_s: np.ndarray
    a_m_s2: np.ndarray
    window_s: float
    start_speed_m_s: float
    end_speed_m_s: float
    if TYPE_CHECKING:
        # the double integral of the speed at the knots, set by __post_init__; not a field at run
        # time (a class-level annotation would make it one)
        _s2: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h = np.diff(self.tau_s)
        area = self.s_m[:-1] * h + self.v_m_s[:-1] * h**2 / 2 + self.a_m_s2 * h**3 / 6
        object.__setattr__(self, "_s2", np.concatenate([[0.0], np.cumsum(area)]))

    def evaluate(self, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw (arc length, speed, antiderivative of arc length) at times ``tau_s`` (K,)."""
        tau = self.tau_s
        k = clip_ufunc(np.searchsorted(tau, tau_s, side="right") - 1, 0, tau.size - 2)
        h = tau_s - tau[k]
        s0, v0, a = self.s_m[k], self.v_m_s[k], self.a_m_s2[k]
        s = s0 + v0 * h + 0.5 * a * h * h
        v = v0 + a * h
        s2 = self._s2[k] + s0 * h + 0.5 * v0 * h * h + a * h**3 / 6.0
        before = tau_s < tau[0]
        if before.any():
            hb = tau_s[before] - tau[0]
            vs = self.start_speed_m_s
            s[before] = self.s_m[0] + vs * hb
            v[before] = vs
            s2[before] = self.s_m[0] * hb + 0.5 * vs * hb * hb
        after = tau_s > tau[-1]
        if after.any():
            ha = tau_s[after] - tau[-1]
            ve = self.end_speed_m_s
            s[after] = self.s_m[-1] + ve * ha
            v[after] = ve
            s2[after] = self._s2[-1] + self.s_m[-1] * ha + 0.5 * ve * ha * ha
        return s, v, s2

    def filtered(self, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Box-filtered (arc length, speed, acceleration) at raw times ``tau_s`` (K,).

        Both ends of the windows are evaluated in one call (the arithmetic is elementwise).
        """
        half = 0.5 * self.window_s
        hi, lo = tau_s + half, tau_s - half
        if hi.ndim == 1:
            s, v, s2 = self.evaluate(np.concatenate((hi, lo)))
            k = hi.size
            s_hi, v_hi, s2_hi, s_lo, v_lo, s2_lo = s[:k], v[:k], s2[:k], s[k:], v[k:], s2[k:]
        else:
            (s_hi, v_hi, s2_hi), (s_lo, v_lo, s2_lo) = self.evaluate(hi), self.evaluate(lo)
        inv = 1.0 / self.window_s
        return (s2_hi - s2_lo) * inv, (s_hi - s_lo) * inv, (v_hi - v_lo) * inv


class Trajectory:
    """A time-parameterised curve (DESIGN section 4), built by ``time_parameterize``.

    Parameters
    ----------
    curve : companion.smoothing.BezierPath
        The geometry, addressed by arc length.
    profile : RawProfile
        The raw speed profile along the curve's arc length.
    limits : companion.smoothing.TrajectoryLimits
        The limits the profile was built for.
    tau_start_s, tau_end_s : float
        Raw-profile times of the trajectory's start and end (t = 0 is ``tau_start_s``).
    yaw_mode : str
        ``"tangent"`` (yaw follows the horizontal tangent) or ``"hold"``.
    yaw_hold_rad : float
        Yaw of the ``"hold"`` mode, and of a path with no horizontal motion at all.
    down_m : float or None
        For a 2D curve lifted to NED: the fixed down coordinate (m).
    notes : list of str
        What the time-parameterisation could not honour (e.g. a start speed above the limits).

    Attributes
    ----------
    duration_s : float
    length_m : float
    d : int
        Dimension of the samples (3 for a lifted 2D trajectory).
    """

    def __init__(
        self,
        curve,
        profile: RawProfile,
        limits,
        tau_start_s: float,
        tau_end_s: float,
        *,
        yaw_mode: str = "tangent",
        yaw_hold_rad: float = 0.0,
        down_m: float | None = None,
        notes=(),
        grid_step_m: float = 1.0,
    ) -> None:
        if yaw_mode not in ("tangent", "hold"):
            raise TrajectoryError(f"yaw_mode: expected 'tangent' or 'hold', got {yaw_mode!r}")
        self.curve = curve
        self.profile = profile
        self.limits = limits
        self._tau_start = float(tau_start_s)
        self.duration_s = float(tau_end_s - tau_start_s)
        self.length_m = float(curve.length_m)
        self.yaw_mode = yaw_mode
        self.yaw_hold_rad = float(yaw_hold_rad)
        self.down_m = down_m
        self.notes = list(notes)
        self.grid_step_m = grid_step_m
        self.d = 3 if down_m is not None else curve.d

    # ------------------------------------------------------------------ construction helpers
    @cached_property
    def _fallback_yaw_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Yaw at points every few metres, carried over stretches without horizontal motion."""
        n = max(2, int(math.ceil(self.length_m / 2.0)) + 1)
        s = np.linspace(0.0, self.length_m, n)
        tangent = self.curve.derivative(s, 1)
        horizontal = np.linalg.norm(tangent[:, :2], axis=1) > 1e-6
        yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
        if not np.any(horizontal):
            return s, np.full(n, self.yaw_hold_rad)
        idx = np.where(horizontal, np.arange(n), -1)
        idx = np.maximum.accumulate(idx)
        first = int(np.argmax(horizontal))
        idx[idx < 0] = first
        return s, yaw[idx]

    def _check_t(self, t_s) -> tuple[np.ndarray, bool]:
        arr = np.asarray(t_s, dtype=float)
        if not np.isfinite(arr).all():
            raise TrajectoryError("t_s: times must be finite (no NaN or inf)")
        return clip_ufunc(arr.reshape(-1), 0.0, self.duration_s), arr.ndim == 0

    def _lift(self, xy: np.ndarray, down: float) -> np.ndarray:
        if self.down_m is None:
            return xy
        out = np.empty((xy.shape[0], xy.shape[1] + 1))
        out[:, :-1] = xy
        out[:, -1] = down
        return out

    # ------------------------------------------------------------------ sampling
    def progress(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arc length (m), speed (m/s) and along-track acceleration (m/s^2) at times ``t_s`` (K,)."""
        t, scalar = self._check_t(t_s)
        s, v, a = self.profile.filtered(t + self._tau_start)
        s = clip_ufunc(s, 0.0, self.length_m)
        if scalar:
            return s[0], v[0], a[0]
        return s, v, a

    def s_at(self, t_s) -> np.ndarray:
        """Arc length (m) reached at times ``t_s`` (K,) -> (K,)."""
        return self.progress(t_s)[0]

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at times ``t_s``.

        Parameters
        ----------
        t_s : array_like, shape (K,) or scalar
            Times since the start (s); clipped to [0, duration_s].

        Returns
        -------
        pos, vel, acc : ndarray, shape (K, d) (or (d,) for a scalar time)
            In the curve's frame (north-east for 2D, NED when lifted with ``to_ned``), m, m/s,
            m/s^2.
        """
        t, scalar = self._check_t(t_s)
        s, v, a = self.profile.filtered(t + self._tau_start)
        s = clip_ufunc(s, 0.0, self.length_m)
        piece, u = self.curve.locate(s)
        r, r_s, r_ss = self.curve._arc_derivatives(piece, u, 2)
        vv = v[:, None]
        pos = self._lift(r, self.down_m if self.down_m is not None else 0.0)
        vel = self._lift(r_s * vv, 0.0)
        acc = self._lift(r_ss * vv * vv + r_s * a[:, None], 0.0)
        if scalar:
            return pos[0], vel[0], acc[0]
        return pos, vel, acc

    def yaw_rad(self, t_s) -> np.ndarray:
        """Yaw (rad, in (-pi, pi]) at times ``t_s`` (K,) -> (K,).

        ``"tangent"``: the heading of the horizontal tangent (where the path is vertical, the
        last horizontal heading is held); ``"hold"``: ``yaw_hold_rad``.
        """
        t, scalar = self._check_t(t_s)
        if self.yaw_mode == "hold":
            out = np.full(t.shape, self.yaw_hold_rad)
            return out[0] if scalar else out
        s = clip_ufunc(self.profile.filtered(t + self._tau_start)[0], 0.0, self.length_m)
        piece, u = self.curve.locate(s)
        tangent = self.curve._arc_derivatives(piece, u, 1, position=False)[1]
        yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
        horizontal = tangent[:, :2]
        flat = np.sqrt(np.add.reduce(horizontal * horizontal, axis=1)) <= 1e-6  # np.linalg.norm
        if flat.any():
            table_s, table_yaw = self._fallback_yaw_table
            k = clip_ufunc(np.searchsorted(table_s, s[flat], side="right") - 1, 0, table_yaw.size - 1)
            yaw[flat] = table_yaw[k]
        return yaw[0] if scalar else yaw

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        """Rate of ``yaw_rad`` (rad/s) at times ``t_s`` (K,) -> (K,): v (t x t_s)_z / |t_h|^2."""
        t, scalar = self._check_t(t_s)
        if self.yaw_mode == "hold":
            out = np.zeros(t.shape)
            return out[0] if scalar else out
        s, v, _ = self.profile.filtered(t + self._tau_start)
        s = clip_ufunc(s, 0.0, self.length_m)
        piece, u = self.curve.locate(s)
        _, r_s, r_ss = self.curve._arc_derivatives(piece, u, 2, position=False)
        horiz2 = r_s[:, 0] ** 2 + r_s[:, 1] ** 2
        turn = r_s[:, 0] * r_ss[:, 1] - r_s[:, 1] * r_ss[:, 0]
        out = np.where(horiz2 > 1e-12, v * turn / np.maximum(horiz2, 1e-12), 0.0)
        return out[0] if scalar else out

    def time_at_s(self, s_m) -> np.ndarray:
        """Earliest time (s) at which arc length ``s_m`` (K,) is reached (bisection) -> (K,)."""
        s_target = np.clip(np.asarray(s_m, dtype=float).reshape(-1), 0.0, self.length_m)
        lo = np.zeros_like(s_target)
        hi = np.full_like(s_target, self.duration_s)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = self.s_at(mid) < s_target - 1e-9
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        return hi

    # ------------------------------------------------------------------ derived trajectories
    def to_ned(self, down_m: float) -> Trajectory:
        """A 2D (north-east) trajectory flown at fixed ``down_m`` (NED, m): samples become (K, 3)."""
        if self.curve.d != 2 or self.down_m is not None:
            raise TrajectoryError(f"to_ned: only a 2D trajectory can be lifted, this one is {self.d}D")
        if not math.isfinite(float(down_m)):
            raise TrajectoryError(f"down_m: must be finite, got {down_m!r}")
        return Trajectory(
            self.curve,
            self.profile,
            self.limits,
            self._tau_start,
            self._tau_start + self.duration_s,
            yaw_mode=self.yaw_mode,
            yaw_hold_rad=self.yaw_hold_rad,
            down_m=float(down_m),
            notes=self.notes,
            grid_step_m=self.grid_step_m,
        )

    def time_scaled(self, factor: float) -> Trajectory:
        """The same trajectory flown ``factor`` times slower (every duration times ``factor``).

        Exact: speeds scale by 1/factor, accelerations by 1/factor^2, jerk by 1/factor^3, and
        the limits accordingly (``TrajectoryLimits.stretched``). Boundary speeds scale too, so
        a trajectory that starts moving (a splice) no longer matches its start state.
        """
        k = float(factor)
        if not math.isfinite(k) or k <= 0:
            raise TrajectoryError(f"factor: must be a finite number > 0, got {factor!r}")
        p = self.profile
        profile = RawProfile(
            tau_s=p.tau_s * k,
            s_m=p.s_m,
            v_m_s=p.v_m_s / k,
            a_m_s2=p.a_m_s2 / k**2,
            window_s=p.window_s * k,
            start_speed_m_s=p.start_speed_m_s / k,
            end_speed_m_s=p.end_speed_m_s / k,
        )
        return Trajectory(
            self.curve,
            profile,
            self.limits.stretched(k),
            self._tau_start * k,
            (self._tau_start + self.duration_s) * k,
            yaw_mode=self.yaw_mode,
            yaw_hold_rad=self.yaw_hold_rad,
            down_m=self.down_m,
            notes=self.notes,
            grid_step_m=self.grid_step_m,
        )

    @property
    def start_pos_ned_m(self) -> np.ndarray:
        """Position at t = 0, shape (d,)."""
        return self.sample(0.0)[0]

    @property
    def end_pos_ned_m(self) -> np.ndarray:
        """Position at the end, shape (d,)."""
        return self.sample(self.duration_s)[0]

    def __repr__(self) -> str:
        return (
            f"Trajectory(d={self.d}, length_m={self.length_m:.2f}, duration_s={self.duration_s:.2f}, "
            f"limits={self.limits})"
        )
