"""GeoJSON map files (RFC 7946): a FeatureCollection of obstacles -> a :class:`MapDocument`.

Reading and checking only; the geometry is converted by :mod:`companion.world.mapdata`.
Coordinates are WGS-84 ``[longitude, latitude(, altitude)]`` degrees (the altitude of a
position is ignored: heights come from the properties). Per feature:

=====================================  ==============================================================
geometry                               properties
=====================================  ==============================================================
Polygon, MultiPolygon (buildings)      ``height`` (m above ground), else ``building:levels`` x 3 m;
                                       optional ``min_height`` (m), else ``building:min_level`` x 3 m
Point, MultiPoint (masts, trees)       ``radius`` (m) and the height as above
LineString, MultiLineString (walls)    ``width`` (m) and the height as above
=====================================  ==============================================================

Numbers may be JSON numbers or numeric strings, optionally ending in ``m`` (OpenStreetMap
exports give ``"12"`` or ``"12 m"``). The FeatureCollection may carry a foreign member
``companion`` (an object) with the world's settings::

    "companion": {"name": "yard", "home": [149.16523, -35.363261, 584.0],
                  "bounds": [149.1640, -35.3642, 149.1668, -35.3622],
                  "margin_m": 3.0, "ceiling_m": 60.0, "padding_m": 30.0, "default_height_m": 10.0,
                  "start": [149.16523, -35.363261, 10.0], "goal": [149.16523, -35.36191, 10.0]}

``home`` is a GeoJSON position (longitude, latitude, altitude m AMSL); ``bounds`` is in RFC
7946 bbox order (west, south, east, north); ``start`` and ``goal`` are positions with a height
above ground. Errors name the key at fault, e.g. ``features[3].properties.height: expected a
number > 0, got "tall"``; :func:`parse_geojson` prefixes the file.
"""

from __future__ import annotations

import json
import math
import re

from shapely.geometry import LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon
from shapely.validation import explain_validity

from companion.errors import WorldError
from companion.world.mapdata import DEFAULT_CEILING_M, DEFAULT_PADDING_M, MapDocument, MapFeature

__all__ = ["parse_geojson", "parse_geojson_text", "METRES_PER_LEVEL"]

METRES_PER_LEVEL = 3.0
_GEOMETRIES = ("Polygon", "MultiPolygon", "Point", "MultiPoint", "LineString", "MultiLineString")
_HEADER_KEYS = {"name", "home", "bounds", "margin_m", "ceiling_m", "padding_m", "default_height_m", "start", "goal"}
_NUMBER_RE = re.compile(r"^\s*([-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?)\s*(m)?\s*$")
_WGS84_CRS = ("CRS84", "EPSG::4326", "EPSG:4326")


