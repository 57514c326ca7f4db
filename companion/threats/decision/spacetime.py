"""Check: one pure space-time test of time-parameterised candidates (DESIGN 7.2).

A candidate is sampled at clock times ``t_k`` (K,). Between two samples both the vehicle (its
chord) and every threat (exactly: constant velocity) move linearly, so their relative position
is linear and its closest approach over the interval has a closed form:

    r(s) = r_k + s (r_{k+1} - r_k),   s* = clip(-r_k . dr / |dr|^2, 0, 1),   d = |r(s*)|.

The vehicle's curve leaves its chord by at most ``a_max dt^2 / 8`` (``accel_bound_m_s2``), and a
tube's radius is taken at its larger end, so the check never reports "clear" where the exact
closest approach intrudes, whatever the step (the step only costs conservatism). The static
world (obstacles inflated by their margin, and the bounds) is a 1-Lipschitz distance field:
over a piece of length L between points of clearance c_a and c_b it stays above
``(c_a + c_b - L) / 2`` (each chord is cut into ``STATIC_SUBSTEPS`` pieces); candidates may use ``static_slack_m`` of the safety margin (never more
than half of it).

A manned aircraft's tube is the well-clear cylinder (``prediction``), whose clearance
``max(h - r, scale (v - half_height))`` has no closed form on an interval. It is 1-Lipschitz in
the norm ``|(dh, scale dv)|``, so over an interval whose relative chord has that length L it stays
above ``(c_a + c_b - L) / 2`` (as the static world's); the vehicle's chord error counts ``scale``
times.

Clearance is positive outside every inflated tube and obstacle. Candidates that intrude are
ranked by the intrusion integral ``sum(max(0, -c)^2 dt)`` (deep intrusions weigh most), which
also rewards getting out fast when a pop-up appears around the vehicle.

Pure: numpy only. Every strategy, the monitor and the benchmark use ``check_candidates``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Conflict",
    "BatchCheck",
    "check_candidates",
    "segment_min_distance",
    "sample_times",
    "STATIC_ID",
    "interval_clearance",
]

#: ``Conflict.threat_id`` of a conflict with the static world (obstacle or bounds).
STATIC_ID = "static"


@dataclass(frozen=True)
class Conflict:
    """The first predicted intrusion of a candidate into a tube or the static world.

    Attributes
    ----------
    threat_id : str
        The threat's id, or ``STATIC_ID``.
    t_s : float
        Clock time of the start of the first interval in conflict (s).
    time_to_conflict_s : float
        ``t_s`` minus the first sample time.
    clearance_m : float
        Clearance on that interval (negative: depth of the intrusion, m).
    """

    threat_id: str
    t_s: float
    time_to_conflict_s: float
    clearance_m: float


@dataclass(frozen=True)
class BatchCheck:
    """Result of ``check_candidates`` for C candidates.

    Attributes
    ----------
    clear : ndarray of bool, shape (C,)
    min_clearance_m : ndarray, shape (C,)
        Smallest clearance over the horizon (inf when nothing is near).
    intrusion_m2s : ndarray, shape (C,)
        ``sum(max(0, -clearance)^2 * dt)`` over the intervals (0 when clear).
    conflicts : list of (Conflict or None), length C
    static_clearance_m : ndarray, shape (C,)
        Smallest clearance from the static world alone (inf when not checked): negative means
        the candidate goes deeper into the safety margin than allowed.
    """

    clear: np.ndarray
    min_clearance_m: np.ndarray
    intrusion_m2s: np.ndarray
    conflicts: list
    static_clearance_m: np.ndarray


def reference_accel_bound_m_s2(settings, limits) -> float:
    """Bound (m/s^2) on any reference's acceleration, for the chord error: 1.5 times the largest
    of the planned limits (``limits``: ``accel_m_s2``, ``lat_accel_m_s2``) and the escapes' and
    holds' (``settings``: ``evade_accel_m_s2``, ``hold_decel_m_s2``)."""
    return max(limits.accel_m_s2, limits.lat_accel_m_s2, settings.evade_accel_m_s2, settings.hold_decel_m_s2) * 1.5


