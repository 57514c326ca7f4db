"""Public benchmark worlds of ``../shared/reference/ANCHORS.md`` (planning benchmarks).

Obstacles are discs (2D) or spheres (3D) with centres uniform in [0, 100]^d and radii uniform in
[r_min, r_max], drawn with ``numpy.random.RandomState(seed)`` centre first, then radius, for each
candidate; a candidate whose surface comes within 2 m of the start or the goal is redrawn.
Start is the origin, goal (99, 99) or (99, 99, 99); bounds [0, 100]^d; no safety margin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.world import World

__all__ = ["BenchWorld", "SPECS", "make_world", "BEST_KNOWN_COST"]


@dataclass(frozen=True)
class WorldSpec:
    dim: int
    n_obstacles: int
    r_min_m: float
    r_max_m: float


SPECS = {"2d": WorldSpec(2, 30, 3.0, 8.0), "3d_dense": WorldSpec(3, 60, 6.0, 14.0)}
#: Best known path length (m), any planner, from ANCHORS.md (median over seeds 0-19).
BEST_KNOWN_COST = {"2d": 142.2, "3d_dense": 171.9}
CLEARANCE_TO_ENDS_M = 2.0


@dataclass(frozen=True)
class BenchWorld:
    name: str
    seed: int
    world: World
    start: np.ndarray
    goal: np.ndarray


def make_world(name: str, seed: int) -> BenchWorld:
    """The benchmark world ``name`` ('2d' or '3d_dense') for ``seed`` (0..19 in the anchors)."""
    spec = SPECS[name]
    rs = np.random.RandomState(seed)
    start = np.zeros(spec.dim)
    goal = np.full(spec.dim, 99.0)
    centers, radii = [], []
    while len(centers) < spec.n_obstacles:
        c = rs.uniform(0.0, 100.0, spec.dim)
        r = rs.uniform(spec.r_min_m, spec.r_max_m)
        if np.linalg.norm(c - start) - r < CLEARANCE_TO_ENDS_M or np.linalg.norm(c - goal) - r < CLEARANCE_TO_ENDS_M:
            continue
        centers.append(c)
        radii.append(r)
    world = World.from_spheres(np.array(centers), np.array(radii), [0.0] * spec.dim, [100.0] * spec.dim)
    return BenchWorld(name, seed, world, start, goal)