def _shown(value) -> str:
    """A value as the file has it (JSON text, at most 60 characters)."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _metres(value, where: str, *, positive: bool) -> float:
    """A length in metres: a JSON number or a numeric string (``"12"``, ``"12 m"``)."""
    want = "a number > 0" if positive else "a number >= 0"
    number = None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        number = float(value)
    elif isinstance(value, str) and (match := _NUMBER_RE.match(value)) is not None:
        number = float(match.group(1))
    if number is None or not math.isfinite(number) or number < 0.0 or (positive and number == 0.0):
        raise WorldError(f"{where}: expected {want}, got {_shown(value)}")
    return number


# ----------------------------------------------------------------------------- coordinates


def _lon_lat(position, where: str) -> tuple[float, float]:
    """A GeoJSON position ``[lon, lat(, alt)]`` -> ``(lon_deg, lat_deg)``."""
    if (
        not isinstance(position, list)
        or len(position) not in (2, 3)
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in position)
        or not all(math.isfinite(v) for v in position)
    ):
        raise WorldError(
            f"{where}: expected a position [longitude, latitude] or [longitude, "
            f"latitude, altitude] of finite numbers, got {_shown(position)}"
        )
    lon, lat = float(position[0]), float(position[1])
    if not -180.0 <= lon <= 180.0 or not -90.0 <= lat <= 90.0:
        raise WorldError(
            f"{where}: longitude must be -180..180 and latitude -90..90 degrees "
            f"(RFC 7946, WGS-84), got {_shown(position)}"
        )
    return lon, lat


def _positions(coords, where: str, least: int) -> list[tuple[float, float]]:
    if not isinstance(coords, list) or len(coords) < least:
        raise WorldError(f"{where}: expected a list of at least {least} positions, got {_shown(coords)}")
    return [_lon_lat(p, f"{where}[{i}]") for i, p in enumerate(coords)]


def _ring(coords, where: str) -> list[tuple[float, float]]:
    """A linear ring: >= 4 positions, the last equal to the first (RFC 7946 3.1.6)."""
    ring = _positions(coords, where, 4)
    if ring[0] != ring[-1]:
        raise WorldError(
            f"{where}: a linear ring must be closed (its last position equal to its first, RFC 7946 3.1.6)"
        )
    return ring


def _polygon(coords, where: str) -> Polygon:
    """Polygon coordinates (exterior ring, then holes) -> a valid shapely Polygon."""
    if not isinstance(coords, list) or not coords:
        raise WorldError(f"{where}: expected a list of linear rings, got {_shown(coords)}")
    rings = [_ring(r, f"{where}[{i}]") for i, r in enumerate(coords)]
    polygon = Polygon(rings[0], rings[1:])
    if not polygon.is_valid:
        raise WorldError(
            f"{where}: not a valid polygon: {explain_validity(polygon)} "
            "(self-intersecting or degenerate ring, or a hole outside its polygon)"
        )
    if polygon.area <= 0.0:
        raise WorldError(f"{where}: the polygon has zero area")
    return polygon


def _line(coords, where: str) -> LineString:
    line = LineString(_positions(coords, where, 2))
    if line.length <= 0.0:
        raise WorldError(f"{where}: the line has zero length")
    return line


def _geometry(raw, where: str):
    """A GeoJSON geometry object -> a shapely geometry in degrees (x = lon, y = lat)."""
    if raw is None:
        raise WorldError(f"{where}: null: a feature without a geometry is no obstacle")
    if not isinstance(raw, dict):
        raise WorldError(f"{where}: expected a geometry object, got {_shown(raw)}")
    kind = raw.get("type")
    if kind not in _GEOMETRIES:
        raise WorldError(
            f"{where}.type: unsupported geometry {_shown(kind)} (expected one of {', '.join(_GEOMETRIES)})"
        )
    if "coordinates" not in raw:
        raise WorldError(f"{where}.coordinates: missing")
    coords, at = raw["coordinates"], f"{where}.coordinates"
    if kind == "Point":
        return Point(_lon_lat(coords, at))
    if kind == "MultiPoint":
        return MultiPoint(_positions(coords, at, 1))
    if kind == "LineString":
        return _line(coords, at)
    if kind == "MultiLineString":
        _non_empty(coords, at)
        return MultiLineString([_line(c, f"{at}[{i}]") for i, c in enumerate(coords)])
    if kind == "Polygon":
        return _polygon(coords, at)
    _non_empty(coords, at)
    return MultiPolygon([_polygon(c, f"{at}[{i}]") for i, c in enumerate(coords)])


def _non_empty(coords, where: str) -> None:
    if not isinstance(coords, list) or not coords:
        raise WorldError(f"{where}: expected a non-empty list, got {_shown(coords)}")


# ----------------------------------------------------------------------------- properties


def _height_m(props: dict, where: str, default_height_m: float | None) -> float:
    """``height``, else ``building:levels`` x 3 m, else the file's ``default_height_m``."""
    if "height" in props:
        return _metres(props["height"], f"{where}.height", positive=True)
    if "building:levels" in props:
        return METRES_PER_LEVEL * _metres(props["building:levels"], f"{where}.building:levels", positive=True)
    if default_height_m is not None:
        return default_height_m
    raise WorldError(
        f"{where}.height: missing (give height in m or building:levels, or "
        "companion.default_height_m for the whole file)"
    )


def _min_height_m(props: dict, where: str, height_m: float) -> float:
    """``min_height``, else ``building:min_level`` x 3 m, else 0; below the height."""
    if "min_height" in props:
        key, value = "min_height", _metres(props["min_height"], f"{where}.min_height", positive=False)
    elif "building:min_level" in props:
        key = "building:min_level"
        value = METRES_PER_LEVEL * _metres(props[key], f"{where}.{key}", positive=False)
    else:
        return 0.0
    if not value < height_m:
        raise WorldError(f"{where}.{key}: must be below the height ({height_m:g} m), got {_shown(props[key])}")
    return value


def _feature(raw, where: str, default_height_m: float | None) -> MapFeature:
    """One Feature object -> a MapFeature (geometry and heights checked)."""
    if not isinstance(raw, dict):
        raise WorldError(f"{where}: expected a Feature object, got {_shown(raw)}")
    if raw.get("type") != "Feature":
        raise WorldError(f'{where}.type: expected "Feature", got {_shown(raw.get("type"))}')
    geometry = _geometry(raw.get("geometry"), f"{where}.geometry")
    props = raw.get("properties")
    if props is None:
        props = {}
    if not isinstance(props, dict):
        raise WorldError(f"{where}.properties: expected an object, got {_shown(props)}")
    at = f"{where}.properties"
    height_m = _height_m(props, at, default_height_m)
    extra: dict[str, float] = {"min_height_m": _min_height_m(props, at, height_m)}
    if isinstance(geometry, (Point, MultiPoint)):
        if "radius" not in props:
            raise WorldError(f"{at}.radius: missing (a {raw['geometry']['type']} needs a radius in m)")
        extra["radius_m"] = _metres(props["radius"], f"{at}.radius", positive=True)
    elif isinstance(geometry, (LineString, MultiLineString)):
        if "width" not in props:
            raise WorldError(f"{at}.width: missing (a {raw['geometry']['type']} needs a width in m)")
        extra["width_m"] = _metres(props["width"], f"{at}.width", positive=True)
    return MapFeature(
        where=where,
        geometry_deg=geometry,
        height_m=height_m,
        min_height_m=extra["min_height_m"],
        radius_m=extra.get("radius_m"),
        width_m=extra.get("width_m"),
    )