def sample_times(t_from_s: float, horizon_s: float, step_s: float) -> np.ndarray:
    """Check times (K,) from ``t_from_s`` over ``horizon_s`` every ``step_s`` (last one included)."""
    n = max(2, int(math.ceil(horizon_s / step_s)) + 1)
    return t_from_s + np.linspace(0.0, horizon_s, n)


def segment_min_distance(r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
    """Smallest norm of ``r0 + s (r1 - r0)`` over s in [0, 1], row-wise: (..., d) -> (...)."""
    dr = r1 - r0
    dd = np.einsum("...i,...i->...", dr, dr)
    s = np.clip(-np.einsum("...i,...i->...", r0, dr) / np.maximum(dd, 1e-18), 0.0, 1.0)
    closest = r0 + s[..., None] * dr
    return np.sqrt(np.einsum("...i,...i->...", closest, closest))


def interval_clearance(rel: np.ndarray, reach_m: np.ndarray, tube) -> np.ndarray:
    """Clearance (..., K-1) of every interval of relative positions ``rel`` (..., K, d) from the
    tube's volume, whose radius on each interval is ``reach_m`` (K-1,): exact for a ball, a
    lower bound for a manned aircraft's cylinder (module docstring; in 2D both are columns)."""
    if not math.isfinite(tube.half_height_m) or rel.shape[-1] != 3:
        return segment_min_distance(rel[..., :-1, :], rel[..., 1:, :]) - reach_m
    scale = tube.vertical_scale
    h = np.linalg.norm(rel[..., :2], axis=-1)
    v = scale * (np.abs(rel[..., 2]) - tube.half_height_m)
    ends = np.maximum(h[..., :-1] - reach_m, v[..., :-1]), np.maximum(h[..., 1:] - reach_m, v[..., 1:])
    step = np.diff(rel, axis=-2) * np.array([1.0, 1.0, scale])
    return 0.5 * (ends[0] + ends[1] - np.linalg.norm(step, axis=-1))


def chord_scale(tube, dim: int) -> float:
    """How many times the vehicle's chord error counts in the tube's clearance."""
    return max(tube.vertical_scale, 1.0) if dim == 3 else 1.0


def _tube_clearance(t_s, pos, tube, dim: int, chord_err: np.ndarray) -> np.ndarray:
    """Clearance (C, K-1) of every interval from one tube, less the part of the chord error
    (K-1,) that a manned aircraft's scale adds (the caller takes the chord error itself off
    every clearance)."""
    rel = pos[:, :, :dim] - tube.center_at(t_s)[None, :, :dim]
    radius = tube.radius_at(t_s)
    clearance = interval_clearance(rel, np.maximum(radius[:-1], radius[1:])[None, :], tube)
    return clearance - (chord_scale(tube, dim) - 1.0) * chord_err[None, :]


#: Pieces a chord near the static world is cut into, and what "near" is (m).
STATIC_SUBSTEPS = 4
STATIC_REFINE_M = 1.0
#: Static clearances beyond this (m) are reported as a lower bound only (from bounding boxes).
STATIC_REACH_M = 6.0


def _obstacle_clearance(flat: np.ndarray, world) -> np.ndarray:
    """Clearance (K,) from the inflated obstacles: exact within ``STATIC_REACH_M`` of an
    obstacle's bounding box, a lower bound (the box distance) farther away."""
    dim = world.dim
    margin = world.margin_m
    boxes = [ob.aabb(dim) for ob in world.obstacles]
    lo = np.array([b[0][:dim] for b in boxes], dtype=float)  # (M, d)
    hi = np.array([b[1][:dim] for b in boxes], dtype=float)
    gap = np.maximum(np.maximum(lo[None] - flat[:, None], flat[:, None] - hi[None]), 0.0)
    box = np.sqrt(np.einsum("kmi,kmi->km", gap, gap)) - margin  # (K, M)
    near = box < STATIC_REACH_M
    for m in np.flatnonzero(near.any(axis=0)):
        rows = near[:, m]
        box[rows, m] = world.obstacles[m].sdf_batch(flat[rows]) - margin
    return box.min(axis=1)


def _point_clearance(flat: np.ndarray, world, slack_m: float) -> np.ndarray:
    """Static clearance (K,) of points: the bounds (hard) and the inflated obstacles, into
    whose margin ``slack_m`` may be used."""
    point = np.minimum(flat - world.bounds_min[None, :], world.bounds_max[None, :] - flat).min(axis=1)
    if world.obstacles:
        point = np.minimum(point, _obstacle_clearance(flat, world) + slack_m)
    return point


def _static_clearance(pos, world, slack_m: float, substeps: int = STATIC_SUBSTEPS) -> np.ndarray:
    """Lower bound (C, K-1) of the static world's clearance on every chord. Chords whose bound
    is below ``STATIC_REFINE_M`` are cut into ``substeps`` pieces (the Lipschitz bound then
    costs only a piece's half-length)."""
    c_n, k_n, d = pos.shape
    point = _point_clearance(pos.reshape(-1, d), world, slack_m).reshape(c_n, k_n)
    step = np.diff(pos, axis=1)
    chord = np.linalg.norm(step, axis=2)
    bound = 0.5 * (point[:, :-1] + point[:, 1:] - chord)
    near = bound < STATIC_REFINE_M
    if near.any():
        f = np.arange(substeps + 1)[:, None] / substeps  # (n+1, 1)
        fine = pos[:, :-1][near][:, None, :] + f[None] * step[near][:, None, :]
        fine_point = _point_clearance(fine.reshape(-1, d), world, slack_m).reshape(-1, substeps + 1)
        piece = chord[near][:, None] / substeps
        bound[near] = (0.5 * (fine_point[:, :-1] + fine_point[:, 1:] - piece)).min(axis=1)
    return bound


def check_candidates(
    t_s, pos_ned_m, tubes, world=None, *, accel_bound_m_s2: float = 3.0, static_slack_m: float = 0.0
) -> BatchCheck:
    """Check C candidates sampled at common times against every tube and the static world.

    Parameters
    ----------
    t_s : array_like, shape (K,)
        Increasing clock times (s), K >= 2.
    pos_ned_m : array_like, shape (C, K, d) or (K, d)
        Candidate positions at ``t_s``; d is the world's dimension (2: north-east, the tubes are
        then infinite columns; 3: NED).
    tubes : sequence of Tube
    world : World, optional
        Static obstacles and bounds (dimension d).
    accel_bound_m_s2 : float
        Upper bound of the candidates' acceleration, for the chord error ``a dt^2 / 8``.
    static_slack_m : float
        How far into the obstacles' safety margin a candidate may go (m; capped at half the
        margin, so never into an obstacle itself; the bounds are hard). Planned references keep the whole margin, which the
        chord bound can otherwise mistake for a conflict when a path grazes it.

    Returns
    -------
    BatchCheck
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    pos = np.asarray(pos_ned_m, dtype=float)
    if pos.ndim == 2:
        pos = pos[None]
    c_n, k_n, dim = pos.shape
    dt = np.diff(t)
    chord_err = accel_bound_m_s2 * dt * dt / 8.0
    clearance = np.full((c_n, k_n - 1), np.inf)
    source = np.full((c_n, k_n - 1), -1)
    sources = [tube.threat_id for tube in tubes] + [STATIC_ID]
    for i, tube in enumerate(tubes):
        c = _tube_clearance(t, pos, tube, dim, chord_err)
        closer = c < clearance
        clearance = np.where(closer, c, clearance)
        source = np.where(closer, i, source)
    static = np.full(c_n, np.inf)
    if world is not None:
        c = _static_clearance(pos, world, min(static_slack_m, 0.5 * world.margin_m))
        static = c.min(axis=1) - chord_err.max()
        closer = c < clearance
        clearance = np.where(closer, c, clearance)
        source = np.where(closer, len(tubes), source)
    clearance = clearance - chord_err[None, :]
    bad = clearance < 0.0
    clear = ~bad.any(axis=1)
    intrusion = (np.square(np.minimum(clearance, 0.0)) * dt[None, :]).sum(axis=1)
    first = np.argmax(bad, axis=1)  # first bad interval
    first_clearance = clearance[np.arange(c_n), first]
    first_source = source[np.arange(c_n), first]
    conflicts = [
        None if ok else Conflict(sources[first_source[c]], float(t[k]), float(t[k] - t[0]), float(first_clearance[c]))
        for c, (ok, k) in enumerate(zip(clear.tolist(), first.tolist()))
    ]
    return BatchCheck(clear, clearance.min(axis=1), intrusion, conflicts, static)
