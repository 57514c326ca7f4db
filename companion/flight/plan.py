"""Mission -> legs -> planned, smoothed, time-parameterised trajectories (paper sections 3.1-3.2).

A leg is an *input* to the one trajectory pipeline (``companion.flight.pipeline``); for every
leg of a local mission:

1. ``plan``: the pipeline's planner (GART) from the leg's start to its goal in the leg's
   *slab*: the mission world with its down bounds narrowed to the leg's altitudes plus
   ``slab_margin_m`` (exclusion zones are full-height, so the search is almost planar and the
   path stays level), in a budget doubled at every attempt (``planning_attempts``);
2. ``smooth``, ``time`` and ``check``: the pipeline's smoother (``smoothing.method``: G2, G1 or
   none, repaired against the slab), its speed profile under the leg's speed and the vehicle's
   limits (the leg starts and ends at rest at its waypoints) and its checker: the curve is
   checked free and, when the pipeline has a closed-loop checker, every piece of the leg is
   flown by the helicopter model and its LQI (``companion.smoothing.feasibility``); a piece
   that would saturate a rotor input or track too far off is stretched in time until it does
   not. The figures (peak actuator use, predicted tracking error, stretch) are kept in
   ``LegPlan.feasibility``.

A leg whose altitude changes starts with a vertical climb or descent (its own straight
trajectory, timed and checked by the same pipeline), then flies level: what flight-test
engineers expect, and what keeps the planner in a thin slab. ``TrajectoryChain`` strings the
pieces of a leg into one time-sampled reference.

Everything here is pure: no I/O, the randomness comes from ``rng``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np

from companion.errors import MissionError
from companion.flight.pipeline import Checked, PlanBudget, PlanningProblem, TrajectoryPipeline, TrajectoryStatus
from companion.planning import PlanResult
from companion.smoothing import TrajectoryLimits
from companion.smoothing.bezier_maths import clip_ufunc
from companion.world import Cylinder, Prism, World
from heli_common.typed_config import require_int, require_numbers

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FlightPlanSettings:
    """How each leg of a mission is planned.

    Parameters
    ----------
    planning_budget_s : float
        GART wall-clock budget per leg (anytime: the best path found in the budget). Default 0.5.
    planning_attempts : int
        A leg without a path in the budget is tried again with twice the budget, this many
        times in all (default 4: up to 0.5 + 1 + 2 + 4 s) before it is declared unreachable.
    slab_margin_m : float
        Half-thickness added above and below the leg's altitudes for its planning slab (m).
    climb_speed_m_s, descent_speed_m_s : float
        Vertical speeds of climbs and descents between legs (m/s).
    vertical_accel_m_s2 : float
        Vertical acceleration limit of those climbs and descents (m/s^2).
    min_vertical_change_m : float
        Altitude changes smaller than this are flown within the level leg's tolerance, without a
        vertical segment (m).
    alternatives_k : int
        M-GART alternatives kept per leg for the threat manager to switch to (0: none).
    alternatives_budget_s : float
        Wall-clock budget of one M-GART refresh (s), run in the background.
    alternatives_period_s : float
        The alternatives are refreshed this often (mission s), besides leg starts and
        decisions.
    alternatives_lead_s : float
        They start from the reference this far ahead in time (mission s), so that their entry
        nodes lie ahead, where the vehicle can still turn onto them.
    turn_rate_rad_s : float
        A leg starts at rest: the vehicle first turns on the spot to the leg's heading at this
        rate (rad/s), so it never accelerates while turning hard.
    """

    planning_budget_s: float = 0.5
    planning_attempts: int = 4
    slab_margin_m: float = 2.0
    climb_speed_m_s: float = 2.5
    descent_speed_m_s: float = 1.5
    vertical_accel_m_s2: float = 1.0
    min_vertical_change_m: float = 0.3
    alternatives_k: int = 4
    alternatives_budget_s: float = 0.5
    alternatives_period_s: float = 1.0
    alternatives_lead_s: float = 1.0
    turn_rate_rad_s: float = 0.6

    def __post_init__(self) -> None:
        require_int(MissionError, "flight", "planning_attempts", self.planning_attempts, 1, 10)
        require_int(MissionError, "flight", "alternatives_k", self.alternatives_k, 0, 16)
        require_numbers(
            MissionError,
            "flight",
            self,
            positive=(
                "planning_budget_s",
                "slab_margin_m",
                "climb_speed_m_s",
                "descent_speed_m_s",
                "vertical_accel_m_s2",
                "min_vertical_change_m",
                "alternatives_budget_s",
                "alternatives_period_s",
                "alternatives_lead_s",
                "turn_rate_rad_s",
            ),
        )


class TrajectoryChain:
    """Trajectories flown one after the other, sampled by time like one ``Trajectory``.

    Parameters
    ----------
    pieces : sequence of Trajectory
        Each 3D (NED); each piece starts where the previous one ends, at rest.
    """

    def __init__(self, pieces):
        self.pieces = tuple(pieces)
        if not self.pieces:
            raise MissionError("a trajectory chain needs at least one piece")
        durations = np.array([p.duration_s for p in self.pieces], dtype=float)
        self.t_start_s = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        self.duration_s = float(durations.sum())
        self.length_m = float(sum(p.length_m for p in self.pieces))

    def _split(self, t_s) -> tuple[np.ndarray, np.ndarray | None, int, int]:
        """Clipped times (K,), their piece indices (K,) and the first and last piece they fall in.

        The indices are None when every time falls in one piece (one piece, or one time).
        """
        t = clip_ufunc(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
        if t.size == 0:
            return t, np.zeros(0, dtype=int), 0, -1  # no piece is sampled
        if len(self.pieces) == 1:
            return t, None, 0, 0
        idx = clip_ufunc(np.searchsorted(self.t_start_s, t, side="right") - 1, 0, len(self.pieces) - 1)
        if idx.size == 1:
            k = int(idx[0])
            return t, None, k, k
        first, last = int(idx.min()), int(idx.max())
        return t, (idx if first != last else None), first, last

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (NED) at times ``t_s`` (K,) -> three (K, 3) arrays."""
        t, idx, first, last = self._split(t_s)
        if idx is None:  # all in one piece: no gather, no scatter
            return self.pieces[first].sample(t - self.t_start_s[first])
        pos = np.empty((t.size, 3))
        vel = np.empty((t.size, 3))
        acc = np.empty((t.size, 3))
        for k in range(first, last + 1):
            sel = idx == k
            if sel.any():
                p, v, a = self.pieces[k].sample(t[sel] - self.t_start_s[k])
                pos[sel], vel[sel], acc[sel] = p, v, a
        return pos, vel, acc

    def _per_piece(self, name: str, t_s) -> np.ndarray:
        t, idx, first, last = self._split(t_s)
        if idx is None:
            return getattr(self.pieces[first], name)(t - self.t_start_s[first])
        out = np.empty(t.size)
        for k in range(first, last + 1):
            sel = idx == k
            if sel.any():
                out[sel] = getattr(self.pieces[k], name)(t[sel] - self.t_start_s[k])
        return out

    def yaw_rad(self, t_s) -> np.ndarray:
        """Yaw reference (rad) at times ``t_s`` (K,) -> (K,)."""
        return self._per_piece("yaw_rad", t_s)

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        """Yaw-rate reference (rad/s) at times ``t_s`` (K,) -> (K,)."""
        return self._per_piece("yaw_rate_rad_s", t_s)

    @property
    def end_pos_ned_m(self) -> np.ndarray:
        return self.pieces[-1].end_pos_ned_m