# ----------------------------------------------------------------------------- the collection


def _geo_position(value, where: str) -> tuple[float, float, float]:
    """``[lon, lat, number]`` of the header (home altitude AMSL, start/goal height)."""
    if not isinstance(value, list) or len(value) != 3:
        raise WorldError(f"{where}: expected [longitude, latitude, metres], got {_shown(value)}")
    lon, lat = _lon_lat(value, where)
    if isinstance(value[2], bool) or not isinstance(value[2], (int, float)):
        raise WorldError(f"{where}: expected [longitude, latitude, metres], got {_shown(value)}")
    return lon, lat, float(value[2])


def _bounds_deg(value, where: str) -> tuple[float, float, float, float]:
    if (
        not isinstance(value, list)
        or len(value) != 4
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        raise WorldError(f"{where}: expected [west, south, east, north] in degrees, got {_shown(value)}")
    west, south = _lon_lat(value[:2], where)
    east, north = _lon_lat(value[2:], where)
    if not (west < east and south < north):
        raise WorldError(f"{where}: expected west < east and south < north, got {_shown(value)}")
    return west, south, east, north


def _header(raw, default_name: str) -> dict:
    """The ``companion`` foreign member -> MapDocument keyword arguments."""
    if raw is None:
        return {"name": default_name}
    if not isinstance(raw, dict):
        raise WorldError(f"companion: expected an object, got {_shown(raw)}")
    unknown = sorted(set(raw) - _HEADER_KEYS)
    if unknown:
        raise WorldError(f"companion.{unknown[0]}: unknown key (expected {', '.join(sorted(_HEADER_KEYS))})")
    out: dict = {"name": str(raw.get("name", default_name))}
    if "home" in raw:
        lon, lat, alt_m = _geo_position(raw["home"], "companion.home")
        out["home_lla"] = (lat, lon, alt_m)
    if "bounds" in raw:
        out["bounds_deg"] = _bounds_deg(raw["bounds"], "companion.bounds")
    out["margin_m"] = _metres(raw.get("margin_m", 0.0), "companion.margin_m", positive=False)
    out["ceiling_m"] = _metres(raw.get("ceiling_m", DEFAULT_CEILING_M), "companion.ceiling_m", positive=True)
    out["padding_m"] = _metres(raw.get("padding_m", DEFAULT_PADDING_M), "companion.padding_m", positive=False)
    if "default_height_m" in raw:
        out["default_height_m"] = _metres(raw["default_height_m"], "companion.default_height_m", positive=True)
    for key in ("start", "goal"):
        if key in raw:
            out[f"{key}_deg"] = _geo_position(raw[key], f"companion.{key}")
    return out


def _check_collection(data) -> None:
    if not isinstance(data, dict):
        raise WorldError(f"expected a GeoJSON FeatureCollection object, got {_shown(data)}")
    if data.get("type") != "FeatureCollection":
        raise WorldError(
            f'type: expected "FeatureCollection", got {_shown(data.get("type"))} '
            "(wrap a single Feature or geometry in a FeatureCollection)"
        )
    crs = data.get("crs")
    if crs is not None and not any(tag in json.dumps(crs) for tag in _WGS84_CRS):
        raise WorldError(
            f"crs: {_shown(crs)}: only WGS-84 longitude/latitude is supported (RFC 7946); export the file in EPSG:4326"
        )
    if not isinstance(data.get("features"), list):
        raise WorldError(f"features: expected a list of Feature objects, got {_shown(data.get('features'))}")


def parse_geojson(data, source: str = "map", default_name: str | None = None) -> MapDocument:
    """A parsed GeoJSON FeatureCollection -> :class:`MapDocument`.

    Parameters
    ----------
    data : object
        ``json.loads`` of the file.
    source : str
        The file, for errors (every message starts with it).
    default_name : str, optional
        The world's name when ``companion.name`` is absent (default ``source``).

    Raises
    ------
    WorldError
        ``"<source>: <key>: <what is wrong>"``, the key e.g. ``features[3].properties.height``.
    """
    try:
        _check_collection(data)
        header = _header(data.get("companion"), default_name or source)
        default_height_m = header.pop("default_height_m", None)
        features = [_feature(raw, f"features[{i}]", default_height_m) for i, raw in enumerate(data["features"])]
    except WorldError as exc:
        raise WorldError(f"{source}: {exc}") from None
    return MapDocument(source=source, features=tuple(features), **header)


def parse_geojson_text(text: str, source: str = "map", default_name: str | None = None) -> MapDocument:
    """GeoJSON text -> :class:`MapDocument`; a syntax error names its line and column."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise WorldError(f"{source}: line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    return parse_geojson(data, source, default_name)
