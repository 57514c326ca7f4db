"""Planning world: obstacles, bounds, safety margin and exact collision queries (paper 3.1).

See :class:`World` for the queries and :mod:`companion.world.io` for the world-file format.
"""

from companion.world.io import WorldFile, load_world, read_world_file, world_from_dict, world_to_dict
from companion.world.obstacles import Obstacle
from companion.world.pickling import restore_world, world_state  # registers World's reducer
from companion.world.polyhedral_obstacles import Box, Prism
from companion.world.round_obstacles import Cylinder, Disc, Sphere
from companion.world.world import World

__all__ = [
    "World",
    "Obstacle",
    "Disc",
    "Sphere",
    "Cylinder",
    "Box",
    "Prism",
    "load_world",
    "read_world_file",
    "world_from_dict",
    "world_to_dict",
    "WorldFile",
    "restore_world",
    "world_state",
]
