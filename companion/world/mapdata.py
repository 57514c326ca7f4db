"""Map obstacles: features in WGS-84 longitude/latitude -> the World's obstacles in local NED.

The readers (:mod:`companion.world.geojson`, :mod:`companion.world.kml`) turn a file into a
:class:`MapDocument` of :class:`MapFeature` records (a shapely geometry in degrees, its heights
checked); this module only computes: it converts each feature about a home
(:class:`heli_common.frames.LocalFrame`, pymap3d's exact geodetic <-> NED transform) and builds
the :class:`~companion.world.World`.

- Polygons become :class:`~companion.world.Prism` obstacles. ``Prism`` takes any *simple*
  polygon (its kernels use the even-odd rule and every edge, so convex and concave rings are
  exact) but one ring only, so a polygon with holes is cut into simple pieces along lines
  through its holes (:func:`simple_pieces_ne_m`); a MultiPolygon gives one piece set per part.
- Points become vertical :class:`~companion.world.Cylinder` obstacles (masts, trees).
- LineStrings (wires, walls) are buffered to polygons of their width (flat ends, mitred joins)
  and then treated as polygons.

Heights are above the ground, read from ``ground_alt_m(lat_deg, lon_deg)`` (metres AMSL; the
home's altitude when none is given, flat ground until a terrain model exists). A footprint is
projected at its ground altitude; its top and bottom are taken at the footprint's centroid along
the local vertical there, so the tangent plane's curvature (``r**2 / 2R``, 8 mm at 320 m from
home) is in the limits. The ground under a footprint is its lowest vertex or centroid (the
OpenStreetMap convention: ``height`` counts from the lowest ground contact). An obstacle with
``min_height_m == 0`` has no bottom (``down_max_m = inf``): nothing flies under a building.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon
from shapely.geometry.base import BaseGeometry
from shapely.geometry.polygon import orient
from shapely.ops import split

from companion.errors import WorldError
from companion.world.obstacles import Obstacle
from companion.world.polyhedral_obstacles import Prism
from companion.world.round_obstacles import Cylinder
from companion.world.world import World
from heli_common.frames import GeoError, LocalFrame

__all__ = [
    "MapFeature",
    "MapDocument",
    "GroundAltitude",
    "DEFAULT_CEILING_M",
    "DEFAULT_PADDING_M",
    "flat_ground",
    "footprint_ne_m",
    "footprint_deg",
    "simple_pieces_ne_m",
    "feature_obstacles",
    "map_world",
]

log = logging.getLogger(__name__)

#: ``ground_alt_m(lat_deg (K,), lon_deg (K,)) -> alt_m (K,)``, metres AMSL.
GroundAltitude = Callable[[np.ndarray, np.ndarray], np.ndarray]

DEFAULT_CEILING_M = 120.0  # as the mission conversion's mission.ceiling_m
DEFAULT_PADDING_M = 30.0  # as the mission conversion's mission.padding_m
_AREA_TOL_M2 = 1e-6  # a piece smaller than this is a cut's sliver, dropped
_FAR_FROM_HOME_M = 5000.0  # a feature this far from home is logged (a huge world)


@dataclass(frozen=True)
class MapFeature:
    """One obstacle of a map file, in longitude/latitude degrees, its heights checked.

    Parameters
    ----------
    where : str
        Its place in the file for errors, e.g. ``"features[3]"``.
    geometry_deg : shapely geometry
        Polygon, MultiPolygon, Point, MultiPoint, LineString or MultiLineString; x = longitude,
        y = latitude (degrees, WGS-84). Polygons valid (checked by the reader).
    height_m : float
        Top above the ground (m), > ``min_height_m``; or, with ``top_is_amsl``, the top's
        altitude AMSL (KML ``absolute``).
    min_height_m : float
        Bottom above the ground (m), >= 0.
    radius_m : float, optional
        Radius of a Point's cylinder (m), > 0.
    width_m : float, optional
        Width of a LineString's wall (m), > 0.
    top_is_amsl : bool
        ``height_m`` is an altitude AMSL, not a height above the ground.
    """

    where: str
    geometry_deg: BaseGeometry
    height_m: float
    min_height_m: float = 0.0
    radius_m: float | None = None
    width_m: float | None = None
    top_is_amsl: bool = False


@dataclass(frozen=True)
class MapDocument:
    """A map file's features and the world settings it gives (all optional but the features).

    Parameters
    ----------
    source : str
        The file, for errors.
    name : str
    features : sequence of MapFeature
    home_lla : (lat_deg, lon_deg, alt_m AMSL), optional
        The file's home (the local frame's origin when the caller gives none).
    bounds_deg : (west, south, east, north), optional
        Horizontal bounds (RFC 7946 bbox order); default: the obstacles' extent plus padding.
    margin_m, ceiling_m, padding_m : float
        The world's safety margin; its top above home; the padding of the default bounds.
    start_deg, goal_deg : (lon_deg, lat_deg, height_m above ground), optional
        Defaults for ``companion plan``.
    """

    source: str
    name: str
    features: Sequence[MapFeature]
    home_lla: tuple | None = None
    bounds_deg: tuple | None = None
    margin_m: float = 0.0
    ceiling_m: float = DEFAULT_CEILING_M
    padding_m: float = DEFAULT_PADDING_M
    start_deg: tuple | None = None
    goal_deg: tuple | None = None


def flat_ground(frame: LocalFrame) -> GroundAltitude:
    """The ground of a world without a terrain model: the home's altitude everywhere."""
    alt0_m = frame.alt0_m

    def ground_alt_m(lat_deg, lon_deg):
        return np.full(np.shape(lat_deg), alt0_m, dtype=np.float64)

    return ground_alt_m


