"""The helicopter's own missions in the campaign: one leg each, planned as ``companion run`` plans.

Each mission is one leg flown from a hover at its start (``companion.flight.plan.plan_leg``,
through the settings' trajectory pipeline, searches budgeted in iterations so that the leg is
the same on every machine). Their worlds (local NED metres, home at the origin):

========================  ==========================================================================
mission                   what
========================  ==========================================================================
``open``                  level at 20 m from (0, 0) to (180, 0); no obstacle
``cluttered-<seed>``      the same ends among 14 vertical cylinders (radius 2-5 m, seeded), which
                          the leg plans around
``fenced``                open air with two exclusion zones (prisms) beside the route, 8 m and
                          10 m from it: an evasion that turns into them breaks the fence
``climb`` / ``descend``   climbs from 15 m to 40 m (descends from 40 m to 15 m) at the start, then
                          level: the encounters from above and below meet it in the vertical part
``long``                  level at 100 m from (0, 0) to (700, 0), in a 5 km box (manned traffic)
========================  ==========================================================================

The planner's world keeps ``MARGIN_M`` from the obstacles; the judge uses the bare ones
(``Mission.obstacles``, ``Mission.fences``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.plan import plan_leg
from companion.mission.model import LocalWaypoint
from companion.world import Cylinder, World
from companion.world.polyhedral_obstacles import Prism

__all__ = ["Mission", "MISSION_KINDS", "build_mission", "mission_names", "speed_near", "MARGIN_M", "N_CLUTTERED"]

#: Margin the planner keeps from obstacles and fences (m).
MARGIN_M = 1.0
#: Seeds of the cluttered missions.
N_CLUTTERED = 8
MISSION_KINDS = ("open", "cluttered", "fenced", "climb", "descend", "long")
ACCEPTANCE_M = 3.0
SHORT_GOAL_N_M = 180.0
LONG_GOAL_N_M = 700.0
N_CYLINDERS = 14


@dataclass(frozen=True)
class Mission:
    """One campaign mission.

    Attributes
    ----------
    name : str
        ``open``, ``cluttered-3``, ``fenced``, ``climb``, ``descend`` or ``long``.
    legs : tuple of LegPlan
    world : World
        Where the companion plans (with ``MARGIN_M``).
    obstacles : tuple of Obstacle
        The bare obstacles (judging), fences apart.
    fences : tuple of Prism
        The bare exclusion zones.
    bounds_min_ned_m, bounds_max_ned_m : ndarray, shape (3,)
    """

    name: str
    legs: tuple
    world: World
    obstacles: tuple
    fences: tuple
    bounds_min_ned_m: np.ndarray
    bounds_max_ned_m: np.ndarray

    @property
    def goal_ned_m(self) -> np.ndarray:
        return self.legs[-1].goal_ned_m

    @property
    def start_yaw_rad(self) -> float:
        return float(self.legs[0].trajectory.yaw_rad(np.array([0.0]))[0])

    @property
    def duration_s(self) -> float:
        return float(sum(leg.trajectory.duration_s for leg in self.legs))


def _ends(kind: str) -> tuple[np.ndarray, np.ndarray]:
    if kind == "long":
        return np.array([0.0, 0.0, -100.0]), np.array([LONG_GOAL_N_M, 0.0, -100.0])
    if kind == "climb":
        return np.array([0.0, 0.0, -15.0]), np.array([SHORT_GOAL_N_M, 0.0, -40.0])
    if kind == "descend":
        return np.array([0.0, 0.0, -40.0]), np.array([SHORT_GOAL_N_M, 0.0, -15.0])
    return np.array([0.0, 0.0, -20.0]), np.array([SHORT_GOAL_N_M, 0.0, -20.0])


def _bounds(kind: str) -> tuple[np.ndarray, np.ndarray]:
    if kind == "long":
        return np.array([-2500.0, -2500.0, -600.0]), np.array([3700.0, 2500.0, -8.0])
    return np.array([-60.0, -80.0, -60.0]), np.array([240.0, 80.0, -5.0])


def _cylinders(seed: int, start: np.ndarray, goal: np.ndarray, down: tuple[float, float]) -> list:
    """Seeded vertical cylinders between the ends, none within 8 m of either end."""
    rng = np.random.default_rng([7411, seed])
    out: list = []
    while len(out) < N_CYLINDERS:
        centre = np.array([rng.uniform(20.0, 160.0), rng.uniform(-35.0, 35.0)])
        radius = float(rng.uniform(2.0, 5.0))
        if min(np.linalg.norm(centre - start[:2]), np.linalg.norm(centre - goal[:2])) - radius < 8.0:
            continue
        out.append(Cylinder((float(centre[0]), float(centre[1])), radius, *down))
    return out


def _fences() -> list:
    """Two exclusion zones beside the route (all altitudes)."""
    return [
        Prism(((60.0, 8.0), (120.0, 8.0), (120.0, 45.0), (60.0, 45.0))),
        Prism(((95.0, -10.0), (150.0, -10.0), (150.0, -50.0), (95.0, -50.0))),
    ]


def build_mission(name: str, settings, *, iterations_per_s: float) -> Mission:
    """The campaign mission ``name`` (``MISSION_KINDS``, ``cluttered-<seed>``), planned.

    Parameters
    ----------
    name : str
    settings : companion.config.Settings
        The companion's settings (its pipeline and flight settings plan the leg).
    iterations_per_s : float
        The searches' budget in iterations per second of their time budget.

    Raises
    ------
    ValueError
        An unknown mission name.
    """
    kind, _, seed_text = name.partition("-")
    if kind not in MISSION_KINDS or (kind == "cluttered") != bool(seed_text):
        raise ValueError(f"mission: expected one of {', '.join(MISSION_KINDS)} (cluttered-<seed>), got {name!r}")
    seed = int(seed_text) if seed_text else 0
    start, goal = _ends(kind)
    lo, hi = _bounds(kind)
    obstacles = _cylinders(seed, start, goal, (float(lo[2]), float(hi[2]))) if kind == "cluttered" else []
    fences = _fences() if kind == "fenced" else []
    world = World(obstacles + fences, lo, hi, margin_m=MARGIN_M)
    pipeline = TrajectoryPipeline.from_settings(
        settings.smoothing, settings.planning, iterations_per_s=iterations_per_s
    )
    waypoint = LocalWaypoint(1, "waypoint", goal, ACCEPTANCE_M, 0.0, None)
    leg = plan_leg(
        0, waypoint, start, world, pipeline=pipeline, settings=settings.flight, rng=np.random.default_rng([7412, seed])
    )
    leg = dataclasses.replace(leg, world=world)  # a replan may leave the leg's slab
    return Mission(name, (leg,), world, tuple(obstacles), tuple(fences), lo, hi)


def mission_names(kinds: tuple[str, ...]) -> tuple[str, ...]:
    """Every mission of ``kinds`` (the cluttered kind stands for its ``N_CLUTTERED`` seeds)."""
    names: list[str] = []
    for kind in kinds:
        names += [f"cluttered-{s}" for s in range(N_CLUTTERED)] if kind == "cluttered" else [kind]
    return tuple(names)


def speed_near(mission: Mission, t_s: float) -> float:
    """The nominal speed (m/s) at ``t_s`` of the mission."""
    v = mission.legs[0].trajectory.sample(np.array([t_s]))[1][0]
    return float(math.sqrt(float(v @ v)))
