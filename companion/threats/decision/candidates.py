"""The strategies' candidates: evade, hold, retime, switch, replan (DESIGN 7.4).

Each generator turns one ``Situation`` (the reference state, the tubes, the airspace and the
goal) into ``Candidate`` trajectories whose t = 0 is the situation's time, already judged by
the one space-time check (``judge``). The decision step (``step.decide``) chooses among them
with ``choice.choose``.

- ``evade_candidates``: the whole escape library in one vectorised check; the brake is the
  ``hold`` candidate (a hold is only chosen where its hover stays clear of every tube).
- ``retime_candidates``: the active path slowed or paused so that a mover passes first.
- ``switch_to_alternatives``: M-GART alternatives joined from the current setpoint.
- ``replan_candidates``: the pipeline's planner (GART) in the airspace with the pop-ups as
  obstacles; a mover is placed where the replanned trajectory would meet it (a short stretch of
  its track around that time, never its whole sweep), for a few rounds that share one budget
  (``replan_budget_s``); then the last replan retimed (wait, then go).

Joins and replans are inputs to the situation's ``TrajectoryPipeline`` (smoother, limits,
timer and checker: ``join.join_trajectory``); the escapes take their speed limit from it.

Pure: no I/O; randomness from ``rng``.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from companion.flight.pipeline import PlanBudget, PlanningProblem, TrajectoryPipeline
from companion.threats.decision.alternatives import airspace_for, switch_candidates
from companion.threats.decision.choice import Candidate, ReferenceState, rank_key
from companion.threats.decision.evasion import EscapeLimits, escape_library
from companion.threats.decision.join import HOVER_SPEED_M_S, join_trajectory, lead_length_m, turn_rad
from companion.threats.decision.kinds import CandidateKind
from companion.threats.decision.prediction import horizon_for, is_manned
from companion.threats.decision.retime import RetimedTrajectory, ramp_time_s
from companion.threats.decision.spacetime import STATIC_ID, check_candidates, reference_accel_bound_m_s2, sample_times
from companion.threats.settings import ThreatSettings
from companion.world import Disc, Sphere, World

__all__ = [
    "Situation",
    "check",
    "judge",
    "evade_candidates",
    "retime_candidates",
    "switch_to_alternatives",
    "replan_candidates",
    "positions_at",
    "meeting_obstacles",
    "check_candidates",
]

log = logging.getLogger(__name__)

#: Escapes may fly this much faster than the planned trajectories' speed limit.
ESCAPE_SPEED_FACTOR = 1.2
#: Half-length (s) of the stretch of a mover's track placed where a replan would meet it.
MEETING_HALF_S = 1.5
#: A replan's round needs at least this much of its budget left (s).
MIN_ROUND_S = 0.01


@dataclass(frozen=True)
class Situation:
    """What every generator needs for one decision (immutable).

    Attributes
    ----------
    ref : ReferenceState
    tubes : list of Tube
    world : World
        The airspace: the leg's world widened to contain the reference, with room above and
        below (checks, escapes, joins).
    planning_world : World
        The leg's thin slab widened to contain the reference (replans).
    goal_ned_m : ndarray, shape (d,)
    settings : ThreatSettings
    pipeline : TrajectoryPipeline
        Planner, smoother, limits, timer and checker of every new trajectory.
    lift_down_m : float or None
        Down coordinate of 2D candidates in a 3D flight.
    """

    ref: ReferenceState
    tubes: list
    world: World
    planning_world: World
    goal_ned_m: np.ndarray
    settings: ThreatSettings
    pipeline: TrajectoryPipeline
    lift_down_m: float | None = None

    @property
    def dim(self) -> int:
        return self.world.dim

    @property
    def check_horizon_s(self) -> float:
        """The checks' horizon (s): ``prediction.horizon_for`` the tubes."""
        return horizon_for(self.tubes, self.settings)

    @property
    def manned(self) -> bool:
        """A manned aircraft is among the tubes (its volumes and escapes apply)."""
        return any(map(is_manned, self.tubes))

    def step_s(self, step_s: float) -> float:
        """The check's sample step for a setting's ``step_s``: ``manned_step_s`` when longer and
        a manned aircraft is near."""
        return max(step_s, self.settings.manned_step_s) if self.manned else step_s

    def times(self, step_s: float, extra_s: float = 0.0) -> np.ndarray:
        """Check times over the horizon (plus ``extra_s``) every ``step_s(step_s)``."""
        return sample_times(self.ref.t_s, self.check_horizon_s + extra_s, self.step_s(step_s))

    @property
    def accel_bound_m_s2(self) -> float:
        return reference_accel_bound_m_s2(self.settings, self.pipeline.limits)

    def cruise_m_s(self) -> float:
        """Speed of the way back to the route (the planned trajectories' limit)."""
        return self.pipeline.limits.speed_m_s

    def escape_speed_m_s(self) -> float:
        """Escape speed: ``evade_speed_m_s``, at most 1.2 times the planned speed limit."""
        return min(self.settings.evade_speed_m_s, ESCAPE_SPEED_FACTOR * self.pipeline.limits.speed_m_s)


