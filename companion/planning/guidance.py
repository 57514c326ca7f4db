"""GART step 2, ``attract``: the paper's bidirectional potential acting on a sample.

Inside an inflated obstacle the sample is repelled to just outside the surface (by
``repel_offset_m``); outside, each obstacle within ``influence_m`` attracts it towards its
surface with a force ``k / c`` inversely proportional to the clearance ``c`` (capped at ``c / 2``
so it never crosses the surface); the goal always attracts it by ``goal_gain_m``. The total
displacement is capped at ``max_guidance_m``. Below 128 obstacles every obstacle is scanned; with
more, only those listed for the sample's grid cell. A world of few discs/spheres, vertical
cylinders and prisms (the usual case) is scanned by one compiled kernel (numba,
:func:`attract_to_balls`) doing the scalar code's floating-point operations in the same order
(the balls in closed form, then the other obstacles with their exact ``sdf`` and its
central-difference gradient, :meth:`~companion.world.obstacles.Obstacle.gradient`), so the
guided sample is the same.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion.planning.settings import GartSettings
from companion.world import obstacle_kernels as okern
from companion.world.segments import ball_table, compiled_for

__all__ = ["Guidance"]

_SCAN_ALL_OBSTACLES_BELOW = 128  # guidance scans every obstacle below this count, else grid cells


class Guidance:
    """The potential of ``world``'s obstacles and of ``goal`` (see the module docstring).

    Parameters
    ----------
    world : World
    goal : tuple of d floats
    settings : GartSettings
    """

    def __init__(self, world, goal: tuple, settings: GartSettings):
        self.world = world
        self.goal = goal
        self.s = settings
        self.dim = world.dim
        self.lo = tuple(world.bounds_min.tolist())
        self.hi = tuple(world.bounds_max.tolist())
        self.margin = world.margin_m
        self.scan_all = len(world.obstacles) <= self.SCAN_ALL_BELOW
        self.others = world.non_ball_obstacles
        self.compiled = self.scan_all and compiled_for(world)
        self.space = okern.space_of(world) if self.compiled else None
        self.ball_rows = self.ball_rows_of(world, settings.influence_m)
        self.balls = tuple(tuple(row) for row in self.ball_rows.tolist())

    SCAN_ALL_BELOW = _SCAN_ALL_OBSTACLES_BELOW

    @staticmethod
    def ball_rows_of(world, influence_m: float) -> np.ndarray:
        """(N, d + 2) rows ``(centre..., reach^2, r)`` of the inflated balls, reach = r + influence.

        The skip test needs no arithmetic then; memoised per world and influence.
        """
        key = ("guidance_ball_rows", influence_m)
        rows = world._memo.get(key)
        if rows is None:
            d = world.dim
            rows = ball_table(world).copy()  # (centre..., r^2, r)
            reach = rows[:, d + 1] + influence_m
            rows[:, d] = reach * reach
            world._memo[key] = rows
        return rows

    def attract(self, p: tuple) -> tuple:
        """Sample ``p`` moved by the potential, clamped to the bounds."""
        s = self.s
        if self.compiled:
            out = attract_to_balls(
                np.array(p),
                self.goal,
                self.lo,
                self.hi,
                self.ball_rows,
                self.space,
                s.influence_m,
                s.obstacle_gain_m2,
                s.repel_offset_m,
                s.goal_gain_m,
                s.max_guidance_m,
            )
            return tuple(out.tolist())
        force = [0.0] * self.dim
        if self.scan_all:
            balls, others = self.balls, self.others  # few obstacles: a plain scan is cheapest
        else:
            balls = ()
            others = self.world.obstacles_acting_on_cell(self.world.cell_of(p), s.influence_m + self.margin)
        if balls:
            if self.dim == 2:
                self._balls_2d(p, balls, force)
            else:
                self._balls_3d(p, balls, force)
        if others:
            self._others(p, others, force)
        to_goal = [g - x for g, x in zip(self.goal, p)]
        dist_goal = math.sqrt(sum(v * v for v in to_goal))
        if dist_goal > 1e-9:
            k = min(s.goal_gain_m, dist_goal) / dist_goal
            for i in range(self.dim):
                force[i] += k * to_goal[i]
        norm = math.sqrt(sum(f * f for f in force))
        if norm > s.max_guidance_m:
            scale = s.max_guidance_m / norm
            force = [f * scale for f in force]
        return tuple(min(max(x + f, l), h) for x, f, l, h in zip(p, force, self.lo, self.hi))

    def _others(self, p: tuple, others, force: list) -> None:
        """Add the potential of general obstacles (signed distance and its gradient)."""
        s = self.s
        margin, influence, gain, repel = self.margin, s.influence_m, s.obstacle_gain_m2, s.repel_offset_m
        for ob in others:
            c = ob.sdf(p) - margin
            if c >= influence:
                continue
            g = ob.gradient(p)
            # inside: repel out of the inflated obstacle; outside: attract towards its surface
            mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
            for i in range(self.dim):
                force[i] += mag * g[i]

    def _balls_2d(self, p: tuple, balls: tuple, force: list) -> None:
        """Add the potential of the discs ``balls`` at ``p`` to ``force``."""
        gain, repel = self.s.obstacle_gain_m2, self.s.repel_offset_m
        x, y = p
        for cx, cy, reach2, r in balls:
            dx, dy = x - cx, y - cy
            if dx * dx + dy * dy >= reach2:
                continue
            n = math.sqrt(dx * dx + dy * dy)
            c = n - r
            mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
            if n > 1e-12:
                force[0] += mag * dx / n
                force[1] += mag * dy / n
            else:
                force[0] += mag

    def _balls_3d(self, p: tuple, balls: tuple, force: list) -> None:
        """Add the potential of the spheres ``balls`` at ``p`` to ``force``."""
        gain, repel = self.s.obstacle_gain_m2, self.s.repel_offset_m
        x, y, z = p
        for cx, cy, cz, reach2, r in balls:
            dx, dy, dz = x - cx, y - cy, z - cz
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= reach2:
                continue
            n = math.sqrt(d2)
            c = n - r
            mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
            if n > 1e-12:
                force[0] += mag * dx / n
                force[1] += mag * dy / n
                force[2] += mag * dz / n
            else:
                force[0] += mag


@njit(cache=True)
def _others_force(p, space, influence: float, gain: float, repel: float, force) -> None:
    """:meth:`Guidance._others` over the world's cylinders and prisms (``space``, in their order)."""
    d = p.shape[0]
    margin = space[8]
    reach = influence + margin + space[10]  # beyond: c > influence surely (obstacle_kernels)
    h = 1e-3
    up = np.empty(d)
    down = np.empty(d)
    g = np.empty(d)
    for j in range(space[4].shape[0]):
        if okern.box_gap(j, p[0], p[1], p[0], p[1], space) > reach:
            continue
        c = okern.other_sdf(j, p, space) - margin
        if c >= influence:
            continue
        for i in range(d):  # Obstacle.gradient: central differences, 1 mm
            up[:] = p
            down[:] = p
            up[i] = p[i] + h
            down[i] = p[i] - h
            g[i] = (okern.other_sdf(j, up, space) - okern.other_sdf(j, down, space)) / (2 * h)
        n2 = 0.0
        for i in range(d):
            n2 += g[i] * g[i]
        n = math.sqrt(n2)
        if n < 1e-12:
            for i in range(d):
                g[i] = 1.0 if i == 0 else 0.0
        else:
            for i in range(d):
                g[i] = g[i] / n
        mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
        for i in range(d):
            force[i] += mag * g[i]