@dataclass
class LegPlan:
    """One planned leg.

    Attributes
    ----------
    index : int
        Position of the leg in the mission (0-based).
    waypoint : LocalWaypoint
        The goal (its ``seq`` names the mission item in messages).
    start_ned_m, goal_ned_m : ndarray (3,)
    plan : PlanResult or None
        GART's result for the level part; None for a purely vertical leg.
    path_ned_m : ndarray (M, 3)
        The polyline flown (vertical segment and planner path), for plots and checks.
    trajectory : TrajectoryChain
    world : World
        The slab the level part was planned in.
    notes : list of str
        What the smoother or the timing could not honour, and any stretch of the timing.
    feasibility : dict or None
        The closed-loop check of the leg (``feasibility_summary``); None when not checked.
    """

    index: int
    waypoint: object
    start_ned_m: np.ndarray
    goal_ned_m: np.ndarray
    plan: PlanResult | None
    path_ned_m: np.ndarray
    trajectory: TrajectoryChain
    world: World
    notes: list = field(default_factory=list)
    feasibility: dict | None = None


def leg_slab(world: World, down_values_m, margin_m: float) -> World:
    """The mission world with its down bounds narrowed to ``down_values_m`` +/- ``margin_m``."""
    lo = np.array(world.bounds_min, dtype=float)
    hi = np.array(world.bounds_max, dtype=float)
    lo[2] = max(lo[2], min(down_values_m) - margin_m)
    hi[2] = min(hi[2], max(down_values_m) + margin_m)
    if hi[2] <= lo[2]:
        raise MissionError(f"altitudes {[-d for d in down_values_m]} m are outside the world's altitude bounds")
    return World(world.obstacles, lo, hi, world.margin_m)