def positions_at(trajectory, start_t_s: float, t_s: np.ndarray, dim: int) -> np.ndarray:
    """Positions (K, dim) of ``trajectory`` (t = 0 at ``start_t_s``) at clock times (K,)."""
    pos = trajectory.sample(np.clip(t_s - start_t_s, 0.0, None))[0]
    return np.atleast_2d(pos)[:, :dim]


def check(sit: Situation, t_s: np.ndarray, pos: np.ndarray, *, static: bool = True):
    """``check_candidates`` with the situation's tubes, airspace and settings; ``static=False``
    for candidates on paths whose static clearance is known (keep, retime, planned joins)."""
    return check_candidates(
        t_s,
        pos,
        sit.tubes,
        sit.world if static else None,
        accel_bound_m_s2=sit.accel_bound_m_s2,
        static_slack_m=sit.settings.static_slack_m,
    )


def judge(sit: Situation, candidates: list[Candidate]) -> list[Candidate]:
    """Check planned candidates (t = 0 at the situation's time) against the tubes.

    Planned candidates (switch and replan joins) are built from segments checked free, corners
    repaired and the curve checked in the world by the trajectory pipeline (``join.py``), like
    the mission's legs: the static world is honoured by construction, and re-checking it with
    the chord bound would only mistake a path that grazes the safety margin for a conflict.
    """
    if not candidates:
        return candidates
    t = sit.times(sit.settings.check_step_s)
    pos = np.stack([positions_at(c.trajectory, sit.ref.t_s, t, sit.dim) for c in candidates])
    res = check(sit, t, pos, static=False)
    for i, c in enumerate(candidates):
        c.judged(res, i)
    return candidates


# ---------------------------------------------------------------------------- evade / hold
def _nearest_threat(sit: Situation) -> np.ndarray | None:
    if not sit.tubes:
        return None
    now = np.array([sit.ref.t_s])
    centers = [tube.center_at(now)[0] for tube in sit.tubes]
    d = [np.linalg.norm(c[:2] - sit.ref.pos_ned_m[:2]) for c in centers]
    return centers[int(np.argmin(d))]


#: Escapes whose static clearance is computed at a time, best first (see ``_judge_library``).
STATIC_CHUNK = 24


def _judge_library(sit: Situation, lib, remaining_to_goal_s: float, rank) -> list[tuple]:
    """The manoeuvres of ``lib`` judged: (candidate without its trajectory yet, library, index)
    triples, for every manoeuvre that may be the best and the brake (index 0).

    All are checked against the tubes in one vectorised pass; the static world (the costly
    part) only best first, in chunks, until the next unchecked one ranks no better than the
    best checked one: the static world can only make a candidate worse, so the others cannot
    win (branch and bound, exact).
    """
    s = sit.settings
    t = sit.times(s.evade_step_s)
    pos, duration = lib.positions(t - sit.ref.t_s)
    pos = pos[:, :, : sit.dim]
    tubes_only = check(sit, t, pos, static=False)
    back_m = np.linalg.norm(pos[:, -1] - sit.ref.pos_ned_m[None, : sit.dim], axis=1)
    to_goal = remaining_to_goal_s + duration + back_m / sit.cruise_m_s() + s.restart_s
    cands = [
        Candidate("evade", f"evade {lib.labels[i]}", None, float(to_goal[i]), ends_short=True).judged(tubes_only, i)
        for i in range(len(lib))
    ]
    order = sorted(range(1, len(cands)), key=lambda i: rank(cands[i]))
    checked: list[int] = []
    best = None
    while order and (best is None or rank(cands[order[0]]) < best):
        chunk, order = order[:STATIC_CHUNK], order[STATIC_CHUNK:]
        if not checked:
            chunk = [0] + chunk
        full = check(sit, t, pos[chunk])
        for j, i in enumerate(chunk):
            cands[i].judged(full, j)
        checked += chunk
        best = min(rank(cands[i]) for i in checked if i != 0) if len(checked) > 1 else None
    return [(cands[i], lib, i) for i in checked]


