"""Speed profile along arc length under speed, acceleration, lateral-acceleration and jerk limits.

Paper section 3.2 ("adjust the duration") made explicit, in the style of time-optimal path
parameterisation by forward and backward passes:

1. ``arc_grid``: a grid of arc lengths every ``grid_step_m`` metres plus every piece joint
   (where a G2 spiral reaches its peak curvature) and every stop.
2. ``speed_limit_sq``: w_max(s) = min(v_max^2, a_lat / kappa(s)) (w = v^2); zero at stops.
3. ``erode``: w_max is replaced by its minimum over +-(v_max T + step) metres, where
   T = 2 a_max / j_max is the jerk filter's width (step 6): the filter mixes speeds from up to
   v_max T metres away, so eroding first keeps v^2 kappa <= a_lat after filtering.
4. ``forward_backward``: with w linear between knots, |dw/ds| <= 2 a_max is the acceleration
   limit; the largest such w below w_max is the minimum of a forward and a backward pass, each
   one ``numpy.minimum.accumulate`` (min-plus convolution with a cone): no Python loop.
5. ``raw_profile``: times from dt = 2 ds / (v_k + v_{k+1}) (exact for constant acceleration);
   a dwell of T at every stop.
6. The ``Trajectory`` smooths the raw profile with a moving average of width T, which bounds
   the jerk by 2 a_max / T = j_max and keeps speed <= v_max and |a| <= a_max.

The trajectory starts and ends at rest by default. Given a start (end) speed, the first (last)
v T / 2 metres are held at that speed so that the trajectory starts (ends) exactly at it with
zero along-track acceleration, which is what splicing needs.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from companion.errors import SmoothingError
from companion.flight.trajectory import RawProfile, Trajectory
from companion.smoothing.bezier import BezierPath
from companion.smoothing.settings import TrajectoryLimits

__all__ = ["time_parameterize", "retime", "arc_grid", "speed_limit_sq", "erode", "forward_backward"]

logger = logging.getLogger(__name__)


def _as_curve(curve) -> BezierPath:
    if isinstance(curve, BezierPath):
        return curve
    from companion.smoothing.polyline import clean_path

    nodes, _ = clean_path(curve, "curve")
    return BezierPath([nodes[i : i + 2] for i in range(nodes.shape[0] - 1)])


def _check_speed(name: str, value: float, limit: float, notes: list[str] | None = None) -> float:
    """Validate a boundary speed; above ``limit`` it is an error, or (with ``notes``) clamped."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise SmoothingError(f"{name}: expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise SmoothingError(f"{name}: must be a finite number >= 0, got {value!r}")
    if v > limit * (1.0 + 1e-6):
        if notes is None:
            raise SmoothingError(f"{name}: {v} m/s exceeds the speed limit {limit} m/s")
        notes.append(f"{name} {v:.3f} m/s is above the speed limit {limit} m/s; the profile starts at the limit")
    return min(v, limit)


