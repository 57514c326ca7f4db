"""Collision re-check of smoothed corners and their repair (paper section 3.2, made safe).

Smoothing cuts corners: a G1 or G2 corner curve lies inside the triangle formed by its two
end points and the polyline's corner node (convex-hull property of Bezier curves), so it can
touch an obstacle that the polyline avoids. Each corner curve is *certified* free with the
world's signed clearance c(p) (distance to the nearest inflated obstacle, 1-Lipschitz):
between two samples at most D metres of arc apart, every point is free when
c_a + c_b > D. The arc-length bound D is the parameter step times the largest hodograph
control point (|B'(u)| never exceeds it). Intervals that cannot be certified are split, down
to a resolution of 1 mm; a sample with c <= 0 or an interval still uncertain at that
resolution makes the corner *clipping* (conservative).

A clipping corner is shrunk towards its node (halving its size) and re-checked; as the size
goes to zero the curve tends to the polyline corner, which is free when the polyline is. If it
still clips after the allowed halvings, the polyline's own corner is kept and the trajectory
stops there. So the smoothed path is never less safe than the polyline.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from companion.smoothing.bezier_maths import bernstein

__all__ = ["corners_clear", "repair_corners"]

logger = logging.getLogger(__name__)

_INITIAL_INTERVALS = 16
_RESOLUTION_M = 1e-3
_MAX_ROUNDS = 24
_MAX_SAMPLES = 200_000


def corners_clear(world, curves: np.ndarray) -> np.ndarray:
    """Certify corner curves free of the world's inflated obstacles.

    Parameters
    ----------
    world : companion.world.World
        Needs ``clearance_m(points (K, d)) -> (K,)`` (signed distance to the inflated
        obstacles) and ``contains(points) -> bool (K,)``.
    curves : ndarray, shape (G, m, N+1, d)
        For every corner, the m Bezier pieces (degree N) of its curve.

    Returns
    -------
    ndarray of bool, shape (G,)
        True where every point of the corner's curve is certified free.
    """
    curves = np.asarray(curves, dtype=float)
    n_groups, m = curves.shape[:2]
    ok = np.ones(n_groups, dtype=bool)
    if n_groups == 0:
        return ok
    degree = curves.shape[2] - 1
    ctrl = curves.reshape(n_groups * m, degree + 1, curves.shape[3])  # (P, N+1, d)
    group_of = np.repeat(np.arange(n_groups), m)
    hod = degree * np.diff(ctrl, axis=1)
    speed_bound = np.max(np.linalg.norm(hod, axis=2), axis=1)  # (P,)

    def points(piece: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.einsum("kn,knd->kd", bernstein(degree, u), ctrl[piece])

    def clearance(pts: np.ndarray) -> np.ndarray:
        c = np.asarray(world.clearance_m(pts), dtype=float)
        inside = np.asarray(world.contains(pts), dtype=bool)
        return np.where(inside, c, -1.0)

    n_pieces = ctrl.shape[0]
    u_edges = np.linspace(0.0, 1.0, _INITIAL_INTERVALS + 1)
    piece = np.repeat(np.arange(n_pieces), _INITIAL_INTERVALS)
    u_lo = np.tile(u_edges[:-1], n_pieces)
    u_hi = np.tile(u_edges[1:], n_pieces)
    c_all = (bernstein(degree, u_edges)[None] @ ctrl).reshape(-1, ctrl.shape[2])
    c_all = clearance(c_all).reshape(n_pieces, -1)
    c_lo = c_all[:, :-1].ravel()
    c_hi = c_all[:, 1:].ravel()
    samples = c_all.size
    for _ in range(_MAX_ROUNDS):
        bad_sample = (c_lo <= 0.0) | (c_hi <= 0.0)
        ok[np.unique(group_of[piece[bad_sample]])] = False
        reach = (u_hi - u_lo) * speed_bound[piece]
        uncertain = ~bad_sample & (c_lo + c_hi <= reach) & ok[group_of[piece]]
        if not np.any(uncertain):
            return ok
        too_fine = uncertain & (reach < _RESOLUTION_M)
        ok[np.unique(group_of[piece[too_fine]])] = False
        uncertain &= ~too_fine & ok[group_of[piece]]
        if samples > _MAX_SAMPLES:
            ok[np.unique(group_of[piece[uncertain]])] = False
            return ok
        piece, u_lo, u_hi, c_lo, c_hi = (a[uncertain] for a in (piece, u_lo, u_hi, c_lo, c_hi))
        u_mid = 0.5 * (u_lo + u_hi)
        c_mid = clearance(points(piece, u_mid))
        samples += u_mid.size
        piece = np.concatenate([piece, piece])
        u_lo, u_hi = np.concatenate([u_lo, u_mid]), np.concatenate([u_mid, u_hi])
        c_lo, c_hi = np.concatenate([c_lo, c_mid]), np.concatenate([c_mid, c_hi])
    remaining = c_lo + c_hi <= (u_hi - u_lo) * speed_bound[piece]
    ok[np.unique(group_of[piece[remaining]])] = False
    return ok


def repair_corners(
    world, build: Callable[[np.ndarray, np.ndarray], np.ndarray], corner_ids: np.ndarray, max_halvings: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shrink clipping corners (halving their size) until they are certified free.

    Parameters
    ----------
    world : companion.world.World
    build : callable (ids (K,), scales (K,)) -> ndarray, shape (K, m, N+1, d)
        Builds corners' curves at a fraction in (0, 1] of their nominal size.
    corner_ids : ndarray of int, shape (C,)
        Corners to check.
    max_halvings : int
        How many times a corner may be halved before it is given up.

    Returns
    -------
    curves : ndarray, shape (C, m, N+1, d)
        The final curve of every corner (meaningless where ``sharp``).
    scales : ndarray, shape (C,)
        The final scale of every corner (1 where nothing changed).
    sharp : ndarray of bool, shape (C,)
        Corners still clipping at the smallest size: the caller keeps the polyline corner.
    """
    ids = np.asarray(corner_ids, dtype=int)
    scales = np.ones(ids.size)
    curves = build(ids, scales)
    sharp = np.zeros(ids.size, dtype=bool)
    pending = np.arange(ids.size)
    for halving in range(max_halvings + 1):
        if pending.size == 0:
            break
        ok = corners_clear(world, curves[pending])
        failing = pending[~ok]
        if halving == max_halvings:
            sharp[failing] = True
            break
        scales[failing] *= 0.5
        if failing.size:
            curves[failing] = build(ids[failing], scales[failing])
        pending = failing
    if np.any(sharp):
        logger.info("corners %s still clip at 1/%d of their size: kept sharp", ids[sharp].tolist(), 2**max_halvings)
    return curves, scales, sharp
