"""Emergency threat manager: replan when there is time, switch when there is not, else hold.

Paper section 3.3 (Fig. 5: switching to a pre-planned M-GART path inside the switching range;
Fig. 8: a moving obstacle met at close range) made precise by DESIGN section 7:

1. ``predict``: threats move at constant velocity (``Threat.position_at``); each is inflated by
   ``inflation_m``.
2. ``first_conflict``: the remaining reference (the active trajectory, then a hover at its end)
   is checked in space *and time* against the predicted threats over ``horizon_s``.
3. ``decide``: time to the first conflict > replanning estimate + margin -> ``replan``: GART
   from the current reference state on ``world.with_threats(...)`` (a moving threat is replaced
   by the volume it sweeps), G2 smoothing, speed profile starting at the current speed.
   Otherwise ``switch``: among the M-GART alternatives, the entry node within ``switch_range_m``
   with the lowest remaining cost whose spliced trajectory stays clear of the predicted threats.
   A replan that fails falls back to a switch; when nothing is safe -> ``hold`` (brake to a
   hover along the current path, ``BrakeAlongPath``), and the next call replans from the hold.
4. ``join``: every new trajectory leaves the current reference position along the current
   velocity at the current speed (a straight lead long enough to slow down for the first
   corner), so neither the position nor the velocity setpoint jumps.

The measured replanning time feeds a running estimate (mean + 3 mean absolute deviations),
which is the replanning budget of step 3.

Pure: no asyncio, no zenoh, no clock of its own (times are arguments; the wall clock only
measures the decision's own duration). The daemon calls ``on_threats`` from a worker thread.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from companion.errors import CompanionError
from companion.planning import GartSettings, MgartSettings, gart, mgart
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.smoothing.g2 import spiral_distance_m
from companion.threats.model import Threat
from companion.threats.settings import ThreatSettings
from companion.world import Sphere, World

__all__ = ["ThreatManager", "Decision", "Conflict", "Alternative", "ReferenceState",
           "first_conflict", "min_separation_m", "lead_length_m", "entry_index", "threat_obstacles", "join_trajectory", "BrakeAlongPath",
           "ThreatManagerError"]

log = logging.getLogger(__name__)

#: Smallest speed (m/s) with a meaningful direction; below it the vehicle counts as hovering.
HOVER_SPEED_M_S = 0.05
#: Leads tried by a join: the first from ``lead_length_m``, then shorter when blocked or
#: longer when the profile cannot start at the current speed.
JOIN_ATTEMPTS = 4


class ThreatManagerError(CompanionError, ValueError):
    """Bad arguments to the threat manager (naming them)."""


@dataclass(frozen=True)
class ReferenceState:
    """The reference (setpoint) at time ``t_s``: where a new trajectory must start.

    Attributes
    ----------
    t_s : float
        Time on the manager's clock (s).
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : ndarray, shape (d,)
    """

    t_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    acc_ned_m_s2: np.ndarray


@dataclass(frozen=True)
class Conflict:
    """The first predicted intrusion of the reference into an inflated threat.

    Attributes
    ----------
    threat_id : str
    t_s : float
        Time of the first sample in conflict (manager clock, s).
    time_to_conflict_s : float
        ``t_s`` minus the time of the check.
    distance_m : float
        Distance between the reference and the threat centre then (horizontal in 2D).
    limit_m : float
        Inflated radius of the threat.
    """

    threat_id: str
    t_s: float
    time_to_conflict_s: float
    distance_m: float
    limit_m: float


@dataclass(frozen=True)
class Alternative:
    """One pre-planned M-GART path to the goal, a switching target.

    Any point of the path is a possible entry node: the path is sampled every ``spacing_m``
    (the *entries*); a switch flies to an entry, then on along the path's own nodes.

    Attributes
    ----------
    path_id : str
    path_ned_m : ndarray, shape (M, d)
        The path's nodes (as planned: its corners fit the G2 smoothing).
    entry_pos_ned_m : ndarray, shape (E, d)
        Entry points along the path.
    entry_next : ndarray of int, shape (E,)
        Index of the path node that follows each entry.
    entry_remaining_m : ndarray, shape (E,)
        Length of the path from each entry to its end (the entry's remaining cost).
    """

    path_id: str
    path_ned_m: np.ndarray
    entry_pos_ned_m: np.ndarray
    entry_next: np.ndarray
    entry_remaining_m: np.ndarray

    @classmethod
    def from_path(cls, path_id: str, path_ned_m, spacing_m: float = 2.0) -> "Alternative":
        """Build from a polyline (M, d), M >= 2, with entries at most ``spacing_m`` apart."""
        path = np.asarray(path_ned_m, dtype=float)
        if path.ndim != 2 or path.shape[0] < 2 or path.shape[1] not in (2, 3) \
                or not np.all(np.isfinite(path)):
            raise ThreatManagerError(f"alternative {path_id!r}: path_ned_m must be a finite (M, 2|3) "
                                     f"array with M >= 2, got shape {path.shape}")
        if not (math.isfinite(spacing_m) and spacing_m > 0):
            raise ThreatManagerError(f"spacing_m: must be a finite number > 0, got {spacing_m!r}")
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        tail = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])     # from node i to the end
        pos, nxt, rem = [], [], []
        for i, (a, b) in enumerate(zip(path[:-1], path[1:])):
            n = max(1, int(math.ceil(seg[i] / spacing_m)))
            f = np.arange(0, n)[:, None] / n
            pos.append(a[None, :] + f * (b - a)[None, :])
            nxt.append(np.full(n, i + 1))
            rem.append(tail[i + 1] + (1.0 - f[:, 0]) * seg[i])
        return cls(str(path_id), path, np.vstack(pos), np.concatenate(nxt), np.concatenate(rem))

    def nodes_from(self, entry: int) -> np.ndarray:
        """The polyline (K, d) flown after switching at ``entry``: the entries from it on, the last
        node (collinear points are dropped before smoothing, so the corners keep their room)."""
        return np.vstack([self.entry_pos_ned_m[entry:], self.path_ned_m[-1:]])


@dataclass(frozen=True)
class Decision:
    """What the manager decided on a threat update.

    Attributes
    ----------
    kind : str
        ``none`` (no conflict), ``replan``, ``switch``, ``hold`` or ``rejected``.
    reason : str
        Why, in words (logged and published in the ``events`` message).
    trajectory : Trajectory or None
        The new reference for ``replan``, ``switch`` and ``hold``: engage it so that its time 0
        is ``start_t_s`` on the manager's clock (the reference state it was built from), which
        keeps the setpoint continuous whatever the decision latency.
    start_t_s : float or None
    path_id : str or None
        ``replan-<n>``, the alternative's id, or ``hold-<n>``.
    path_ned_m : ndarray (M, d) or None
        The polyline of the new reference (for ``uav/<sysid>/path``).
    conflict : Conflict or None
        The conflict that triggered the decision.
    decide_ms : float
        Wall-clock duration of the whole decision (ms).
    plan_ms : float
        Part of it spent planning, smoothing and timing the new trajectory (ms).
    resume : bool
        True after a ``hold``: call ``on_threats`` (or ``resume``) again to replan from the hold.
    """

    kind: str
    reason: str
    trajectory: object = None
    start_t_s: float | None = None
    path_id: str | None = None
    path_ned_m: np.ndarray | None = None
    conflict: Conflict | None = None
    decide_ms: float = 0.0
    plan_ms: float = 0.0
    resume: bool = False

    def as_event(self) -> dict:
        """The ``uav/<sysid>/events`` message of this decision (without the transport latency)."""
        out = {"event": self.kind, "reason": self.reason, "path_id": self.path_id,
               "decide_ms": round(self.decide_ms, 3), "plan_ms": round(self.plan_ms, 3)}
        if self.conflict is not None:
            out["threat_id"] = self.conflict.threat_id
            out["time_to_conflict_s"] = round(self.conflict.time_to_conflict_s, 3)
        return out


# ---------------------------------------------------------------------------- pure steps
def _positions(trajectory, t_rel_s: np.ndarray) -> np.ndarray:
    pos = trajectory.sample(t_rel_s)[0]
    return np.atleast_2d(pos)


def check_step_s(threats, step_s: float, inflation_m: float, vehicle_speed_m_s: float) -> float:
    """Time step of the conflict check: relative motion per step <= 1/4 of the smallest radius."""
    if not threats:
        return step_s
    r_min = min(t.radius_m for t in threats) + inflation_m
    v_rel = vehicle_speed_m_s + max(float(np.linalg.norm(t.velocity_ned_m_s)) for t in threats)
    return min(step_s, 0.25 * r_min / max(v_rel, 1e-3))


def first_conflict(trajectory, start_t_s: float, t_from_s: float, t_to_s: float, threats,
                   *, inflation_m: float, dim: int, step_s: float = 0.1,
                   speed_bound_m_s: float = 10.0, escape: bool = False) -> Conflict | None:
    """First time in [t_from_s, t_to_s] the reference enters an inflated, predicted threat.

    Parameters
    ----------
    trajectory : Trajectory-like
        ``sample(t) -> (pos (K, d'), vel, acc)``, ``duration_s``; after its end the vehicle
        hovers at the end position (sampling clips the time).
    start_t_s : float
        Clock time of the trajectory's t = 0.
    t_from_s, t_to_s : float
        Checked window (clock time, s).
    threats : sequence of Threat
        Local-frame threats with ``received_t_s`` on the same clock.
    inflation_m : float
        Added to every radius.
    dim : int
        2: horizontal distance only (a threat is the column above its footprint); 3: 3D.
    step_s : float
        Largest time step; refined by ``check_step_s``.
    speed_bound_m_s : float
        Upper bound of the reference speed (for the step refinement).
    escape : bool
        When the reference already lies within a threat's inflated radius at ``t_from_s`` (the
        vehicle braked into the margin), only getting closer than it is now (or than the bare
        radius) counts as a conflict, so that a way out can be found.

    Returns
    -------
    Conflict or None
    """
    if not threats or t_to_s <= t_from_s:
        return None
    dt = check_step_s(threats, step_s, inflation_m, speed_bound_m_s)
    t = np.arange(t_from_s, t_to_s + 0.5 * dt, dt)
    pos = _positions(trajectory, np.clip(t - start_t_s, 0.0, None))
    best: Conflict | None = None
    for threat in threats:
        centers = threat.position_at(t)
        diff = pos[:, :dim] - centers[:, :dim]
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        limit = threat.radius_m + inflation_m
        if escape and dist[0] < limit:
            limit = max(threat.radius_m, dist[0] - 0.05)
        hit = np.flatnonzero(dist < limit)
        if hit.size and (best is None or t[hit[0]] < best.t_s):
            k = hit[0]
            best = Conflict(threat.id, float(t[k]), float(t[k] - t_from_s), float(dist[k]), limit)
    return best


def min_separation_m(trajectory, start_t_s: float, t_from_s: float, t_to_s: float, threats,
                     *, dim: int, step_s: float = 0.05) -> float:
    """Smallest distance from the reference to any threat's *surface* (m) over the window."""
    if not threats:
        return math.inf
    t = np.arange(t_from_s, t_to_s + 0.5 * step_s, step_s)
    pos = _positions(trajectory, np.clip(t - start_t_s, 0.0, None))
    out = math.inf
    for threat in threats:
        diff = pos[:, :dim] - threat.position_at(t)[:, :dim]
        out = min(out, float(np.min(np.linalg.norm(diff, axis=1))) - threat.radius_m)
    return out


def threat_obstacles(threats, t_s: float, *, inflation_m: float, sweep_s: float, dim: int,
                     keep_free=()) -> list:
    """Static obstacles standing for the threats in a replan (spheres, discs in a 2D world).

    A static threat is one sphere of radius r + inflation at its position; a moving threat is a
    chain of such spheres along its predicted track over [t_s, t_s + sweep_s], spaced by half
    the radius (its swept volume). A sphere containing one of ``keep_free`` (the start, the
    goal: points the plan must be able to use) is left out: the space-time check of the
    resulting trajectory decides about it.

    Returns
    -------
    list of companion.world.Sphere
    """
    out = []
    keep = [np.asarray(p, dtype=float) for p in keep_free]
    for threat in threats:
        radius = threat.radius_m + inflation_m
        speed = float(np.linalg.norm(threat.velocity_ned_m_s))
        if speed * sweep_s > 1e-6:
            n = int(math.ceil(speed * sweep_s / (0.5 * radius))) + 1
            times = t_s + np.linspace(0.0, sweep_s, n)
        else:
            times = np.array([t_s])
        for c in threat.position_at(times):
            if any(np.linalg.norm(p[:dim] - c[:dim]) <= radius for p in keep):
                continue
            out.append(Sphere(tuple(float(x) for x in c), radius))
    return out


def lead_length_m(speed_m_s: float, turn_rad: float, limits: TrajectoryLimits,
                  kappa_max_1_m: float) -> float:
    """Straight lead along the current velocity before the first corner of a join (m).

    Long enough to keep the current speed for half the jerk window (the profile's start) and fit
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


def _turn_rad(u: np.ndarray, w: np.ndarray) -> float:
    nu, nw = np.linalg.norm(u), np.linalg.norm(w)
    if nu < 1e-9 or nw < 1e-9:
        return 0.0
    return float(math.acos(max(-1.0, min(1.0, float(np.dot(u, w) / (nu * nw))))))


def _clean_nodes(nodes: np.ndarray, tol_m: float = 0.05, tol_rad: float = 1e-6) -> np.ndarray:
    """Drop repeated nodes and nodes in the middle of a straight line."""
    keep = [nodes[0]]
    for p in nodes[1:]:
        if np.linalg.norm(p - keep[-1]) > tol_m:
            keep.append(p)
    out = [keep[0]]
    for i in range(1, len(keep) - 1):
        if _turn_rad(keep[i] - out[-1], keep[i + 1] - keep[i]) > tol_rad:
            out.append(keep[i])
    if len(keep) > 1:
        out.append(keep[-1])
    return np.asarray(out)


def join_trajectory(ref: ReferenceState, nodes, *, world: World | None, limits: TrajectoryLimits,
                    kappa_max_1_m: float, lift_down_m: float | None = None, lead_m: float | None = None):
    """A trajectory from the reference state through ``nodes`` without a setpoint jump.

    The polyline is [current position, lead point, nodes...]: the lead leaves along the current
    velocity, the corners are G2-smoothed (with collision repair when ``world`` is given) and
    the profile starts at the current speed (checked) and ends at rest at the last node.

    Parameters
    ----------
    ref : ReferenceState
        pos and vel of dimension d (the planning dimension).
    nodes : array_like, shape (M, d)
        Where to go (the first is the entry node; the last the goal).
    world : World or None
        Static obstacles: every segment must be free; corners are repaired.
    limits : TrajectoryLimits
    kappa_max_1_m : float
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
    p0 = np.asarray(ref.pos_ned_m, dtype=float)
    v0 = np.asarray(ref.vel_ned_m_s, dtype=float)
    nodes = np.atleast_2d(np.asarray(nodes, dtype=float))
    speed = min(float(np.linalg.norm(v0)), limits.speed_m_s)
    if speed < HOVER_SPEED_M_S:
        return _timed_join(np.vstack([p0[None, :], nodes]), 0.0, world=world, limits=limits,
                           kappa_max_1_m=kappa_max_1_m, lift_down_m=lift_down_m)
    u = v0 / np.linalg.norm(v0)
    fixed = lead_m is not None
    lead = float(lead_m) if fixed else lead_length_m(speed, _turn_rad(u, nodes[0] - p0), limits, kappa_max_1_m)
    reason = "no join"
    attempts = 1 if fixed else JOIN_ATTEMPTS
    for attempt in range(attempts):
        p_lead = p0 + u * lead
        k = 0 if fixed else entry_index(p_lead, u, nodes, kappa_max_1_m)
        if k is None:
            return None, "no node far enough beyond the stopping distance"
        traj, poly = _timed_join(np.vstack([p0, p_lead, nodes[k:]]), speed, world=world,
                                 limits=limits, kappa_max_1_m=kappa_max_1_m, lift_down_m=lift_down_m,
                                 first_checked=1 if fixed else 0)
        if traj is None:
            if fixed or attempt == attempts - 1:
                return traj, poly
            lead *= 0.6          # blocked: a shorter lead with a gentler first corner may fit
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
    node (turning onto the path) each need their spiral distance (eq. 19) on the segment between
    them; nodes closer than that are skipped.

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


def _timed_join(points: np.ndarray, speed_m_s: float, *, world, limits, kappa_max_1_m, lift_down_m,
                first_checked: int = 0):
    poly = _clean_nodes(points)
    if poly.shape[0] < 2:
        return None, "nothing to fly"
    if world is not None:
        for a, b in zip(poly[first_checked:-1], poly[first_checked + 1:]):
            if not world.segment_free(a, b):
                return None, "the join crosses a static obstacle"
    curve = smooth_g2(poly, kappa_max_1_m, world=world)
    traj = time_parameterize(curve, limits, start_speed_m_s=speed_m_s)
    if lift_down_m is not None:
        traj = traj.to_ned(lift_down_m)
    return traj, poly


class BrakeAlongPath:
    """Brake to a hover *along the active reference's path* (the hold of DESIGN section 7).

    The vehicle keeps to the geometric path it was flying (so a hold never leaves the free
    space the path was planned in) with a raised-cosine speed profile
    ``v(t) = v0 (1 + cos(pi t / T)) / 2``, ``T = pi v0 / (2 decel)``: the along-track
    acceleration is zero at both ends, at most ``decel`` in between, and the vehicle stops after
    ``v0 T / 2``. Position, velocity (tangent times speed) and acceleration (along-track plus
    the path's centripetal ``kappa v^2``) are interpolated by arc length from a dense sampling
    of the active reference. If the active reference ends (at rest) before that distance, it is
    followed to its end unchanged.

    Parameters
    ----------
    active : Trajectory-like
        ``sample(t_s)`` and ``duration_s``; samples of dimension d (2 or 3).
    active_start_t_s : float
        Clock time of the active reference's t = 0.
    t_s : float
        Clock time at which the hold starts (the reference state there is kept).
    decel_m_s2 : float
        Largest along-track deceleration (m/s^2), > 0.

    Attributes
    ----------
    duration_s, length_m : float
    end_pos_ned_m : ndarray, shape (d,)
    """

    def __init__(self, active, active_start_t_s: float, t_s: float, decel_m_s2: float) -> None:
        self.t_rel0_s = min(max(t_s - active_start_t_s, 0.0), active.duration_s)
        p0, v0, _ = active.sample(np.array([self.t_rel0_s]))
        self.v0_m_s = float(np.linalg.norm(v0[0]))
        self.duration_s = math.pi * self.v0_m_s / (2.0 * decel_m_s2)
        self.length_m = self.v0_m_s * self.duration_s / 2.0
        remaining_s = active.duration_s - self.t_rel0_s
        self._follow = None
        if self.v0_m_s < 1e-3:
            self._table(active, np.array([self.t_rel0_s]))
            self.duration_s, self.length_m = 0.0, 0.0
        else:
            scan_s = min(remaining_s, 2.0 * self.length_m / self.v0_m_s + 10.0)
            t = self.t_rel0_s + np.arange(0.0, scan_s + 0.02, 0.02)
            self._table(active, np.minimum(t, active.duration_s))
            if self._s[-1] < self.length_m:          # the active reference stops first
                self._follow = (active, self.t_rel0_s)
                self.duration_s = remaining_s
                self.length_m = float(self._s[-1])
        self.end_pos_ned_m = self.sample(np.array([self.duration_s]))[0][0]

    def _table(self, active, t: np.ndarray) -> None:
        pos, vel, acc = active.sample(t)
        pos, vel, acc = np.atleast_2d(pos), np.atleast_2d(vel), np.atleast_2d(acc)
        speed = np.linalg.norm(vel, axis=1)
        seg = np.linalg.norm(np.diff(pos, axis=0), axis=1)
        self._s = np.concatenate([[0.0], np.cumsum(seg)])
        moving = speed > 1e-6
        tangent = np.where(moving[:, None], vel / np.maximum(speed, 1e-6)[:, None], 0.0)
        if not np.any(moving):
            tangent[:, 0] = 1.0
        else:   # carry the last known direction over stops
            idx = np.maximum.accumulate(np.where(moving, np.arange(len(t)), -1))
            idx[idx < 0] = int(np.argmax(moving))
            tangent = tangent[idx]
        along = np.einsum("ij,ij->i", acc, tangent)
        normal = acc - along[:, None] * tangent
        self._curv = np.where(moving[:, None], normal / np.maximum(speed, 1e-6)[:, None] ** 2, 0.0)
        self._pos, self._tangent = pos, tangent
        self._yaw = np.unwrap(np.arctan2(tangent[:, 1], tangent[:, 0]))
        self.d = pos.shape[1]

    def _interp(self, s: np.ndarray, table: np.ndarray) -> np.ndarray:
        if self._s.size == 1:
            return np.repeat(table[:1], s.size, axis=0)
        return np.stack([np.interp(s, self._s, table[:, j]) for j in range(table.shape[1])], axis=1)

    def profile(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arc length (m), speed (m/s) and along-track acceleration (m/s^2) at ``t_s`` (K,)."""
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
        if self.duration_s <= 0.0:
            return np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
        w = math.pi / self.duration_s
        v0 = self.v0_m_s
        return (0.5 * v0 * (t + np.sin(w * t) / w), 0.5 * v0 * (1.0 + np.cos(w * t)),
                -0.5 * v0 * w * np.sin(w * t))

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (K, d) at times ``t_s`` (K,) since the hold began."""
        if self._follow is not None:
            active, t0 = self._follow
            t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
            pos, vel, acc = active.sample(t0 + t)
            return np.atleast_2d(pos), np.atleast_2d(vel), np.atleast_2d(acc)
        s, v, a = self.profile(t_s)
        tangent = self._interp(s, self._tangent)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1), 1e-12)[:, None]
        pos = self._interp(s, self._pos)
        vel = tangent * v[:, None]
        acc = tangent * a[:, None] + self._interp(s, self._curv) * (v * v)[:, None]
        return pos, vel, acc

    def yaw_rad(self, t_s) -> np.ndarray:
        """Heading of the path (rad, in (-pi, pi]) at times ``t_s`` (K,)."""
        if self._follow is not None:
            active, t0 = self._follow
            t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
            return active.yaw_rad(t0 + t)
        s = self.profile(t_s)[0]
        yaw = np.interp(s, self._s, self._yaw) if self._s.size > 1 else np.full(s.shape, self._yaw[0])
        return np.angle(np.exp(1j * yaw))

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        """Rate of the path heading (rad/s) at times ``t_s`` (K,): d(yaw)/ds times speed."""
        if self._follow is not None:
            active, t0 = self._follow
            t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
            return active.yaw_rate_rad_s(t0 + t)
        s, v, _ = self.profile(t_s)
        if self._s.size < 2:
            return np.zeros_like(s)
        slope = np.diff(self._yaw) / np.maximum(np.diff(self._s), 1e-9)
        middle = 0.5 * (self._s[1:] + self._s[:-1])
        return np.interp(s, middle, slope) * v

    def path_ned_m(self, step_m: float = 2.0) -> np.ndarray:
        """The hold's path as a polyline (K, d), for ``uav/<sysid>/path``."""
        n = max(2, int(math.ceil(self.length_m / step_m)) + 1)
        return self.sample(np.linspace(0.0, self.duration_s, n) if self.duration_s > 0 else np.zeros(2))[0]


# ---------------------------------------------------------------------------- the manager
@dataclass
class _ReplanEstimate:
    """Running estimate of the replanning time: mean and mean absolute deviation (s)."""

    mean_s: float
    dev_s: float = 0.0
    samples: int = 0

    def update(self, measured_s: float, gain: float) -> None:
        if self.samples == 0:
            self.mean_s, self.dev_s = measured_s, 0.25 * measured_s
        else:
            err = measured_s - self.mean_s
            self.mean_s += gain * err
            self.dev_s += gain * (abs(err) - self.dev_s)
        self.samples += 1

    @property
    def high_s(self) -> float:
        return self.mean_s + 3.0 * self.dev_s


@dataclass
class _Active:
    trajectory: object
    start_t_s: float
    path_id: str
    holding: bool = False


class ThreatManager:
    """The replan / switch / hold policy (see the module docstring). Not thread-safe by itself:
    call it from one worker thread at a time (``set_alternatives`` may come from another).

    Parameters
    ----------
    world : World
        Static world of the current leg (2D or 3D, local NED).
    goal_ned_m : array_like, shape (d,)
        Goal of the current leg.
    settings : ThreatSettings, optional
    limits : TrajectoryLimits, optional
        Limits of new trajectories (default ``TrajectoryLimits()``).
    kappa_max_1_m : float
        K_max of the G2 smoothing (default 0.1).
    gart_settings : GartSettings, optional
        Settings of the replanning GART (its time budget comes from ``settings``).
    rng : numpy.random.Generator, optional
        Default: ``numpy.random.default_rng(settings.seed)``.
    mode : str
        ``hybrid`` (DESIGN section 7, default), ``replan`` (replan only) or ``switch`` (switch
        only): the single strategies exist for the benchmark.
    """

    MODES = ("hybrid", "replan", "switch")

    def __init__(self, world: World, goal_ned_m, *, settings: ThreatSettings | None = None,
                 limits: TrajectoryLimits | None = None, kappa_max_1_m: float = 0.1,
                 gart_settings: GartSettings | None = None, rng: np.random.Generator | None = None,
                 mode: str = "hybrid") -> None:
        self.settings = settings or ThreatSettings()
        if not isinstance(self.settings, ThreatSettings):
            raise ThreatManagerError(f"settings: expected ThreatSettings, got {type(settings).__name__}")
        if mode not in self.MODES:
            raise ThreatManagerError(f"mode: expected one of {', '.join(self.MODES)}, got {mode!r}")
        self.mode = mode
        self.limits = limits or TrajectoryLimits()
        if not (isinstance(kappa_max_1_m, (int, float)) and math.isfinite(kappa_max_1_m) and kappa_max_1_m > 0):
            raise ThreatManagerError(f"kappa_max_1_m: must be a finite number > 0, got {kappa_max_1_m!r}")
        self.kappa_max_1_m = float(kappa_max_1_m)
        self.gart_settings = gart_settings or GartSettings(kappa_max_1_m=self.kappa_max_1_m)
        self.rng = rng if rng is not None else np.random.default_rng(self.settings.seed)
        self.world = world
        self.goal_ned_m = np.zeros(world.dim)
        self.set_leg(world, goal_ned_m)
        self._active: _Active | None = None
        self._alternatives: tuple[Alternative, ...] = ()
        self._estimate = _ReplanEstimate(self.settings.replan_budget_s)
        self._counter = 0

    # ------------------------------------------------------------------ inputs
    def set_leg(self, world: World, goal_ned_m) -> None:
        """A new leg: its static world and goal (clears nothing else)."""
        if not isinstance(world, World):
            raise ThreatManagerError(f"world: expected a World, got {type(world).__name__}")
        goal = np.asarray(goal_ned_m, dtype=float).reshape(-1)
        if goal.shape != (world.dim,) or not np.all(np.isfinite(goal)):
            raise ThreatManagerError(f"goal_ned_m: expected {world.dim} finite numbers, got {goal_ned_m!r}")
        self.world = world
        self.goal_ned_m = goal

    def set_active(self, trajectory, start_t_s: float, path_id: str = "active") -> None:
        """The reference being flown: ``trajectory`` with its t = 0 at clock time ``start_t_s``.

        Call it whenever the daemon engages a reference (the manager's own decisions included).
        """
        if not hasattr(trajectory, "sample") or not hasattr(trajectory, "duration_s"):
            raise ThreatManagerError("trajectory: expected an object with sample(t_s) and duration_s")
        if not math.isfinite(start_t_s):
            raise ThreatManagerError(f"start_t_s: must be finite, got {start_t_s!r}")
        self._active = _Active(trajectory, float(start_t_s), str(path_id))

    def set_alternatives(self, alternatives) -> None:
        """Replace the switching targets (a list of ``Alternative`` or of (M, d) paths).

        Thread-safe (one reference swap): the daemon refreshes them in the background.
        """
        alts = []
        for i, alt in enumerate(alternatives):
            if not isinstance(alt, Alternative):
                alt = Alternative.from_path(f"alt{i}", alt, self.settings.entry_spacing_m)
            if alt.path_ned_m.shape[1] != self.world.dim:
                raise ThreatManagerError(f"alternatives[{i}]: dimension {alt.path_ned_m.shape[1]} "
                                         f"does not match the world's {self.world.dim}")
            alts.append(alt)
        self._alternatives = tuple(alts)

    @property
    def alternatives(self) -> tuple[Alternative, ...]:
        return self._alternatives

    @property
    def active_path_id(self) -> str | None:
        return None if self._active is None else self._active.path_id

    @property
    def replan_estimate_s(self) -> float:
        """Current replanning budget: running mean + 3 mean absolute deviations (s)."""
        return self._estimate.high_s

    def compute_alternatives(self, threats, t_s: float, k: int = 4, *, rng: np.random.Generator,
                             max_time_s: float = 2.0, settings: MgartSettings | None = None,
                             start_ned_m=None) -> list[Alternative]:
        """M-GART alternatives from the current reference (or ``start_ned_m``) to the goal.

        Slow (``max_time_s``): run it in the background after every change, then give the
        result to ``set_alternatives``. Threats known now are avoided (swept volumes).

        Returns
        -------
        list of Alternative
            Cheapest first, ids ``alt<i>-<n>``; empty when M-GART finds nothing.
        """
        if start_ned_m is None:
            ref = self.reference_state(t_s)
            if ref is None:
                raise ThreatManagerError("start_ned_m: needed when no trajectory is active")
            start_ned_m = ref.pos_ned_m
        start = np.asarray(start_ned_m, dtype=float)[: self.world.dim]
        world = self._threat_world(self._relevant(threats, t_s, start), t_s, keep_free=[start, self.goal_ned_m])
        settings = settings or MgartSettings(gart=self.gart_settings)
        results = mgart(world, start, self.goal_ned_m, k, rng=rng, max_time_s=max_time_s, settings=settings)
        self._counter += 1
        return [Alternative.from_path(f"alt{i}-{self._counter}", r.path, self.settings.entry_spacing_m)
                for i, r in enumerate(results) if r.status == "exact" and r.path is not None]

    # ------------------------------------------------------------------ state
    def reference_state(self, t_s: float) -> ReferenceState | None:
        """Reference of the active trajectory at clock time ``t_s`` (planning dimension)."""
        if self._active is None:
            return None
        t_rel = min(max(t_s - self._active.start_t_s, 0.0), self._active.trajectory.duration_s)
        pos, vel, acc = self._active.trajectory.sample(np.array([t_rel]))
        d = self.world.dim
        return ReferenceState(float(t_s), np.asarray(pos[0][:d], float), np.asarray(vel[0][:d], float),
                              np.asarray(acc[0][:d], float))

    def _lift_down_m(self, t_s: float) -> float | None:
        """Down coordinate to lift 2D trajectories to, when the active one is 3D in a 2D world."""
        if self.world.dim == 3 or self._active is None:
            return None
        t_rel = min(max(t_s - self._active.start_t_s, 0.0), self._active.trajectory.duration_s)
        pos = np.atleast_2d(self._active.trajectory.sample(np.array([t_rel]))[0])[0]
        return float(pos[2]) if pos.shape[0] == 3 else None

    def _relevant(self, threats, t_s: float, pos: np.ndarray) -> list[Threat]:
        """Local, unexpired threats within the sensor range of ``pos`` now."""
        d = self.world.dim
        out = []
        for th in threats:
            if th.frame != "local_ned":
                raise ThreatManagerError(f"threat {th.id!r}: convert global threats to local NED "
                                         f"first (ThreatTable(home=...))")
            if th.expires_t_s <= t_s:
                continue
            dist = float(np.linalg.norm(th.position_at(t_s)[:d] - pos[:d])) - th.radius_m
            if dist <= self.settings.sensor_range_m:
                out.append(th)
        return out

    def _threat_world(self, threats, t_s: float, keep_free) -> World:
        obstacles = threat_obstacles(threats, t_s, inflation_m=self.settings.inflation_m,
                                     sweep_s=self.settings.sweep_horizon_s, dim=self.world.dim,
                                     keep_free=keep_free)
        return self.world.with_threats(obstacles) if obstacles else self.world

    def _speed_bound(self) -> float:
        return self.limits.speed_m_s

    def _conflict_of(self, trajectory, start_t_s: float, t_s: float, threats) -> Conflict | None:
        return first_conflict(trajectory, start_t_s, t_s, t_s + self.settings.horizon_s, threats,
                              inflation_m=self.settings.inflation_m, dim=self.world.dim,
                              step_s=self.settings.check_step_s, speed_bound_m_s=self._speed_bound(),
                              escape=True)

    def check(self, threats, t_s: float) -> Conflict | None:
        """Space-time conflict of the active reference with ``threats`` over the horizon."""
        ref = self.reference_state(t_s)
        if ref is None:
            return None
        relevant = self._relevant(threats, t_s, ref.pos_ned_m)
        return self._conflict_of(self._active.trajectory, self._active.start_t_s, t_s, relevant)

    # ------------------------------------------------------------------ the decision
    def on_threats(self, threats, t_s: float) -> Decision:
        """Decide what to do about ``threats`` at clock time ``t_s`` (DESIGN section 7).

        Parameters
        ----------
        threats : sequence of Threat
            Every threat known now (``ThreatTable.snapshot(t_s)``), local frame, stamped on the
            same clock as ``t_s``.
        t_s : float
            Now (the reference state is the active trajectory's at ``t_s``).

        Returns
        -------
        Decision
            For ``replan``, ``switch`` and ``hold`` the manager has already made the new
            trajectory its active one (with ``start_t_s``); the caller engages it too.
        """
        t0 = time.perf_counter()
        ref = self.reference_state(t_s)
        if ref is None:
            return Decision("none", "no active trajectory", decide_ms=_ms_since(t0))
        relevant = self._relevant(threats, t_s, ref.pos_ned_m)
        if self._active.holding:
            return self._finish(self._resume(ref, relevant, "resume after hold", None), t0)
        conflict = self._conflict_of(self._active.trajectory, self._active.start_t_s, t_s, relevant)
        if conflict is None:
            return Decision("none", "the remaining reference is clear of every threat",
                            decide_ms=_ms_since(t0))
        ttc = conflict.time_to_conflict_s
        budget = self._estimate.high_s + self.settings.replan_margin_s
        what = (f"threat {conflict.threat_id} in {ttc:.2f} s "
                f"({'>' if ttc > budget else '<='} replan budget {budget:.2f} s)")
        if self.mode == "replan" or (self.mode == "hybrid" and ttc > budget):
            decision = self._replan(ref, relevant, what, conflict)
            if decision is None and self.mode == "hybrid":
                decision = self._switch(ref, relevant, what + "; replan found no clear path", conflict)
        else:
            decision = self._switch(ref, relevant, what, conflict)
        if decision is None:
            decision = self._hold(ref, what + "; no clear path or alternative", conflict)
        return self._finish(decision, t0)

    def resume(self, threats, t_s: float) -> Decision:
        """Replan from the current reference (after a ``hold``); ``hold`` again if impossible."""
        t0 = time.perf_counter()
        ref = self.reference_state(t_s)
        if ref is None:
            return Decision("none", "no active trajectory", decide_ms=_ms_since(t0))
        relevant = self._relevant(threats, t_s, ref.pos_ned_m)
        return self._finish(self._resume(ref, relevant, "resume", None), t0)

    def reject(self, error: Exception) -> Decision:
        """The ``rejected`` decision for an invalid threat sample (the flight goes on)."""
        return Decision("rejected", str(error))

    def _resume(self, ref: ReferenceState, threats, what: str, conflict) -> Decision:
        if self.mode == "switch":
            decision = self._switch(ref, threats, what, conflict)
        else:
            decision = self._replan(ref, threats, what, conflict)
        if decision is not None:
            return decision
        self._active.holding = True
        return Decision("hold", what + "; still no clear path: keep holding", path_id=self._active.path_id,
                        conflict=conflict, resume=True)

    def _finish(self, decision: Decision, t0: float) -> Decision:
        decision = replace(decision, decide_ms=_ms_since(t0))
        if decision.trajectory is not None:
            self._active = _Active(decision.trajectory, decision.start_t_s, decision.path_id,
                                   holding=decision.kind == "hold")
        log.info("threat decision %s (%s) path %s: decide %.1f ms, plan %.1f ms", decision.kind,
                 decision.reason, decision.path_id, decision.decide_ms, decision.plan_ms)
        return decision

    # ------------------------------------------------------------------ replan
    def _replan(self, ref: ReferenceState, threats, what: str, conflict) -> Decision | None:
        t0 = time.perf_counter()
        try:
            return self._replan_inner(ref, threats, what, conflict, t0)
        finally:
            self._estimate.update(time.perf_counter() - t0, self.settings.estimate_gain)

    def _replan_inner(self, ref, threats, what, conflict, t0) -> Decision | None:
        s = self.settings
        speed = float(np.linalg.norm(ref.vel_ned_m_s))
        start = ref.pos_ned_m
        lead = None
        if speed >= HOVER_SPEED_M_S:
            u = ref.vel_ned_m_s / speed
            turn = max(_turn_rad(u, self.goal_ned_m - start), s.replan_turn_rad)
            lead = lead_length_m(min(speed, self.limits.speed_m_s), turn, self.limits, self.kappa_max_1_m)
            start = start + u * lead
            if not self.world.in_bounds(start) or not self.world.segment_free(ref.pos_ned_m, start):
                log.info("replan: the stopping lead leaves the free space")
                return None
        world = self._threat_world(threats, ref.t_s, keep_free=[ref.pos_ned_m, start, self.goal_ned_m])
        result = gart(world, start, self.goal_ned_m, rng=self.rng, max_time_s=s.gart_budget_s,
                      settings=self.gart_settings)
        if result.status == "timeout":
            result = gart(world, start, self.goal_ned_m, rng=self.rng, max_time_s=s.gart_first_budget_s,
                          stop_at_first=True, settings=self.gart_settings)
        if result.status != "exact":
            log.info("replan: GART %s", result.status)
            return None
        nodes = result.path[1:] if speed >= HOVER_SPEED_M_S else result.path
        traj, poly = join_trajectory(ref, nodes, world=world, limits=self.limits,
                                     kappa_max_1_m=self.kappa_max_1_m, lift_down_m=self._lift_down_m(ref.t_s),
                                     lead_m=lead)
        if traj is None:
            log.info("replan: %s", poly)
            return None
        if self._conflict_of(traj, ref.t_s, ref.t_s, threats) is not None:
            log.info("replan: the new trajectory still meets a predicted threat")
            return None
        self._counter += 1
        return Decision("replan", what, traj, ref.t_s, f"replan-{self._counter}", poly, conflict,
                        plan_ms=_ms_since(t0))

    # ------------------------------------------------------------------ switch
    def switch_candidates(self, ref: ReferenceState) -> list[tuple[float, Alternative, int]]:
        """Entry nodes within the switching range, cheapest remaining cost first.

        Entries of one alternative closer than 2.5 entry spacings to a cheaper one are left out
        (they would give nearly the same trajectory); the order is round robin over the
        alternatives: the cheapest entry of each (cheapest first), then the second ...

        Returns
        -------
        list of (cost_m, alternative, entry index)
            cost = distance to the entry + the alternative's length from it to the goal.
        """
        out = []
        for alt in self._alternatives:
            dist = np.linalg.norm(alt.entry_pos_ned_m - ref.pos_ned_m[None, :], axis=1)
            for e in np.flatnonzero(dist <= self.settings.switch_range_m):
                out.append((float(dist[e] + alt.entry_remaining_m[e]), alt, int(e)))
        out.sort(key=lambda c: (c[0], -c[2]))
        per_alt: dict[str, list[tuple[float, Alternative, int]]] = {}
        spacing = 2.5 * self.settings.entry_spacing_m
        for cand in out:
            mine = per_alt.setdefault(cand[1].path_id, [])
            pos = cand[1].entry_pos_ned_m[cand[2]]
            if all(np.linalg.norm(p[1].entry_pos_ned_m[p[2]] - pos) >= spacing for p in mine):
                mine.append(cand)
        # round robin over the alternatives (cheapest first in each round): a threat that blocks
        # one alternative usually blocks all its entries, so diversity comes first
        rounds = max((len(v) for v in per_alt.values()), default=0)
        picked = []
        for r in range(rounds):
            picked += sorted((v[r] for v in per_alt.values() if len(v) > r), key=lambda c: c[0])
        return picked

    def _switch(self, ref: ReferenceState, threats, what: str, conflict) -> Decision | None:
        t0 = time.perf_counter()
        tried = 0
        lift = self._lift_down_m(ref.t_s)
        why: dict[str, int] = {}
        alternatives = len(self._alternatives)
        for cost, alt, i in self.switch_candidates(ref):
            if tried >= self.settings.max_candidates or \
                    time.perf_counter() - t0 > self.settings.switch_budget_s:
                break
            tried += 1
            traj, poly = join_trajectory(ref, alt.nodes_from(i), world=self.world, limits=self.limits,
                                         kappa_max_1_m=self.kappa_max_1_m, lift_down_m=lift)
            if traj is None:
                why[poly.split(" (")[0]] = why.get(poly.split(" (")[0], 0) + 1
                continue
            if self._conflict_of(traj, ref.t_s, ref.t_s, threats) is not None:
                why["meets a predicted threat"] = why.get("meets a predicted threat", 0) + 1
                continue
            return Decision("switch", f"{what}; entry node {i} of {alt.path_id} "
                            f"({cost:.1f} m to go)", traj, ref.t_s, alt.path_id, poly, conflict,
                            plan_ms=_ms_since(t0))
        log.info("switch: no safe entry among %d candidates tried of %d alternatives (%s)", tried,
                 alternatives, "; ".join(f"{k}: {n}" for k, n in why.items()))
        return None

    # ------------------------------------------------------------------ hold
    def _hold(self, ref: ReferenceState, what: str, conflict) -> Decision:
        t0 = time.perf_counter()
        traj = BrakeAlongPath(self._active.trajectory, self._active.start_t_s, ref.t_s,
                              self.settings.hold_decel_m_s2)
        poly = traj.path_ned_m()[:, : self.world.dim]
        self._counter += 1
        return Decision("hold", what, traj, ref.t_s, f"hold-{self._counter}", poly, conflict,
                        plan_ms=_ms_since(t0), resume=self.mode != "switch")


def _ms_since(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3