def evade_candidates(sit: Situation, remaining_to_goal_s: float, *, brake_only: bool = False) -> list[Candidate]:
    """The brake (as ``hold``) and the best escape manoeuvre, from the library judged in one
    vectorised pass; when none is clear, a local search around the four least bad.

    An escape ends in a hover away from the route: its time to the goal is the route's
    remaining time plus the manoeuvre, the way back to where it left the route at cruise speed
    and ``restart_s`` (stop, plan back, accelerate again).
    """
    s = sit.settings
    coasts = s.evade_coasts_s + s.manned_coasts_s if sit.manned else s.evade_coasts_s
    lim = EscapeLimits(
        sit.escape_speed_m_s(),
        s.evade_accel_m_s2,
        s.evade_climb_m_s,
        s.evade_descent_m_s,
        s.evade_vertical_accel_m_s2,
        coasts,
    )
    lib = escape_library(
        sit.ref.pos_ned_m, sit.ref.vel_ned_m_s, lim, vertical=sit.dim == 3, away_from=_nearest_threat(sit)
    )
    rank = lambda c: rank_key(c, s.clearance_weight_s_m, s.clearance_cap_m)  # noqa: E731
    judged = _judge_library(sit, lib, remaining_to_goal_s, rank)
    brake = judged[0]
    brake[0].kind, brake[0].label = CandidateKind.HOLD, "hold (brake to a hover)"
    picks = [brake]
    if not brake_only:
        escapes = sorted(judged[1:], key=lambda entry: rank(entry[0]))
        if not escapes[0][0].clear:
            least_bad = lib.refined([i for _, _, i in escapes[:4]])
            escapes = sorted(
                escapes[:4] + _judge_library(sit, least_bad, remaining_to_goal_s, rank),
                key=lambda entry: rank(entry[0]),
            )
        picks.append(escapes[0])
    out = []
    for cand, library, i in picks:
        cand.trajectory = library.manoeuvre(i, sit.ref.yaw_rad)
        cand.path_ned_m = cand.trajectory.sample(np.linspace(0.0, cand.trajectory.duration_s, 12))[0][:, : sit.dim]
        out.append(cand)
    return out


# ---------------------------------------------------------------------------- retime
def retime_candidates(
    sit: Situation, active, active_start_t_s: float, remaining_to_goal_s: float, ends_short: bool
) -> list[Candidate]:
    """The active reference slowed (``retime_rates``) or paused for each of ``retime_waits_s``."""
    s = sit.settings
    tau0 = min(max(sit.ref.t_s - active_start_t_s, 0.0), active.duration_s)
    remaining = active.duration_s - tau0
    if remaining < 0.5:
        return []
    look = tau0 + np.linspace(0.0, min(remaining, 10.0), 40)
    speed = float(np.max(np.linalg.norm(np.atleast_2d(active.sample(look)[1]), axis=1)))
    out = []
    for rate in s.retime_rates:
        ramp = ramp_time_s(rate, max(speed, 0.1), s.hold_decel_m_s2)
        for wait in s.retime_waits_s:
            traj = RetimedTrajectory(
                active, tau0, rate, wait, ramp, f"retime {'pause' if rate == 0 else f'x{rate:.1f}'} {wait:.1f} s"
            )
            out.append(Candidate("retime", traj.label, traj, remaining_to_goal_s + traj.delay_s, ends_short=ends_short))
    # one vectorised sampling of the base for every warp, over the horizon plus the longest
    # delay: a retime must not merely push a conflict beyond the horizon
    delay = max(c.trajectory.delay_s for c in out)
    t = sit.times(s.check_step_s, delay)
    taus = np.concatenate([c.trajectory.tau_at(t - sit.ref.t_s) for c in out])
    pos = np.atleast_2d(active.sample(taus)[0])[:, : sit.dim].reshape(len(out), t.size, sit.dim)
    res = check(sit, t, pos, static=False)  # on the active, checked path
    for i, c in enumerate(out):
        c.judged(res, i)
    return out