def arc_grid(curve: BezierPath, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Arc-length grid of the speed profile and the curvature at its points.

    The grid holds: points at most ``step_m`` apart on the straight pieces (zero curvature),
    the arc-length table knots of every curved piece (16 per piece, uniform in the Bezier
    parameter, ends included; their curvature comes with the table), every stop, and the
    interior curvature peaks (G1 corners). G2 spirals have monotone curvature and G1 corners
    a single peak, so no curvature between two grid points exceeds the larger of the two.

    Returns
    -------
    s_m : ndarray, shape (N+1,)
        Increasing arc lengths from 0 to ``curve.length_m``.
    kappa_1_m : ndarray, shape (N+1,)
        Curvature at each (the larger one where two pieces meet).
    """
    starts = curve.piece_start_s
    lines = np.nonzero(~curve.curved_piece)[0]
    line_len = starts[lines + 1] - starts[lines]
    counts = np.maximum(1, np.ceil(line_len / step_m).astype(int))
    owner = np.repeat(np.arange(lines.size), counts + 1)
    offset = np.arange(owner.size) - np.repeat(np.cumsum(counts + 1) - (counts + 1), counts + 1)
    line_s = starts[lines][owner] + line_len[owner] * offset / counts[owner]
    knot_s, knot_kappa = curve.knots_with_curvature()
    peak_s = curve.curvature_peaks_s
    peak_kappa = curve.curvature(peak_s) if peak_s.size else np.zeros(0)
    s_all = np.concatenate([[0.0, curve.length_m], line_s, knot_s, peak_s, curve.stop_s])
    k_all = np.concatenate([np.zeros(2 + line_s.size), knot_kappa, peak_kappa, np.zeros(curve.stop_s.size)])
    order = np.argsort(s_all, kind="stable")
    s_sorted = np.clip(s_all[order], 0.0, curve.length_m)
    k_sorted = k_all[order]
    new = np.concatenate([[True], np.diff(s_sorted) > 1e-9])
    first = np.nonzero(new)[0]
    return s_sorted[first], np.maximum.reduceat(k_sorted, first)


def speed_limit_sq(kappa_1_m: np.ndarray, limits: TrajectoryLimits) -> np.ndarray:
    """Squared speed limit min(v_max^2, a_lat / kappa) from curvatures (N,) -> (N,)."""
    with np.errstate(divide="ignore"):
        lateral = np.where(kappa_1_m > 0.0, limits.lat_accel_m_s2 / np.maximum(kappa_1_m, 1e-300), np.inf)
    return np.minimum(limits.speed_m_s**2, lateral)


def erode(values: np.ndarray, s_m: np.ndarray, radius_m: float) -> np.ndarray:
    """Minimum of ``values`` over every window [s - radius, s + radius] (sparse-table RMQ).

    Parameters
    ----------
    values, s_m : ndarray, shape (N,)
        Values at increasing arc lengths.
    radius_m : float

    Returns
    -------
    ndarray, shape (N,)
    """
    n = values.size
    lo = np.searchsorted(s_m, s_m - radius_m, side="left")
    hi = np.searchsorted(s_m, s_m + radius_m, side="right") - 1
    length = hi - lo + 1
    levels = max(1, int(np.max(length)).bit_length())
    table = np.full((levels, n), np.inf)
    table[0] = values
    span = 1
    for k in range(1, levels):
        table[k, : n - span] = np.minimum(table[k - 1, : n - span], table[k - 1, span:])
        span *= 2
    level = np.floor(np.log2(np.maximum(length, 1))).astype(int)
    return np.minimum(table[level, lo], table[level, hi - (1 << level) + 1])


def forward_backward(w_max: np.ndarray, s_m: np.ndarray, accel_m_s2: float) -> np.ndarray:
    """Largest w = v^2 <= ``w_max`` with |dw/ds| <= 2 a between knots (forward/backward passes).

    Forward pass: w_k <= w_j + 2 a (s_k - s_j) for every j <= k, i.e.
    ``2 a s + minimum.accumulate(w_max - 2 a s)``; backward pass symmetrically.
    """
    two_a_s = 2.0 * accel_m_s2 * s_m
    forward = two_a_s + np.minimum.accumulate(w_max - two_a_s)
    backward = -two_a_s + np.minimum.accumulate((w_max + two_a_s)[::-1])[::-1]
    return np.maximum(np.minimum(forward, backward), 0.0)


def raw_profile(
    s_m: np.ndarray, w: np.ndarray, stop_idx: np.ndarray, window_s: float, start_speed_m_s: float, end_speed_m_s: float
) -> RawProfile:
    """Times of the knots (constant acceleration between them) with a dwell at every stop."""
    v = np.sqrt(w)
    ds = np.diff(s_m)
    vsum = v[:-1] + v[1:]
    dt = 2.0 * ds / np.maximum(vsum, 1e-12)
    accel = np.where(dt > 0, (v[1:] - v[:-1]) / np.maximum(dt, 1e-300), 0.0)
    if stop_idx.size:
        # insert a knot with the same (s, v = 0) after every stop knot, reached after the dwell
        insert_at = stop_idx  # knot index of the stop
        s_out = np.insert(s_m, insert_at + 1, s_m[insert_at])
        v_out = np.insert(v, insert_at + 1, 0.0)
        dt_out = np.insert(dt, insert_at, window_s)
        a_out = np.insert(accel, insert_at, 0.0)
    else:
        s_out, v_out, dt_out, a_out = s_m, v, dt, accel
    tau = np.concatenate([[0.0], np.cumsum(dt_out)])
    return RawProfile(
        tau_s=tau,
        s_m=s_out,
        v_m_s=v_out,
        a_m_s2=a_out,
        window_s=window_s,
        start_speed_m_s=start_speed_m_s,
        end_speed_m_s=end_speed_m_s,
    )


def time_parameterize(
    curve,
    limits: TrajectoryLimits | None = None,
    *,
    start_speed_m_s: float = 0.0,
    end_speed_m_s: float = 0.0,
    grid_step_m: float = 1.0,
    yaw_mode: str = "tangent",
    yaw_hold_rad: float | None = None,
) -> Trajectory:
    """Time-parameterise a curve under speed, acceleration, lateral-acceleration and jerk limits.

    Parameters
    ----------
    curve : BezierPath or array_like, shape (M, d)
        The geometry. A polyline is flown as straight lines, stopping at every corner.
    limits : TrajectoryLimits, optional
        Defaults to ``TrajectoryLimits()`` (8 m/s, 2 m/s^2, 2.5 m/s^2 lateral, 3 m/s^3).
    start_speed_m_s, end_speed_m_s : float
        Speed along the tangent at the start and the end (default 0: from and to rest); the
        acceleration there is zero. A start speed above the limits (the vehicle is already
        faster) is lowered to what they allow, with a note: a velocity step, never an error.
    grid_step_m : float
        Largest arc-length step of the profile grid (m); curved pieces are sampled more
        densely anyway (16 knots per piece plus their curvature peaks). Default 1.
    yaw_mode : str
        ``"tangent"`` or ``"hold"``.
    yaw_hold_rad : float, optional
        Yaw of the ``"hold"`` mode (default: the initial tangent heading).

    Returns
    -------
    Trajectory
        Its speed never exceeds ``speed_m_s``, the along-track acceleration ``accel_m_s2``,
        the along-track jerk ``jerk_m_s3``, and v^2 kappa exceeds ``lat_accel_m_s2`` only by
        the discretisation of the curvature on the grid (well below 1 % at the default step).

    Raises
    ------
    SmoothingError
        Bad limits, a negative boundary speed, an end speed above the speed limit, a
        non-positive grid step.
    """
    limits = TrajectoryLimits() if limits is None else limits
    if not isinstance(limits, TrajectoryLimits):
        raise SmoothingError(f"limits: expected a TrajectoryLimits, got {type(limits).__name__}")
    if (
        isinstance(grid_step_m, bool)
        or not isinstance(grid_step_m, (int, float))
        or not math.isfinite(grid_step_m)
        or grid_step_m <= 0
    ):
        raise SmoothingError(f"grid_step_m: must be a finite number > 0, got {grid_step_m!r}")
    notes: list[str] = []
    v0 = _check_speed("start_speed_m_s", start_speed_m_s, limits.speed_m_s, notes)
    v1 = _check_speed("end_speed_m_s", end_speed_m_s, limits.speed_m_s)
    path = _as_curve(curve)
    window = 2.0 * limits.accel_m_s2 / limits.jerk_m_s3
    step = min(float(grid_step_m), max(path.length_m / 4.0, 1e-6))
    s, kappa = arc_grid(path, step)
    w_max = speed_limit_sq(kappa, limits)
    stop_idx = np.searchsorted(s, path.stop_s)
    w_max[stop_idx] = limits.speed_m_s**2
    max_gap = float(np.max(np.diff(s)))
    w_max = erode(w_max, s, limits.speed_m_s * window + max_gap)
    w_max[stop_idx] = 0.0
    hold_start = s <= v0 * window / 2.0 + max_gap + 1e-9
    hold_end = s >= path.length_m - v1 * window / 2.0 - max_gap - 1e-9
    w_max[0] = min(w_max[0], v0**2)
    w_max[-1] = min(w_max[-1], v1**2)
    if v0 > 0.0:
        w_max[hold_start] = np.minimum(w_max[hold_start], v0**2)
    if v1 > 0.0:
        w_max[hold_end] = np.minimum(w_max[hold_end], v1**2)
    w = forward_backward(w_max, s, limits.accel_m_s2)
    if v0 > 0 and w[0] < v0**2 * (1 - 1e-9):
        notes.append(
            f"start speed {v0:.3f} m/s is above the {math.sqrt(w[0]):.3f} m/s the limits allow "
            f"at the start; the profile starts slower"
        )
    if v1 > 0 and w[-1] < v1**2 * (1 - 1e-9):
        notes.append(f"end speed {v1:.3f} m/s is above the {math.sqrt(w[-1]):.3f} m/s the limits allow at the end")
    for note in notes:
        logger.warning("time_parameterize: %s", note)
    v0 = min(v0, math.sqrt(w[0]))
    v1 = min(v1, math.sqrt(w[-1]))
    profile = raw_profile(s, w, stop_idx, window, v0, v1)
    tau_start = -window / 2.0 if v0 == 0.0 else 0.0
    tau_end = profile.tau_s[-1] + (window / 2.0 if v1 == 0.0 else 0.0)
    if yaw_hold_rad is None:
        t0 = path.derivative(0.0, 1)
        yaw_hold_rad = float(math.atan2(t0[1], t0[0])) if np.hypot(t0[0], t0[1]) > 1e-6 else 0.0
    return Trajectory(
        path,
        profile,
        limits,
        tau_start,
        tau_end,
        yaw_mode=yaw_mode,
        yaw_hold_rad=yaw_hold_rad,
        notes=notes,
        grid_step_m=float(grid_step_m),
    )


def retime(trajectory: Trajectory, limits: TrajectoryLimits) -> Trajectory:
    """The same curve and boundary speeds as ``trajectory``, re-timed for other ``limits`` (e.g.
    ``limits.stretched(k)``); lifted to the same altitude when ``trajectory`` is."""
    p = trajectory.profile
    out = time_parameterize(
        trajectory.curve,
        limits,
        start_speed_m_s=p.start_speed_m_s,
        end_speed_m_s=p.end_speed_m_s,
        grid_step_m=trajectory.grid_step_m,
        yaw_mode=trajectory.yaw_mode,
        yaw_hold_rad=trajectory.yaw_hold_rad,
    )
    return out.to_ned(trajectory.down_m) if trajectory.down_m is not None else out