# ----------------------------------------------------------------------------- footprints


def footprint_ne_m(geometry_deg: BaseGeometry, frame: LocalFrame, ground_alt_m: GroundAltitude) -> BaseGeometry:
    """The geometry projected to local north-east metres at its ground altitude.

    Parameters
    ----------
    geometry_deg : shapely geometry, x = longitude, y = latitude (degrees)
    frame : LocalFrame
    ground_alt_m : GroundAltitude

    Returns
    -------
    shapely geometry of the same type, x = north (m), y = east (m)
    """

    def to_ne(lon_lat_deg: np.ndarray) -> np.ndarray:  # (K, 2) -> (K, 2)
        lon, lat = lon_lat_deg[:, 0], lon_lat_deg[:, 1]
        north_m, east_m, _ = frame.to_ned(lat, lon, ground_alt_m(lat, lon))
        return np.column_stack([north_m, east_m])

    return shapely.transform(geometry_deg, to_ne)


def footprint_deg(
    geometry_ne_m: BaseGeometry,
    frame: LocalFrame,
    ground_alt_m: GroundAltitude,
    tolerance_m: float = 1e-6,
    max_iterations: int = 10,
) -> BaseGeometry:
    """Inverse of :func:`footprint_ne_m`: local north-east metres on the ground -> degrees.

    The point of the ground above or below ``(north, east)`` is found by fixed-point iteration
    on its *down* coordinate (the ground's altitude there, ``ground_alt_m``); on flat ground the
    first step is exact to the millimetre and the second to the nanometre.

    Parameters
    ----------
    geometry_ne_m : shapely geometry, x = north (m), y = east (m)
    frame : LocalFrame
    ground_alt_m : GroundAltitude
    tolerance_m : float
        Stop when no vertex's altitude is further than this from the ground.
    max_iterations : int

    Returns
    -------
    shapely geometry of the same type, x = longitude, y = latitude (degrees)
    """

    def to_deg(ne_m: np.ndarray) -> np.ndarray:  # (K, 2) -> (K, 2)
        north_m, east_m = ne_m[:, 0], ne_m[:, 1]
        down_m = np.zeros(len(ne_m))
        for _ in range(max_iterations):
            lat, lon, alt_m = frame.to_lla(north_m, east_m, down_m)
            error_m = alt_m - ground_alt_m(lat, lon)
            down_m = down_m + error_m
            if np.all(np.abs(error_m) <= tolerance_m):
                break
        lat, lon, _ = frame.to_lla(north_m, east_m, down_m)
        return np.column_stack([lon, lat])

    return shapely.transform(geometry_ne_m, to_deg)


def _cut_through_hole(polygon_ne: Polygon) -> list[Polygon]:
    """Split ``polygon_ne`` by the line of constant north through its first hole's interior."""
    inner = Polygon(polygon_ne.interiors[0]).representative_point()
    lo_n, lo_e, hi_n, hi_e = polygon_ne.bounds
    cut = LineString([(inner.x, lo_e - 1.0), (inner.x, hi_e + 1.0)])
    pieces = split(polygon_ne, cut)
    return [g for g in pieces.geoms if isinstance(g, Polygon) and g.area > _AREA_TOL_M2]


def simple_pieces_ne_m(polygon_ne: Polygon) -> list[Polygon]:
    """Simple polygons (no holes, counter-clockwise) whose union is ``polygon_ne``.

    A ``Prism`` holds one simple ring, convex or not; a polygon with holes is cut along a line
    of constant north through each hole in turn (the cut opens the hole into the pieces'
    boundaries), so ``h`` holes give at most ``2 h + 1`` pieces sharing cut edges.

    Parameters
    ----------
    polygon_ne : shapely Polygon, valid

    Returns
    -------
    list of shapely Polygon
    """
    todo, done = [polygon_ne], []
    while todo:
        poly = todo.pop()
        if poly.interiors:
            todo += _cut_through_hole(poly)
        else:
            done.append(orient(poly, sign=1.0))
    return done