# ---------------------------------------------------------------------------- switch
def switch_to_alternatives(sit: Situation, alternatives) -> tuple[list[Candidate], dict]:
    """Joins to the alternatives' entry nodes, cheapest first, until one is clear or the
    budget (``max_candidates``, ``switch_budget_s``) is spent. Returns the candidates and why
    the others were dropped (counts)."""
    s = sit.settings
    t0 = time.perf_counter()
    d = sit.dim
    why: dict[str, int] = {}
    out = []
    entries = switch_candidates(alternatives, sit.ref.pos_ned_m[:d], s.switch_range_m, s.entry_spacing_m)
    for tried, (_cost, alt, i) in enumerate(entries):
        out_of_time = not sit.pipeline.reproducible and time.perf_counter() - t0 > s.switch_budget_s
        if tried >= s.max_candidates or out_of_time:
            break
        traj, poly = join_trajectory(
            sit.ref.pos_ned_m[:d],
            sit.ref.vel_ned_m_s[:d],
            alt.nodes_from(i),
            world=sit.world,
            pipeline=sit.pipeline,
            lift_down_m=sit.lift_down_m,
        )
        if traj is None:
            key = poly.split(" (")[0]
            why[key] = why.get(key, 0) + 1
            continue
        cand = judge(sit, [Candidate("switch", f"switch {alt.path_id}", traj, traj.duration_s, alt.path_id, poly)])[0]
        out.append(cand)
        if cand.clear:
            break
        why["meets a predicted threat"] = why.get("meets a predicted threat", 0) + 1
    return out, why


# ---------------------------------------------------------------------------- replan
def ball(center_ned_m, radius_m: float, dim: int):
    """A Disc (2D world) or Sphere (3D) obstacle standing for a threat."""
    center = tuple(float(x) for x in center_ned_m[:dim])
    return Sphere(center, radius_m) if dim == 3 else Disc(center, radius_m)


def _keeps_free(center: np.ndarray, radius: float, points, dim: int) -> bool:
    return all(np.linalg.norm(p[:dim] - center[:dim]) > radius for p in points)


def static_spheres(sit: Situation, keep_free) -> list:
    """The static tubes (pop-ups) as spheres, leaving out those around ``keep_free`` points."""
    out = []
    now = np.array([sit.ref.t_s])
    for tube in sit.tubes:
        if tube.speed_m_s > 0.05 or is_manned(tube):
            continue
        c, r = tube.center_at(now)[0], float(tube.radius_at(now)[0])
        if math.isfinite(r) and _keeps_free(c, r, keep_free, sit.dim):
            out.append(ball(c, r, sit.dim))
    return out


def meeting_spheres(sit: Situation, tube, t_meet_s: float, keep_free) -> list:
    """The stretch of a mover's track around the time ``t_meet_s`` a candidate would meet it."""
    times = t_meet_s + np.linspace(-MEETING_HALF_S, MEETING_HALF_S, 5)
    radius = float(tube.radius_at(np.array([t_meet_s + MEETING_HALF_S]))[0]) + 0.5
    if not math.isfinite(radius):  # the tube has ended by then
        return []
    return [ball(c, radius, sit.dim) for c in tube.center_at(times) if _keeps_free(c, radius, keep_free, sit.dim)]


def meeting_obstacles(sit: Situation, active, active_start_t_s: float, keep_free) -> list:
    """Pop-ups, and each mover's track around the time ``active`` comes closest to it (when
    closer than its radius plus ``switch_range_m / 4``): obstacles for the alternatives."""
    out = static_spheres(sit, keep_free)
    t = sit.times(sit.settings.check_step_s)
    pos = positions_at(active, active_start_t_s, t, sit.dim)
    for tube in sit.tubes:
        if tube.speed_m_s <= 0.05 or is_manned(tube):
            continue
        dist = np.linalg.norm(pos - tube.center_at(t)[:, : sit.dim], axis=1) - tube.radius_at(t)
        k = int(np.argmin(dist))
        if dist[k] < sit.settings.switch_range_m / 4:
            out += meeting_spheres(sit, tube, float(t[k]), keep_free)
    return out


