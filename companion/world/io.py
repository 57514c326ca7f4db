"""World files: TOML or JSON in local NED metres (north, east[, down]).

Format (TOML; JSON has the same keys)::

    [world]
    name = "paper 2D"            # optional
    bounds_min = [0.0, 0.0]       # 2 numbers -> 2D world, 3 -> 3D (north, east, down)
    bounds_max = [100.0, 100.0]
    margin_m = 1.0                # optional, default 0: inflation of every obstacle
    start = [0.0, 0.0]            # optional defaults for `companion plan`
    goal = [99.0, 99.0]

    [[obstacles]]
    type = "disc"                 # disc | sphere | cylinder | box | prism
    center = [20.0, 30.0]
    radius = 5.0

    [[obstacles]]
    type = "prism"                # polygon extruded vertically (fence exclusion zone)
    vertices = [[40, 40], [60, 40], [50, 60]]
    alt_min = 0.0                 # or down_min / down_max (down = -altitude); optional
    alt_max = 60.0

``cylinder`` takes ``center`` (north, east), ``radius`` and the same optional vertical limits;
``box`` takes ``min`` and ``max`` corners. Errors name the file and the key at fault (for
example ``obstacles[3].radius``) or, for a syntax error, the line.

Map files in longitude/latitude are read too, by suffix: ``.geojson`` (or a ``.json`` whose top
level has a GeoJSON ``type``) through :mod:`companion.world.geojson`, ``.kml`` through
:mod:`companion.world.kml`; their features become obstacles in local NED about a home
(:mod:`companion.world.mapdata`), which the caller gives (``home_lla``) or the file does.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import WorldError
from companion.world.obstacles import Obstacle
from companion.world.polyhedral_obstacles import Box, Prism
from companion.world.round_obstacles import Cylinder, Disc, Sphere
from companion.world.world import World

__all__ = ["WorldFile", "load_world", "read_world_file", "world_from_dict", "world_to_dict", "dumps_world_toml"]

_WORLD_KEYS = {"name", "description", "bounds_min", "bounds_max", "margin_m", "start", "goal"}
_OBSTACLE_KEYS = {
    "disc": {"center", "radius"},
    "sphere": {"center", "radius"},
    "cylinder": {"center", "radius", "down_min", "down_max", "alt_min", "alt_max"},
    "box": {"min", "max"},
    "prism": {"vertices", "down_min", "down_max", "alt_min", "alt_max"},
}


@dataclass(frozen=True)
class WorldFile:
    """A world file's content: the world plus optional name and default start/goal (d,);
    ``home_lla`` (lat_deg, lon_deg, alt_m AMSL) is the origin of a map file's local frame
    (None for a TOML/JSON world, already in local NED)."""

    world: World
    name: str
    start: tuple | None
    goal: tuple | None
    home_lla: tuple | None = None


def _require(table: dict, key: str, where: str):
    if key not in table:
        raise WorldError(f"{where}.{key}: missing")
    return table[key]


def _vector(value, where: str, dim: int | None = None) -> tuple:
    if not isinstance(value, (list, tuple)) or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        raise WorldError(f"{where}: expected a list of numbers, got {value!r}")
    if dim is not None and len(value) != dim:
        raise WorldError(f"{where}: expected {dim} numbers, got {len(value)}")
    if not all(math.isfinite(float(v)) for v in value):
        raise WorldError(f"{where}: numbers must be finite, got {value!r}")
    return tuple(float(v) for v in value)


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WorldError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _vertical_limits(table: dict, where: str) -> tuple[float, float]:
    has_down = "down_min" in table or "down_max" in table
    has_alt = "alt_min" in table or "alt_max" in table
    if has_down and has_alt:
        raise WorldError(f"{where}: give either down_min/down_max or alt_min/alt_max, not both")
    if has_alt:
        alt_lo = _number(table.get("alt_min", -math.inf), f"{where}.alt_min")
        alt_hi = _number(table.get("alt_max", math.inf), f"{where}.alt_max")
        if not alt_lo < alt_hi:
            raise WorldError(f"{where}.alt_max: must exceed alt_min, got {alt_hi} <= {alt_lo}")
        return -alt_hi, -alt_lo
    lo = _number(table.get("down_min", -math.inf), f"{where}.down_min")
    hi = _number(table.get("down_max", math.inf), f"{where}.down_max")
    if not lo < hi:
        raise WorldError(f"{where}.down_max: must exceed down_min, got {hi} <= {lo}")
    return lo, hi


def _obstacle_from_dict(table, where: str, dim: int) -> Obstacle:
    if not isinstance(table, dict):
        raise WorldError(f"{where}: expected a table, got {table!r}")
    kind = _require(table, "type", where)
    if kind not in _OBSTACLE_KEYS:
        raise WorldError(f"{where}.type: expected one of {', '.join(sorted(_OBSTACLE_KEYS))}, got {kind!r}")
    unknown = set(table) - _OBSTACLE_KEYS[kind] - {"type", "name"}
    if unknown:
        raise WorldError(f"{where}.{sorted(unknown)[0]}: unknown key for a {kind}")
    try:
        if kind == "disc":
            return Disc(
                _vector(_require(table, "center", where), f"{where}.center", 2),
                _number(_require(table, "radius", where), f"{where}.radius"),
            )
        if kind == "sphere":
            return Sphere(
                _vector(_require(table, "center", where), f"{where}.center", 3),
                _number(_require(table, "radius", where), f"{where}.radius"),
            )
        if kind == "cylinder":
            lo, hi = _vertical_limits(table, where)
            return Cylinder(
                _vector(_require(table, "center", where), f"{where}.center", 2),
                _number(_require(table, "radius", where), f"{where}.radius"),
                lo,
                hi,
            )
        if kind == "box":
            return Box(
                _vector(_require(table, "min", where), f"{where}.min", dim),
                _vector(_require(table, "max", where), f"{where}.max", dim),
            )
        verts = _require(table, "vertices", where)
        if not isinstance(verts, list):
            raise WorldError(f"{where}.vertices: expected a list of [north, east] pairs")
        pts = [_vector(v, f"{where}.vertices[{i}]", 2) for i, v in enumerate(verts)]
        lo, hi = _vertical_limits(table, where)
        return Prism(tuple(pts), lo, hi)
    except WorldError as exc:
        msg = str(exc)
        if msg.startswith(where):
            raise
        raise WorldError(f"{where}: {msg}") from None


def world_from_dict(data, source: str = "world") -> WorldFile:
    """Build a :class:`WorldFile` from a parsed mapping; errors name ``source`` and the key."""
    if not isinstance(data, dict):
        raise WorldError(f"{source}: expected a table at the top level")
    unknown = set(data) - {"world", "obstacles"}
    if unknown:
        raise WorldError(f"{source}: {sorted(unknown)[0]}: unknown top-level key (expected world, obstacles)")
    head = data.get("world")
    if not isinstance(head, dict):
        raise WorldError(f"{source}: world: missing [world] table")
    bad = set(head) - _WORLD_KEYS
    if bad:
        raise WorldError(f"{source}: world.{sorted(bad)[0]}: unknown key")
    try:
        lo = _vector(_require(head, "bounds_min", "world"), "world.bounds_min")
        if len(lo) not in (2, 3):
            raise WorldError(f"world.bounds_min: expected 2 or 3 numbers, got {len(lo)}")
        dim = len(lo)
        hi = _vector(_require(head, "bounds_max", "world"), "world.bounds_max", dim)
        margin = _number(head.get("margin_m", 0.0), "world.margin_m")
        start = _vector(head["start"], "world.start", dim) if "start" in head else None
        goal = _vector(head["goal"], "world.goal", dim) if "goal" in head else None
        obs_list = data.get("obstacles", [])
        if not isinstance(obs_list, list):
            raise WorldError("obstacles: expected an array of tables ([[obstacles]])")
        obstacles = [_obstacle_from_dict(t, f"obstacles[{i}]", dim) for i, t in enumerate(obs_list)]
        try:
            world = World(obstacles, lo, hi, margin)
        except WorldError as exc:
            msg = str(exc)
            if msg.startswith(("bounds_", "margin_m")):
                msg = "world." + msg
            raise WorldError(msg) from None
    except WorldError as exc:
        raise WorldError(f"{source}: {exc}") from None
    name = head.get("name", Path(source).stem)
    return WorldFile(world=world, name=str(name), start=start, goal=goal)


_MAP_SUFFIXES = (".geojson", ".kml")


def _read_text(p: Path) -> str:
    try:
        return p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or exc
        raise WorldError(f"{p}: cannot read world file ({reason})") from None


def _is_geojson(data) -> bool:
    """Whether parsed JSON is GeoJSON (a top-level ``type``) rather than a JSON world file."""
    return isinstance(data, dict) and "type" in data and "world" not in data


def _map_world_file(doc, home_lla, ground_alt_m) -> WorldFile:
    """A map document's world about the home (``companion.world.mapdata``)."""
    from companion.world.mapdata import map_world

    world, frame, start, goal = map_world(doc, home_lla, ground_alt_m)
    return WorldFile(
        world=world, name=doc.name, start=start, goal=goal, home_lla=(frame.lat0_deg, frame.lon0_deg, frame.alt0_m)
    )