def _polygons_ne_m(feature: MapFeature, footprint: BaseGeometry) -> list[Polygon]:
    """The feature's footprint as valid polygons (a line buffered to its width)."""
    if isinstance(footprint, (LineString, MultiLineString)):
        assert feature.width_m is not None  # the reader requires a width of every line
        footprint = footprint.buffer(0.5 * feature.width_m, cap_style="flat", join_style="mitre")
    parts = list(footprint.geoms) if isinstance(footprint, MultiPolygon) else [footprint]
    out = []
    for k, part in enumerate(parts):
        part = shapely.remove_repeated_points(part, 1e-6)
        if not part.is_valid or part.area <= _AREA_TOL_M2:
            which = f".geometry.coordinates[{k}]" if isinstance(feature.geometry_deg, MultiPolygon) else ".geometry"
            reason = shapely.is_valid_reason(part) if not part.is_valid else "zero area"
            raise WorldError(f"{feature.where}{which}: not a valid polygon in local metres ({reason})")
        out.append(part)
    return out


# ----------------------------------------------------------------------------- heights


def _lowest_ground_alt_m(feature: MapFeature, ground_alt_m: GroundAltitude) -> float:
    """The ground under the footprint: the lowest of its vertices and centroid (m AMSL)."""
    coords = shapely.get_coordinates(feature.geometry_deg)  # (K, 2) lon, lat
    centre = feature.geometry_deg.centroid
    lon = np.append(coords[:, 0], centre.x)
    lat = np.append(coords[:, 1], centre.y)
    return float(np.min(ground_alt_m(lat, lon)))


def _down_limits_m(feature: MapFeature, frame: LocalFrame, ground_alt_m: GroundAltitude) -> tuple[float, float]:
    """``(down_min_m, down_max_m)``: the top and bottom along the local vertical at the centroid."""
    ground_m = _lowest_ground_alt_m(feature, ground_alt_m)
    top_alt_m = feature.height_m if feature.top_is_amsl else ground_m + feature.height_m
    bottom_alt_m = ground_m + feature.min_height_m
    if not top_alt_m > bottom_alt_m:
        raise WorldError(
            f"{feature.where}: the top ({top_alt_m:.2f} m AMSL) is not above the "
            f"bottom ({bottom_alt_m:.2f} m AMSL: ground {ground_m:.2f} m + min_height "
            f"{feature.min_height_m:g} m)"
        )
    centre = feature.geometry_deg.centroid
    _, _, down_m = frame.to_ned(np.array([centre.y] * 2), np.array([centre.x] * 2), np.array([top_alt_m, bottom_alt_m]))
    down_max_m = float(down_m[1]) if feature.min_height_m > 0.0 else math.inf
    return float(down_m[0]), down_max_m


# ----------------------------------------------------------------------------- obstacles


def feature_obstacles(feature: MapFeature, frame: LocalFrame, ground_alt_m: GroundAltitude) -> list[Obstacle]:
    """The World obstacles of one map feature (local NED about ``frame``'s origin).

    Parameters
    ----------
    feature : MapFeature
    frame : LocalFrame
        The home.
    ground_alt_m : GroundAltitude

    Returns
    -------
    list of Prism (polygons, lines) or Cylinder (points)

    Raises
    ------
    WorldError
        Naming ``feature.where``: a footprint that is not valid once projected, a top not above
        the bottom, a coordinate the frame rejects.
    """
    try:
        footprint = footprint_ne_m(feature.geometry_deg, frame, ground_alt_m)
        down_min_m, down_max_m = _down_limits_m(feature, frame, ground_alt_m)
    except GeoError as exc:
        raise WorldError(f"{feature.where}: {exc}") from None
    _log_if_far(feature, footprint)
    if isinstance(footprint, (Point, MultiPoint)):
        points = list(footprint.geoms) if isinstance(footprint, MultiPoint) else [footprint]
        assert feature.radius_m is not None  # the reader requires a radius of every point
        return [Cylinder((p.x, p.y), feature.radius_m, down_min_m, down_max_m) for p in points]
    prisms: list[Obstacle] = []
    for polygon in _polygons_ne_m(feature, footprint):
        for piece in simple_pieces_ne_m(polygon):
            prisms.append(Prism(tuple(piece.exterior.coords)[:-1], down_min_m, down_max_m))
    return prisms