def _replan_start(sit: Situation):
    """Start of the replan: the current position at a hover, else a lead along the velocity."""
    d = sit.dim
    p, v = sit.ref.pos_ned_m[:d], sit.ref.vel_ned_m_s[:d]
    speed = float(np.linalg.norm(v))
    if speed < HOVER_SPEED_M_S:
        return p, None
    u = v / speed
    turn = max(turn_rad(u, sit.goal_ned_m - p), sit.settings.replan_turn_rad)
    limits = sit.pipeline.limits
    lead = lead_length_m(min(speed, limits.speed_m_s), turn, limits, sit.pipeline.turn_kappa_1_m)
    return p + u * lead, lead


def replan_candidates(sit: Situation, *, rng: np.random.Generator, path_id: str) -> list[Candidate]:
    """Replans through time with the situation's pipeline (see the module docstring),
    cheapest-first rounds."""
    s = sit.settings
    d = sit.dim
    p, v = sit.ref.pos_ned_m[:d], sit.ref.vel_ned_m_s[:d]
    start, lead = _replan_start(sit)
    world = airspace_for(sit.planning_world, [p, start])
    if not world.in_bounds(p) or (lead is not None and not world.segment_free(p, start)):
        log.info("replan: the start or its stopping lead is outside the free space")
        return []
    keep = [p, start, sit.goal_ned_m]
    obstacles = static_spheres(sit, keep)
    out: list[Candidate] = []
    left_s = s.replan_budget_s
    for _ in range(s.replan_iterations):
        budget = round_budget(s, left_s)
        if budget is None:
            log.info("replan: its %.2f s budget is spent", s.replan_budget_s)
            break
        planning = world.with_threats(obstacles) if obstacles else world
        result = sit.pipeline.plan(PlanningProblem(planning, start, sit.goal_ned_m), budget, rng=rng)
        left_s -= sit.pipeline.search_time_s(result)
        if result.status != "exact":
            log.info("replan: GART %s", result.status)
            break
        nodes = result.path[1:] if lead is not None else result.path
        traj, poly = join_trajectory(
            p, v, nodes, world=planning, pipeline=sit.pipeline, lift_down_m=sit.lift_down_m, lead_m=lead
        )
        if traj is None:
            log.info("replan: %s", poly)
            break
        cand = judge(sit, [Candidate("replan", "replan", traj, traj.duration_s, path_id, poly)])[0]
        out.append(cand)
        if cand.clear or cand.conflict.threat_id == STATIC_ID:
            break
        tube = next(t for t in sit.tubes if t.threat_id == cand.conflict.threat_id)
        if is_manned(tube):  # a volume to keep out of in time, not an obstacle
            break
        obstacles = obstacles + meeting_spheres(sit, tube, cand.conflict.t_s, keep)
    if out and not any(c.clear for c in out) and lead is None:
        out += retimed_starts(sit, out[-1])  # from a hover: wait for the mover, then go
    return out


def round_budget(s: ThreatSettings, left_s: float) -> PlanBudget | None:
    """The search budget of a replan's next round, out of the ``left_s`` its rounds still share
    (``replan_budget_s`` in all): GART's ``gart_budget_s``, then a first path in
    ``gart_first_budget_s``, each cut to what is left; None when less than ``MIN_ROUND_S`` is."""
    if left_s < MIN_ROUND_S:
        return None
    search_s = min(s.gart_budget_s, left_s)
    first_s = min(s.gart_first_budget_s, left_s - search_s)
    return PlanBudget(search_s, first_path_s=first_s if first_s >= MIN_ROUND_S else None)


def retimed_starts(sit: Situation, cand: Candidate) -> list[Candidate]:
    """``cand`` (starting at rest) delayed by each wait of the settings: hover, then go."""
    waits = [w for w in sit.settings.retime_waits_s if w > 0]
    out = [
        Candidate(
            "replan",
            f"replan after {w:.1f} s",
            RetimedTrajectory(cand.trajectory, 0.0, 0.0, w, 1e-3),
            cand.time_to_goal_s + w,
            cand.path_id,
            cand.path_ned_m,
        )
        for w in waits
    ]
    return judge(sit, out)
