"""The leg's world widened for a decision: the airspace (room above and below for escapes and
alternatives) and the planning slab (replans), each containing the reference.

Both derive from the leg's world and the reference's position. Rebuilding them costs ~3 ms per
decision step in a cluttered benchmark world (30 obstacles: the grid index is rebuilt), so a
small memo (per process, bounded) keeps the last widened world of each leg world, keyed by the
leg's ``world_key`` (which travels with the leg to a worker process, unlike the world's
identity), and reuses it while the points stay inside its down bounds.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from companion.threats.decision.alternatives import airspace_for
from companion.world import World

__all__ = ["airspace", "planning_slab", "MEMO_SIZE"]

#: Widened worlds kept (a few leg worlds, each as a slab and an airspace or two: the manned
#: traffic's has more room).
MEMO_SIZE = 12

_memo: OrderedDict[tuple[str, str], tuple[tuple, World]] = OrderedDict()


def airspace(world: World, world_key: str, points, settings, room_m: float | None = None) -> World:
    """``world`` widened to contain ``points`` with ``room_m`` (default
    ``settings.vertical_room_m``) above and below, never lower than ``settings.min_altitude_m``
    (``ThreatSettings``)."""
    room = settings.vertical_room_m if room_m is None else float(room_m)
    return _widened(
        world,
        world_key,
        f"airspace {room:g}",
        points,
        lambda: airspace_for(world, points, room, -settings.min_altitude_m),
    )


def planning_slab(world: World, world_key: str, points) -> World:
    """``world`` (the leg's thin slab) widened to contain ``points``."""
    return _widened(world, world_key, "slab", points, lambda: airspace_for(world, points))


def _signature(world: World) -> tuple:
    """What a key's world must still match (a cheap guard against a key reused for another world)."""
    return (world.dim, tuple(world.bounds_min), tuple(world.bounds_max), len(world.obstacles), world.margin_m)


def _widened(world: World, world_key: str, kind: str, points, build) -> World:
    """The memoised widened world, rebuilt when a point leaves its down bounds."""
    key = (world_key, kind)
    entry = _memo.get(key)
    downs = np.atleast_2d(np.asarray(points, dtype=float))[:, -1]
    if (
        entry is not None
        and entry[0] == _signature(world)
        and (world.dim != 3 or (np.all(downs >= entry[1].bounds_min[2]) and np.all(downs <= entry[1].bounds_max[2])))
    ):
        _memo.move_to_end(key)
        return entry[1]
    widened = build()
    _memo[key] = (_signature(world), widened)
    _memo.move_to_end(key)
    while len(_memo) > MEMO_SIZE:
        _memo.popitem(last=False)
    return widened
