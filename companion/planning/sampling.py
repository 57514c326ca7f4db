"""GART step 1, ``sample``: the goal, a uniform point of the bounds, or an informed point.

Once a path of cost ``c_best`` exists, only points of the prolate hyperspheroid with foci start
and goal and transverse diameter ``c_best`` can still shorten it (Gammell et al., Informed
RRT*); :meth:`Sampler.sample` draws from it when ``informed`` is on.

Every random number comes from one :class:`RandomStream`, which draws uniforms from the
planner's ``numpy.random.Generator`` in batches. The batches grow (64, 128, ... 8192 values): a
first path needs a few hundred numbers, an anytime run hundreds of thousands, and numpy
delivers ``random(n)`` values in the same order whatever the batch size, so the stream (and the
planner's result for a seed) does not depend on it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RandomStream", "Sampler"]

_FIRST_BATCH = 64
_MAX_BATCH = 8192
_INFORMED_TRIES = 20


class RandomStream:
    """Uniform floats in [0, 1) from ``rng``, drawn in growing batches.

    Parameters
    ----------
    rng : numpy.random.Generator
    """

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.values: list[float] = []
        self.next = 0
        self.batch = _FIRST_BATCH

    def refill(self) -> None:
        """Replace the consumed batch by the next one (twice as long, up to 8192 values)."""
        self.values = self.draw_batch().tolist()
        self.next = 0

    def draw_batch(self) -> np.ndarray:
        """The next batch of the stream, (64, 128, ... 8192,) floats; the compiled planner reads it as an array."""
        values = self.rng.random(self.batch)
        self.batch = min(2 * self.batch, _MAX_BATCH)
        return values

    def __call__(self) -> float:
        """The next uniform number."""
        i = self.next
        if i >= len(self.values):
            self.refill()
            i = 0
        self.next = i + 1
        return self.values[i]


class Sampler:
    """Samples of GART's step 1 (goal bias, uniform, informed) over the box ``[lo, hi]``.

    Parameters
    ----------
    world : World
        For the bounds test of informed samples.
    start, goal : tuple of d floats
    goal_bias : float
        Probability of returning the goal itself.
    informed : bool
        Sample the informed set once a path exists.
    uniform : RandomStream
    """

    def __init__(self, world, start: tuple, goal: tuple, goal_bias: float, informed: bool, uniform: RandomStream):
        self.world = world
        self.goal = goal
        self.goal_bias = goal_bias
        self.informed = informed
        self.u = uniform
        self.dim = len(start)
        self.lo = tuple(world.bounds_min.tolist())
        self.span = tuple(h - l for l, h in zip(self.lo, world.bounds_max.tolist()))
        self.ellipse = ellipse_frame(start, goal)

    def sample(self, c_best_m: float) -> tuple[tuple, bool]:
        """A sample and whether it is the goal itself; ``c_best_m`` the best path length so far."""
        if self.u() < self.goal_bias:
            return self.goal, True
        if self.informed and c_best_m < math.inf:
            p = self.sample_informed(c_best_m)
            if p is not None:
                return p, False
        return self.sample_uniform(), False

    def sample_uniform(self) -> tuple:
        """A uniform point of the bounds."""
        u = self.u
        return tuple(l + u() * s for l, s in zip(self.lo, self.span))

    def sample_informed(self, c_best_m: float) -> tuple | None:
        """A uniform point of the prolate hyperspheroid with foci start/goal, diameter ``c_best_m``."""
        if self.ellipse is None:
            return None
        c_min, basis, centre = self.ellipse
        if c_best_m <= c_min:
            return None
        r_major = 0.5 * c_best_m
        r_minor = 0.5 * math.sqrt(c_best_m * c_best_m - c_min * c_min)
        u = self.u
        dim = self.dim
        for _ in range(_INFORMED_TRIES):
            while True:
                x = [2.0 * u() - 1.0 for _ in range(dim)]
                if sum(v * v for v in x) <= 1.0:
                    break
            p = list(centre)
            for k, b in enumerate(basis):
                scale = (r_major if k == 0 else r_minor) * x[k]
                for m in range(dim):
                    p[m] += scale * b[m]
            point = tuple(p)
            if self.world.in_bounds(point):
                return point
        return None


def ellipse_frame(start: tuple, goal: tuple):
    """``(c_min, basis, centre)`` of the informed set: focal distance, orthonormal rows, centre.

    ``basis`` (d lists of d floats) starts with the unit vector start -> goal (Gram-Schmidt on
    the coordinate axes for the others). None when start and goal coincide.
    """
    dim = len(start)
    a = [g - s for s, g in zip(start, goal)]
    c_min = math.sqrt(sum(x * x for x in a))
    if c_min < 1e-9:
        return None
    basis = [[x / c_min for x in a]]
    for e in range(dim):
        v = [1.0 if k == e else 0.0 for k in range(dim)]
        for b in basis:
            dot = sum(x * y for x, y in zip(v, b))
            v = [x - dot * y for x, y in zip(v, b)]
        n = math.sqrt(sum(x * x for x in v))
        if n > 1e-6:
            basis.append([x / n for x in v])
        if len(basis) == dim:
            break
    centre = tuple(0.5 * (s + g) for s, g in zip(start, goal))
    return c_min, basis, centre