def vertical_trajectory(
    start_ned_m: np.ndarray, down_m: float, settings: FlightPlanSettings, yaw_rad: float, pipeline: TrajectoryPipeline
) -> Checked:
    """A straight climb or descent from ``start_ned_m`` to ``down_m`` at rest at both ends,
    timed and checked (closed loop) by ``pipeline``."""
    end = np.array([start_ned_m[0], start_ned_m[1], down_m])
    climbing = down_m < start_ned_m[2]
    speed = settings.climb_speed_m_s if climbing else settings.descent_speed_m_s
    accel = settings.vertical_accel_m_s2
    limits = TrajectoryLimits(speed_m_s=speed, accel_m_s2=accel, lat_accel_m_s2=accel, jerk_m_s3=4.0 * accel)
    timed = pipeline.timer.time(np.vstack([start_ned_m, end]), limits, yaw_mode="hold", yaw_hold_rad=yaw_rad)
    return pipeline.checker.check(timed)


def footprint(world: World) -> World | None:
    """The 2D (north-east) world of a slab whose obstacles all span its whole height, else None.

    Fence zones are vertical extrusions: in such a slab the search is planar, and a 2D search
    is several times faster than the same search in 3D.
    """
    lo, hi = world.bounds_min, world.bounds_max
    for ob in world.obstacles:
        if not isinstance(ob, (Cylinder, Prism)) or ob.down_min_m > lo[2] or ob.down_max_m < hi[2]:
            return None
    return World(world.obstacles, lo[:2], hi[:2], world.margin_m)


def level(path: np.ndarray, down_m: float, world: World) -> np.ndarray:
    """The path flown at ``down_m`` throughout, if that is collision-free; else unchanged.

    GART searches the whole slab; where the obstacles are vertical extrusions (fence zones) the
    level path is as safe and saves the climbs and descents.
    """
    flat = np.array(path, dtype=float)
    flat[:, 2] = down_m
    return flat if world.path_free(flat) else path


def leg_limits(waypoint, limits: TrajectoryLimits) -> TrajectoryLimits:
    """The vehicle's limits with the leg's cruise speed (a DO_CHANGE_SPEED or item speed)."""
    speed = waypoint.speed_m_s
    if speed is None or speed <= 0:
        return limits
    return replace(limits, speed_m_s=min(float(speed), limits.speed_m_s))


def plan_level(
    level_start: np.ndarray,
    goal: np.ndarray,
    slab: World,
    waypoint,
    *,
    pipeline: TrajectoryPipeline,
    settings: FlightPlanSettings,
    rng: np.random.Generator,
    where: str,
) -> tuple[PlanResult, np.ndarray, Checked]:
    """The level part of a leg through the pipeline; returns (PlanResult, path, Checked)."""
    budget = PlanBudget(settings.planning_budget_s, settings.planning_attempts)
    plane = footprint(slab)
    if plane is not None:
        result = pipeline.plan(PlanningProblem(plane, level_start[:2], goal[:2]), budget, rng=rng)
        if result.path is not None:
            result = replace(result, path=np.column_stack([result.path, np.full(len(result.path), goal[2])]))
    else:
        result = pipeline.plan(PlanningProblem(slab, level_start, goal), budget, rng=rng)
    if result.status != "exact":
        reason = {
            "invalid_start": "the leg starts inside an obstacle or outside the bounds",
            "invalid_goal": "the goal is inside an obstacle (with the safety margin)",
            "timeout": f"no path found in {budget.total_s:g} s of search",
        }[result.status]
        raise MissionError(f"{where}: unreachable: {reason}")
    assert result.path is not None  # an 'exact' result has a path
    path = level(result.path, goal[2], slab)
    checked = pipeline.trajectory(path, slab, limits=leg_limits(waypoint, pipeline.limits))
    if checked.status is TrajectoryStatus.BLOCKED:
        raise MissionError(f"{where}: the smoothed trajectory is not free: {checked.reason}")
    return result, path, checked


def feasibility_summary(reports) -> dict:
    """The closed-loop figures of a leg from the ``FeasibilityReport`` of each of its pieces.

    Peaks and maxima are over the pieces, the stretch is the largest, the RMS tracking error is
    weighted by the pieces' (stretched) durations; ``pieces`` keeps each piece's own figures.
    """
    parts = [r.summary() for r in reports]
    durations = np.array([p["duration_s"] for p in parts])
    rms = np.array([p["rms_tracking_error_m"] for p in parts])
    weights = durations if durations.sum() > 0 else np.ones_like(durations)
    peak = {name: max(p["peak_abs_delta"][name] for p in parts) for name in parts[0]["peak_abs_delta"]}
    return {
        "feasible": all(p["feasible"] for p in parts),
        "stretch": max(p["stretch"] for p in parts),
        "max_abs_delta": max(p["max_abs_delta"] for p in parts),
        "peak_abs_delta": peak,
        "saturated": any(p["saturated"] for p in parts),
        "max_tracking_error_m": max(p["max_tracking_error_m"] for p in parts),
        "rms_tracking_error_m": float(np.sqrt(np.sum(weights * rms**2) / np.sum(weights))),
        "initial_max_abs_delta": max(p["initial_max_abs_delta"] for p in parts),
        "initial_max_tracking_error_m": max(p["initial_max_tracking_error_m"] for p in parts),
        "initial_saturated": any(p["initial_saturated"] for p in parts),
        "attempts": sum(p["attempts"] for p in parts),
        "reason": "; ".join(p["reason"] for p in parts if p["reason"]),
        "duration_s": float(durations.sum()),
        "check_s": sum(p["check_s"] for p in parts),
        "pieces": parts,
    }