def _read_map_document(p: Path, text: str, data=None):
    """The :class:`~companion.world.mapdata.MapDocument` of a GeoJSON or KML file."""
    if p.suffix.lower() == ".kml":
        from companion.world.kml import parse_kml

        return parse_kml(text.encode("utf-8"), str(p), p.stem)
    from companion.world.geojson import parse_geojson, parse_geojson_text

    if data is not None:
        return parse_geojson(data, str(p), p.stem)
    return parse_geojson_text(text, str(p), p.stem)


def read_world_file(path, home_lla: tuple | None = None, ground_alt_m=None) -> WorldFile:
    """Read a world file: ``.toml`` or ``.json`` in local NED (the module docstring gives the
    format), or a ``.geojson`` / ``.kml`` map file in longitude/latitude.

    Parameters
    ----------
    path : path
    home_lla : (lat_deg, lon_deg, alt_m AMSL), optional
        The local frame's origin for a map file (default: the file's ``companion.home``);
        ignored by a TOML/JSON world.
    ground_alt_m : callable, optional
        ``ground_alt_m(lat_deg (K,), lon_deg (K,)) -> (K,)`` metres AMSL, the ground under a
        map feature (default: the home's altitude).
    """
    p = Path(path)
    text = _read_text(p)
    if p.suffix.lower() in _MAP_SUFFIXES:
        return _map_world_file(_read_map_document(p, text), home_lla, ground_alt_m)
    if p.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise WorldError(f"{p}: line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
        if _is_geojson(data):
            return _map_world_file(_read_map_document(p, text, data), home_lla, ground_alt_m)
    else:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise WorldError(f"{p}: {exc}") from None
    return world_from_dict(data, str(p))


def load_world(path, home_lla: tuple | None = None, ground_alt_m=None) -> World:
    """Load a world file (TOML, JSON, GeoJSON or KML: :func:`read_world_file`) and return its
    :class:`World`."""
    return read_world_file(path, home_lla, ground_alt_m).world


def world_to_dict(world: World, name: str | None = None, start=None, goal=None) -> dict:
    """Inverse of :func:`world_from_dict` (JSON-serialisable)."""
    head: dict = {}
    if name:
        head["name"] = name
    head["bounds_min"] = world.bounds_min.tolist()
    head["bounds_max"] = world.bounds_max.tolist()
    head["margin_m"] = world.margin_m
    if start is not None:
        head["start"] = [float(v) for v in np.asarray(start)]
    if goal is not None:
        head["goal"] = [float(v) for v in np.asarray(goal)]
    return {"world": head, "obstacles": [ob.to_dict() for ob in world.obstacles]}


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(round(v, 6))
    return repr(v)


def dumps_world_toml(world: World, name: str | None = None, start=None, goal=None) -> str:
    """The world as TOML text in the world-file format."""
    data = world_to_dict(world, name, start, goal)
    lines = ["[world]"] + [f"{k} = {_toml_value(v)}" for k, v in data["world"].items()]
    for ob in data["obstacles"]:
        lines += ["", "[[obstacles]]"] + [f"{k} = {_toml_value(v)}" for k, v in ob.items()]
    return "\n".join(lines) + "\n"