@njit(cache=True)
def attract_to_balls(
    p,
    goal,
    lo,
    hi,
    balls: np.ndarray,
    space,
    influence: float,
    gain: float,
    repel: float,
    goal_gain: float,
    max_guidance: float,
) -> np.ndarray:
    """:meth:`Guidance.attract` for a world of the compiled case: the moved sample, shape (d,).

    ``p`` (d,) array; ``balls`` (N, d + 2) rows ``(centre..., (r + influence)^2, r)``; ``space``
    the world's obstacles (:func:`~companion.world.obstacle_kernels.space_of`: its cylinders and
    prisms are used). The arithmetic is that of the scalar methods, term by term.
    """
    d = balls.shape[1] - 2
    force = np.zeros(d)
    delta = np.empty(d)
    for j in range(balls.shape[0]):
        delta[0] = p[0] - balls[j, 0]
        d2 = delta[0] * delta[0]
        for k in range(1, d):
            delta[k] = p[k] - balls[j, k]
            d2 += delta[k] * delta[k]
        if d2 >= balls[j, d]:
            continue
        n = math.sqrt(d2)
        c = n - balls[j, d + 1]
        mag = -c + repel if c <= 0.0 else -min(gain / c, 0.5 * c)
        if n > 1e-12:
            for k in range(d):
                force[k] += mag * delta[k] / n
        else:
            force[0] += mag
    if space[4].shape[0]:
        _others_force(p, space, influence, gain, repel, force)
    for k in range(d):
        delta[k] = goal[k] - p[k]
    s2 = delta[0] * delta[0]
    for k in range(1, d):
        s2 += delta[k] * delta[k]
    dist_goal = math.sqrt(s2)
    if dist_goal > 1e-9:
        g = min(goal_gain, dist_goal) / dist_goal
        for k in range(d):
            force[k] += g * delta[k]
    f2 = force[0] * force[0]
    for k in range(1, d):
        f2 += force[k] * force[k]
    norm = math.sqrt(f2)
    if norm > max_guidance:
        scale = max_guidance / norm
        for k in range(d):
            force[k] = force[k] * scale
    out = np.empty(d)
    for k in range(d):
        out[k] = min(max(p[k] + force[k], lo[k]), hi[k])
    return out