def _log_if_far(feature: MapFeature, footprint_ne: BaseGeometry) -> None:
    distance_m = footprint_ne.distance(Point(0.0, 0.0))
    if distance_m > _FAR_FROM_HOME_M:
        log.warning("%s is %.1f km from home: the world grows to include it", feature.where, distance_m / 1000.0)


def _geo_point_ned_m(position_deg: tuple, frame: LocalFrame, ground_alt_m: GroundAltitude) -> tuple:
    """``(lon_deg, lat_deg, height_m above ground)`` -> ``(north, east, down)`` metres."""
    lon, lat, height_m = position_deg
    ground_m = float(ground_alt_m(np.array([lat]), np.array([lon]))[0])
    n, e, d = frame.to_ned(lat, lon, ground_m + height_m)
    return tuple(round(float(v), 6) for v in (n, e, d))  # to the micrometre


def _bounds_ne_m(
    doc: MapDocument, obstacles: list[Obstacle], frame: LocalFrame, extra_ne_m: list[tuple]
) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal bounds: the file's ``bounds_deg`` box, else the extent of home, the obstacles
    and ``extra_ne_m`` plus ``padding_m + margin_m``."""
    if doc.bounds_deg is not None:
        west, south, east, north = doc.bounds_deg
        lon = np.array([west, east, east, west, 0.5 * (west + east), 0.5 * (west + east), west, east])
        lat = np.array([south, south, north, north, south, north, 0.5 * (south + north), 0.5 * (south + north)])
        n, e, _ = frame.to_ned(lat, lon, np.full(lat.shape, frame.alt0_m))
        return np.array([n.min(), e.min()]), np.array([n.max(), e.max()])
    corners = [np.zeros(2)] + [np.asarray(p[:2], dtype=float) for p in extra_ne_m]
    for ob in obstacles:
        lo, hi = ob.aabb(2)
        corners += [np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)]
    pts = np.vstack(corners)
    pad_m = doc.padding_m + doc.margin_m
    return pts.min(axis=0) - pad_m, pts.max(axis=0) + pad_m


def map_world(
    doc: MapDocument, home_lla: tuple | None = None, ground_alt_m: GroundAltitude | None = None
) -> tuple[World, LocalFrame, tuple | None, tuple | None]:
    """The 3D planning world of a map document, in local NED about the home.

    Parameters
    ----------
    doc : MapDocument
    home_lla : (lat_deg, lon_deg, alt_m AMSL), optional
        The origin; default the document's ``home_lla``.
    ground_alt_m : GroundAltitude, optional
        Ground altitude AMSL under a point; default :func:`flat_ground` (the home's altitude).

    Returns
    -------
    world : World
        Bounds: horizontal as :func:`_bounds_ne_m`, vertical from ``-ceiling_m`` (down) to 0
        (the home's level), as the mission conversion bounds a mission's world.
    frame : LocalFrame
    start_ned_m, goal_ned_m : (3,) tuples or None

    Raises
    ------
    WorldError
        Prefixed with ``doc.source``: no home, a feature that cannot be converted, a start or
        goal or bounds the frame rejects.
    """
    try:
        home = home_lla if home_lla is not None else doc.home_lla
        if home is None:
            raise WorldError(
                "a map world needs a home (the origin of local NED): give --home "
                "LAT,LON,ALT (a GeoJSON file may carry it as companion.home)"
            )
        try:
            frame = LocalFrame(*home)
        except GeoError as exc:
            raise WorldError(f"home: {exc}") from None
        ground = ground_alt_m or flat_ground(frame)
        obstacles: list[Obstacle] = []
        for feature in doc.features:
            obstacles += feature_obstacles(feature, frame, ground)
        start = None if doc.start_deg is None else _geo_point_ned_m(doc.start_deg, frame, ground)
        goal = None if doc.goal_deg is None else _geo_point_ned_m(doc.goal_deg, frame, ground)
        lo_ne, hi_ne = _bounds_ne_m(doc, obstacles, frame, [p for p in (start, goal) if p is not None])
        world = World(obstacles, [lo_ne[0], lo_ne[1], -doc.ceiling_m], [hi_ne[0], hi_ne[1], 0.0], doc.margin_m)
    except (WorldError, GeoError) as exc:
        raise WorldError(f"{doc.source}: {exc}") from None
    log.debug(
        "%s: %d features -> %d obstacles about home %.7f, %.7f, %.1f m",
        doc.source,
        len(doc.features),
        len(obstacles),
        frame.lat0_deg,
        frame.lon0_deg,
        frame.alt0_m,
    )
    return world, frame, start, goal
