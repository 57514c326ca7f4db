"""Join: a trajectory from the current reference state onto a path, without a setpoint jump.

The one splice of the project (paper section 3.3: switching to a pre-planned path; DESIGN 7.4:
"spliced from the current setpoint without a jump"). The polyline is [current position, lead
point, nodes...]: the lead leaves along the current velocity, long enough to keep the current
speed for half the jerk window and fit the first corner of the pipeline's smoother (a G2
corner: eq. 19) and, when the current speed is above the corner speed sqrt(a_lat / K_max)
(zero for the polyline of ``smoothing.method = "none"``), to slow down to it. The polyline is
an input to the trajectory pipeline (``companion.flight.pipeline``): smoothed by its smoother
(repaired against the world when one is given), timed from the current speed (checked) to rest
at the last node, and checked. Used by switches, replans and the plan back to the mission after
an evasion.

Pure: no I/O.
"""

from __future__ import annotations

import math

import numpy as np

from companion.flight.pipeline import TrajectoryPipeline
from companion.smoothing import TrajectoryLimits
from companion.smoothing.g2 import spiral_distance_m
from companion.world import World

__all__ = ["join_trajectory", "lead_length_m", "entry_index", "turn_rad", "HOVER_SPEED_M_S"]

#: Smallest speed (m/s) with a meaningful direction; below it the vehicle counts as hovering.
HOVER_SPEED_M_S = 0.05
#: Leads tried by a join: the first from ``lead_length_m``, then shorter when blocked or
#: longer when the profile cannot start at the current speed.
JOIN_ATTEMPTS = 4


def lead_length_m(speed_m_s: float, turn_rad: float, limits: TrajectoryLimits, kappa_max_1_m: float) -> float:
    """Straight lead along the current velocity before the first corner of a join (m).

    ``kappa_max_1_m``: the curvature of the smoother's corners (``TrajectoryPipeline.turn_kappa_1_m``;
    inf for a polyline, which stops at its corners). Long enough to keep the current speed for half the jerk window (the profile's start) and fit
    the corner's spirals (eq. 19); when the current speed is above the speed the corner allows
    (K_max at the lateral acceleration limit), also to slow down to it outside the window over
    which the profile spreads a corner's speed limit (``speed_m_s * window``).
    """
    if speed_m_s < HOVER_SPEED_M_S:
        return 0.0
    window_s = 2.0 * limits.accel_m_s2 / limits.jerk_m_s3
    v_turn = min(speed_m_s, math.sqrt(limits.lat_accel_m_s2 / kappa_max_1_m))
    turn = min(abs(turn_rad), 0.95 * math.pi)
    if turn < 1e-3:
        return speed_m_s * window_s / 2.0 + 0.5
    corner_m = float(spiral_distance_m(turn, kappa_max_1_m))
    if speed_m_s <= v_turn:
        return speed_m_s * window_s / 2.0 + corner_m + 0.5
    slow_m = (speed_m_s**2 - v_turn**2) / (2.0 * limits.accel_m_s2)
    return speed_m_s * window_s / 2.0 + limits.speed_m_s * window_s + slow_m + corner_m + 0.5


def turn_rad(u: np.ndarray, w: np.ndarray) -> float:
    nu, nw = np.linalg.norm(u), np.linalg.norm(w)
    if nu < 1e-9 or nw < 1e-9:
        return 0.0
    return float(math.acos(max(-1.0, min(1.0, float(np.dot(u, w) / (nu * nw))))))


def _clean_nodes(nodes: np.ndarray, tol_m: float = 0.05, tol_rad: float = 1e-6) -> np.ndarray:
    """Drop repeated nodes (within ``tol_m`` of the last one kept) and nodes in the middle of a
    straight line (turning less than ``tol_rad``). Vectorised: an alternative's entries, every
    ``entry_spacing_m`` along it, come here by the hundred."""
    keep = _deduplicated(nodes, tol_m)
    if keep.shape[0] < 3:
        return keep
    seg = np.diff(keep, axis=0)
    corners = np.flatnonzero(_angles_rad(seg[:-1], seg[1:]) > tol_rad) + 1
    return np.vstack([keep[:1], keep[corners], keep[-1:]])


def _deduplicated(nodes: np.ndarray, tol_m: float) -> np.ndarray:
    """``nodes`` without those within ``tol_m`` of the last node kept."""
    if nodes.shape[0] < 2 or np.all(np.linalg.norm(np.diff(nodes, axis=0), axis=1) > tol_m):
        return nodes
    keep = [nodes[0]]
    for p in nodes[1:]:
        if np.linalg.norm(p - keep[-1]) > tol_m:
            keep.append(p)
    return np.asarray(keep)