def plan_leg(
    index: int,
    waypoint,
    start_ned_m,
    world: World,
    *,
    pipeline: TrajectoryPipeline,
    settings: FlightPlanSettings,
    rng: np.random.Generator,
    yaw_rad: float = 0.0,
) -> LegPlan | None:
    """Plan, smooth, time and check one leg from ``start_ned_m`` to ``waypoint`` (``pipeline``).

    The level part is planned first; a climb or descent before it holds the level part's
    initial heading (``yaw_rad`` when there is no level part). Returns None when the goal is
    where the leg starts (e.g. a LAND item right below the last waypoint): nothing to fly.

    Raises
    ------
    MissionError
        The goal is unreachable (inside an obstacle, or no path within the budget), naming the
        mission item.
    """
    start = np.asarray(start_ned_m, dtype=float).reshape(3)
    goal = np.array(waypoint.pos_ned_m, dtype=float)
    if waypoint.kind in ("land", "rtl"):
        goal[2] = start[2]  # fly there level; the vehicle's LAND descends
    where = f"item {waypoint.seq} ({waypoint.kind})"
    level_start = np.array([start[0], start[1], goal[2]])
    slab = leg_slab(world, [goal[2]], settings.slab_margin_m)
    result, path, level_part = None, level_start[None, :], None
    if np.hypot(*(goal[:2] - level_start[:2])) > 1e-3:
        result, path, level_part = plan_level(
            level_start, goal, slab, waypoint, pipeline=pipeline, settings=settings, rng=rng, where=where
        )
        yaw_rad = float(level_part.trajectory.yaw_rad(np.array([0.0]))[0])
    checks = []
    if abs(goal[2] - start[2]) >= settings.min_vertical_change_m:
        checks.append(vertical_trajectory(start, goal[2], settings, yaw_rad, pipeline))
    if level_part is not None:
        checks.append(level_part)
    if not checks:
        return None
    pieces = [c.trajectory for c in checks]
    reports = [c.report for c in checks if c.report is not None]
    checked = feasibility_summary(reports) if reports else None
    notes = [n for p in pieces for n in p.notes]
    log.info(
        "leg %d to %s: %s, %.1f m, %.1f s%s",
        index,
        where,
        result.status if result else "vertical",
        sum(p.length_m for p in pieces),
        sum(p.duration_s for p in pieces),
        f" ({'; '.join(notes)})" if notes else "",
    )
    if checked is not None:
        log.info(
            "leg %d: closed loop %s, stretch x%.3g, max |delta| %.2f, tracking error max %.2f m "
            "RMS %.2f m (check %.0f ms)",
            index,
            "feasible" if checked["feasible"] else "INFEASIBLE",
            checked["stretch"],
            checked["max_abs_delta"],
            checked["max_tracking_error_m"],
            checked["rms_tracking_error_m"],
            1e3 * checked["check_s"],
        )
    return LegPlan(
        index,
        waypoint,
        start,
        goal,
        result,
        np.vstack([start[None, :], path]),
        TrajectoryChain(pieces),
        slab,
        notes,
        checked,
    )


def plan_mission(
    local_mission, start_ned_m, *, pipeline: TrajectoryPipeline, settings: FlightPlanSettings, rng: np.random.Generator
) -> list[LegPlan]:
    """Plan every leg after the takeoff, in flight order; the first leg starts at ``start_ned_m``.

    The takeoff itself is the vehicle's (MAV_CMD_NAV_TAKEOFF); legs start at its altitude.
    Raises ``MissionError`` naming the first unreachable item; nothing is flown then. Every
    leg goes through ``pipeline`` (with a closed-loop checker, every leg is checked and
    stretched where needed).
    """
    legs: list[LegPlan] = []
    start = np.asarray(start_ned_m, dtype=float)
    for waypoint in local_mission.waypoints:
        if waypoint.kind == "takeoff":
            continue
        leg = plan_leg(len(legs), waypoint, start, local_mission.world, pipeline=pipeline, settings=settings, rng=rng)
        if leg is not None:
            legs.append(leg)
            start = leg.goal_ned_m
    return legs
