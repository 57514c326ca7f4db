"""Splicing: a trajectory that starts at the current reference state and joins a path.

Paper section 3.3 (switching to a pre-planned safe path) with DESIGN section 7's requirement
that the switch happens "without a jump". The threat manager (or the daemon) takes the current
setpoint ``(pos, vel, acc) = active.sample(t_now)`` and calls ``join_from_state``:

1. ``lead_in_length``: a straight lead-in along the current velocity, long enough to brake
   from the current speed to the corner speed sqrt(a_lat / K_max) and to fit the first G2
   corner (eq. 19), plus the box-filter hold (the start speed is held for v T / 2 metres).
2. The polyline ``[pos, pos + L v/|v|, path...]`` is smoothed with G2 (collision repair on
   the world when given) and time-parameterised with the current speed as its start speed.

The new trajectory starts exactly at ``pos`` with velocity exactly ``vel`` and zero along-track
acceleration; the position and velocity setpoints are continuous, the acceleration setpoint
changes by at most the current acceleration (bounded by the limits). When the lead-in is
blocked by an obstacle it is shortened (halving) and the result says so in ``notes``; from
(near) rest no lead-in is needed and the trajectory starts at rest.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from companion.errors import SmoothingError
from companion.smoothing.g2 import check_kappa, smooth_g2, spiral_distance_m
from companion.smoothing.polyline import clean_path
from companion.smoothing.settings import TrajectoryLimits
from companion.smoothing.timing import time_parameterize
from companion.trajectory import Trajectory

__all__ = ["join_from_state", "lead_in_length"]

logger = logging.getLogger(__name__)

_REST_M_S = 0.05


def _vector(value, name: str, d: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SmoothingError(f"{name}: expected {d} numbers") from None
    if arr.shape != (d,):
        raise SmoothingError(f"{name}: expected shape ({d},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SmoothingError(f"{name}: must be finite (no NaN or inf)")
    return arr


def lead_in_length(speed_m_s: float, turn_rad: float, kappa_max_1_m: float, limits: TrajectoryLimits,
                   max_corner_m: float = math.inf) -> float:
    """Length (m) of the straight lead-in before the first corner of a splice.

    Parameters
    ----------
    speed_m_s : float
        Current speed.
    turn_rad : float
        Heading change at the end of the lead-in.
    kappa_max_1_m : float
    limits : TrajectoryLimits
    max_corner_m : float
        Cap on the corner size (a sharp turn needs a corner larger than the distance to the
        target, which the smoother shrinks to fit anyway).

    Returns
    -------
    float
        Corner size d (eq. 19, capped) + braking distance to the corner speed + the speed
        hold v T / 2 + the filter reach v_max T, T = 2 a / j.
    """
    window = 2.0 * limits.accel_m_s2 / limits.jerk_m_s3
    v_corner_sq = limits.lat_accel_m_s2 / kappa_max_1_m
    braking = max(0.0, speed_m_s**2 - v_corner_sq) / (2.0 * limits.accel_m_s2)
    turn = min(float(turn_rad), math.pi - 1e-3)
    corner = min(float(spiral_distance_m(turn, kappa_max_1_m)), max_corner_m)
    return corner + braking + 0.5 * speed_m_s * window + limits.speed_m_s * window + 1.0


def _turn(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return 0.0
    return float(np.arccos(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0)))


def join_from_state(pos, vel, path, *, kappa_max_1_m: float = 0.1, limits: TrajectoryLimits | None = None,
                    world=None, acc=None, end_speed_m_s: float = 0.0, max_halvings: int = 6) -> Trajectory:
    """Trajectory from the current reference state onto ``path`` (G2, no setpoint jump).

    Parameters
    ----------
    pos : array_like, shape (d,)
        Current reference position (m), d = path dimension.
    vel : array_like, shape (d,)
        Current reference velocity (m/s). Above ``limits.speed_m_s`` the trajectory starts at
        the limit (a velocity step, reported in ``notes``).
    path : array_like, shape (M, d)
        The path to join, from its entry node (``path[0]``) to its end, M >= 1.
    kappa_max_1_m : float
        K_max of the G2 smoothing (1/m).
    limits : TrajectoryLimits, optional
    world : companion.world.World, optional
        Obstacles (with threats) for the lead-in check and the corner repair.
    acc : array_like, shape (d,), optional
        Current reference acceleration; only validated and used for the log (the new
        trajectory starts with zero along-track acceleration).
    end_speed_m_s : float
        Speed at the end of ``path`` (default 0: stop there).
    max_halvings : int
        How many times a blocked lead-in is halved before it is dropped.

    Returns
    -------
    Trajectory
        ``sample(0)`` gives ``(pos, vel, 0 along-track)``; ``notes`` and ``curve.notes`` say what
        could not be honoured.
    """
    limits = TrajectoryLimits() if limits is None else limits
    kappa = check_kappa(kappa_max_1_m)
    arr = np.asarray(path, dtype=float)
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] not in (2, 3):
        raise SmoothingError(f"path: expected shape (M, 2) or (M, 3) with M >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SmoothingError("path: must be finite (no NaN or inf)")
    d = arr.shape[1]
    p0 = _vector(pos, "pos", d)
    v0 = _vector(vel, "vel", d)
    if acc is not None:
        a0 = _vector(acc, "acc", d)
        logger.debug("join_from_state: dropping along-track acceleration %s", a0)
    speed = float(np.linalg.norm(v0))
    notes: list[str] = []
    if speed < _REST_M_S:
        nodes, _ = clean_path(np.vstack([p0, arr]), "path")
        curve = smooth_g2(nodes, kappa, world=world)
        return time_parameterize(curve, limits, end_speed_m_s=end_speed_m_s)
    heading = v0 / speed
    target = arr[0]
    reach = max(float(np.linalg.norm(target - p0)), 1.0)
    length = lead_in_length(speed, _turn(heading, target - p0), kappa, limits, reach)
    lead = p0 + length * heading
    for _ in range(3):           # the turn at the lead-in end depends on its length
        reach = max(float(np.linalg.norm(target - lead)), 1.0)
        length = lead_in_length(speed, _turn(heading, target - lead), kappa, limits, reach)
        lead = p0 + length * heading
    if world is not None:
        for _ in range(max_halvings):
            if world.segment_free(p0, lead) and world.segment_free(lead, target):
                break
            length *= 0.5
            lead = p0 + length * heading
        else:
            if not (world.segment_free(p0, lead) and world.segment_free(lead, target)):
                notes.append(f"lead-in along the current velocity is blocked down to {length:.2f} m; "
                             f"kept it anyway to stay continuous (check the world)")
    nodes, _ = clean_path(np.vstack([p0, lead, arr]), "path")
    curve = smooth_g2(nodes, kappa, world=world)
    traj = time_parameterize(curve, limits, start_speed_m_s=speed, end_speed_m_s=end_speed_m_s)
    traj.notes = notes + traj.notes
    for note in notes:
        logger.warning("join_from_state: %s", note)
    return traj
