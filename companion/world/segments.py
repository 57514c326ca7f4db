"""Exact segment tests outside the world's grid walk: batched (numpy) and compiled (numba).

Path shortcutting asks, from each waypoint, whether each later waypoint can be joined by a free
straight edge. The scalar :meth:`~companion.world.world.World.segment_free` walks the index grid
along each segment in Python, which costs tens of microseconds for a segment crossing the
world; here every segment is tested against every disc/sphere at once, with the same closed-form
distance (closest point clamped to the segment) and the same floating-point operations, so the
answers equal the scalar ones exactly. Other obstacles (boxes, cylinders, prisms) are tested
with their own exact ``segment_distance`` on the segments that clear the balls.

The planner's inner loop asks one segment at a time; :func:`segment_test` gives it a compiled
test against every obstacle (numba, :func:`companion.world.obstacle_kernels.segment_clear`) for
worlds of discs/spheres, vertical cylinders and prisms (:func:`compiled_for`), which at tens of
obstacles costs less than the Python grid walk of
:meth:`~companion.world.world.World.segment_free`. It uses the scalar methods' arithmetic in the
same order (no fused multiply-add), so its answers are the same booleans.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from companion.world import obstacle_kernels as okern
from companion.world.obstacle_kernels import ball_arrays, ball_table

__all__ = ["segments_free_from", "segments_clear", "segment_test", "ball_arrays", "ball_table", "compiled_for"]

_COMPILED_UP_TO_BALLS = 256  # above, the grid walk visits fewer obstacles than a full scan
_COMPILED_UP_TO_OTHERS = 64  # cylinders and prisms


def segments_free_from(world, a: tuple, ends: list) -> list[bool]:
    """``[world.segment_free(a, b) for b in ends]``, computed in one pass.

    Parameters
    ----------
    world : World
    a : tuple of d floats
        Common start (m).
    ends : list of tuple of d floats
        K end points (m).

    Returns
    -------
    list of K bool
        True where segment ``a b`` stays inside the bounds and clear of every inflated obstacle.
    """
    if not ends:
        return []
    if compiled_for(world):  # balls, cylinders and prisms: compiled
        free = segments_clear(
            np.array(a, dtype=float), np.array(ends, dtype=float).reshape(-1, world.dim), okern.space_of(world)
        )
        return free.tolist()
    if not world.in_bounds(a):
        return [False] * len(ends)
    d = world.dim
    centres, r2 = ball_arrays(world)
    b = np.array(ends, dtype=float).reshape(-1, d)
    delta = [(b[:, k] - a[k])[:, None] for k in range(d)]  # (K, 1) per axis
    l2 = delta[0] * delta[0]
    num = (centres[:, 0] - a[0]) * delta[0]
    for k in range(1, d):
        l2 = l2 + delta[k] * delta[k]
        num = num + (centres[:, k] - a[k]) * delta[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(l2 > 0.0, num / l2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    q = a[0] + t * delta[0] - centres[:, 0]
    q2 = q * q
    for k in range(1, d):
        q = a[k] + t * delta[k] - centres[:, k]
        q2 = q2 + q * q
    free = ~np.any(q2 <= r2, axis=1) if r2.size else np.ones(len(ends), dtype=bool)
    out = []
    others = world.non_ball_obstacles
    margin = world.margin_m
    for ok, end in zip(free.tolist(), ends):
        ok = ok and world.in_bounds(end)
        if ok and others:
            ok = all(ob.segment_distance(a, end) > margin for ob in others)
        out.append(ok)
    return out


@njit(cache=True)
def segments_clear(a, ends: np.ndarray, space) -> np.ndarray:
    """:func:`~companion.world.obstacle_kernels.segment_clear` from ``a`` to each row of ``ends`` (K, d): (K,) bool."""
    out = np.empty(ends.shape[0], dtype=np.bool_)
    for i in range(ends.shape[0]):
        out[i] = okern.segment_clear(a, ends[i], space)
    return out


def segment_test(world) -> Callable[[tuple, tuple], bool]:
    """``world.segment_free`` for tuples of d floats, compiled when :func:`compiled_for` says so.

    Other worlds (a ``Box``, more than 256 balls or 64 cylinders/prisms) get
    ``world.segment_free`` itself. (The arrays are memoised per world, the returned function is
    not: worlds may be pickled.)
    """
    if not compiled_for(world):
        return world.segment_free
    space = okern.space_of(world)
    clear = okern.segment_clear
    as_array = np.array

    def segment_free(a: tuple, b: tuple) -> bool:
        return clear(as_array(a, dtype=float), as_array(b, dtype=float), space)

    return segment_free


def compiled_for(world) -> bool:
    """True when the compiled tests apply: discs/spheres (at most 256), vertical cylinders and
    prisms (at most 64 together), no box."""
    others = world.non_ball_obstacles
    return (
        len(world.inflated_balls) <= _COMPILED_UP_TO_BALLS
        and len(others) <= _COMPILED_UP_TO_OTHERS
        and okern.supported(world)
    )
