"""Worlds pickle: the planning worker processes (``companion.workers``) receive them.

``World`` is immutable (its ``__setattr__`` refuses every change once built) and has slots, so
the default unpickling cannot restore it. The reducer registered here (``copyreg``) sends the
obstacles, bounds, margin and grid index, and rebuilds the rest on arrival: the memoised
lookups start empty, the point test is bound again for the world's dimension.
"""

from __future__ import annotations

import copyreg

from companion.world.world import World

__all__ = ["world_state", "restore_world"]

#: Slots that are not sent: rebuilt by ``restore_world``.
REBUILT = ("point_free", "_memo", "_frozen")


def world_state(world: World) -> dict:
    """The slots of ``world`` that travel (everything but ``REBUILT``)."""
    return {name: getattr(world, name) for name in World.__slots__ if name not in REBUILT}


def restore_world(state: dict) -> World:
    """A ``World`` from ``world_state``'s output, frozen like a freshly built one."""
    world = World.__new__(World)
    for name, value in {**state, "_memo": {}}.items():
        object.__setattr__(world, name, value)
    object.__setattr__(world, "point_free", world._point_free_2d if world.dim == 2 else world._point_free_3d)
    object.__setattr__(world, "_frozen", True)
    return world


copyreg.pickle(World, lambda world: (restore_world, (world_state(world),)))