def join_trajectory(
    pos_ned_m,
    vel_ned_m_s,
    nodes,
    *,
    world: World | None,
    pipeline: TrajectoryPipeline,
    lift_down_m: float | None = None,
    lead_m: float | None = None,
):
    """A trajectory from the reference state through ``nodes`` without a setpoint jump.

    The polyline is [current position, lead point, nodes...]: the lead leaves along the current
    velocity; ``pipeline`` smooths the corners (with collision repair when ``world`` is given),
    times the profile from the current speed (checked) to rest at the last node, and checks it.

    Parameters
    ----------
    pos_ned_m, vel_ned_m_s : array_like, shape (d,)
        The current reference state (the planning dimension).
    nodes : array_like, shape (M, d)
        Where to go (the first is the entry node; the last the goal).
    world : World or None
        Static obstacles: every segment must be free; corners are repaired.
    pipeline : TrajectoryPipeline
        Smoother, limits, timer and checker of the join.
    lift_down_m : float, optional
        Lift a 2D result to NED at this down coordinate.
    lead_m : float, optional
        Fixed lead length (the nodes are then used as given, e.g. a path planned from the
        lead point; the caller has checked the lead segment). Default: ``lead_length_m`` for the turn to the first node, entry nodes too
        close to the lead point skipped (``entry_index``), up to ``JOIN_ATTEMPTS`` leads (1.5
        times longer each when the profile cannot start at the current speed).

    Returns
    -------
    (Trajectory, polyline (K, d)) or (None, reason str)
    """
    p0 = np.asarray(pos_ned_m, dtype=float)
    v0 = np.asarray(vel_ned_m_s, dtype=float)
    nodes = np.atleast_2d(np.asarray(nodes, dtype=float))
    limits, kappa = pipeline.limits, pipeline.turn_kappa_1_m
    speed = min(float(np.linalg.norm(v0)), limits.speed_m_s)
    if speed < HOVER_SPEED_M_S:
        return _timed_join(
            np.vstack([p0[None, :], nodes]), 0.0, world=world, pipeline=pipeline, lift_down_m=lift_down_m
        )
    u = v0 / np.linalg.norm(v0)
    fixed = lead_m is not None
    lead = float(lead_m) if fixed else lead_length_m(speed, turn_rad(u, nodes[0] - p0), limits, kappa)
    reason = "no join"
    attempts = 1 if fixed else JOIN_ATTEMPTS
    for attempt in range(attempts):
        p_lead = p0 + u * lead
        k = 0 if fixed else entry_index(p_lead, u, nodes, kappa)
        if k is None:
            return None, "no node far enough beyond the stopping distance"
        traj, poly = _timed_join(
            np.vstack([p0, p_lead, nodes[k:]]),
            speed,
            world=world,
            pipeline=pipeline,
            lift_down_m=lift_down_m,
            first_checked=1 if fixed else 0,
        )
        if traj is None:
            if fixed or attempt == attempts - 1:
                return traj, poly
            lead *= 0.6  # blocked: a shorter lead with a gentler first corner may fit
            reason = poly
            continue
        start_speed = float(np.linalg.norm(traj.sample(np.array([0.0]))[1][0]))
        if abs(start_speed - speed) <= 0.02 * speed + 0.05:
            return traj, poly
        reason = f"the join cannot start at {speed:.2f} m/s (only {start_speed:.2f})"
        lead *= 1.5
    return None, reason


def _angles_rad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    cos = np.einsum("...i,...i->...", a, b) / np.maximum(na * nb, 1e-12)
    return np.where((na > 1e-9) & (nb > 1e-9), np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)


def entry_index(p_lead: np.ndarray, u: np.ndarray, nodes: np.ndarray, kappa_max_1_m: float) -> int | None:
    """First node ahead of the lead point with room for the two G2 corners around it.

    The corner at the lead point (turning from ``u`` towards the node) and the corner at the
    node (turning onto the path) each need their spiral distance (eq. 19, for the smoother's
    corner curvature ``kappa_max_1_m``; none for a polyline) on the segment between them; nodes
    closer than that are skipped.

    Returns
    -------
    int or None
    """
    rel = nodes - p_lead[None, :]
    dist = np.linalg.norm(rel, axis=1)
    turn1 = np.minimum(_angles_rad(np.broadcast_to(u, rel.shape), rel), 0.95 * np.pi)
    nxt = np.vstack([np.diff(nodes, axis=0), np.zeros((1, nodes.shape[1]))])
    turn2 = np.minimum(_angles_rad(rel, nxt), 0.95 * np.pi)
    need = spiral_distance_m(turn1, kappa_max_1_m) + spiral_distance_m(turn2, kappa_max_1_m) + 0.5
    ok = np.flatnonzero((rel @ u > 1e-6) & (dist >= need))
    return int(ok[0]) if ok.size else None


def _timed_join(
    points: np.ndarray, speed_m_s: float, *, world, pipeline: TrajectoryPipeline, lift_down_m, first_checked: int = 0
):
    """The cleaned polyline through the pipeline: (Trajectory, polyline) or (None, reason)."""
    poly = _clean_nodes(points)
    if poly.shape[0] < 2:
        return None, "nothing to fly"
    if world is not None:
        for a, b in zip(poly[first_checked:-1], poly[first_checked + 1 :]):
            if not world.segment_free(a, b):
                return None, "the join crosses a static obstacle"
    checked = pipeline.trajectory(poly, world, start_speed_m_s=speed_m_s)
    if not checked.status.flyable:
        return None, f"the join is {checked.status.value}: {checked.reason}"
    traj = checked.trajectory
    if lift_down_m is not None:
        traj = traj.to_ned(lift_down_m)
    return traj, poly
