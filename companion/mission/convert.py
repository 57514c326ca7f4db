"""Mission (global) -> local NED waypoints and the planning world (paper section 3.1).

The paper plans in a bounded workspace cluttered with obstacles inflated by the vehicle's size
plus a margin. A ground station's mission gives that workspace:

- geofence *exclusion* polygons -> ``companion.world.Prism`` (full height), exclusion circles ->
  ``companion.world.Cylinder`` (full height);
- an *inclusion* polygon or circle -> the world bounds (its bounding box; waypoints outside the
  polygon itself are rejected); without one, the bounds are the extent of home, the waypoints
  and the exclusion zones plus ``padding_m``;
- altitude bounds from the ground (home level) to ``ceiling_m``;
- an optional world file adds obstacles (``companion.world.load_world``): TOML/JSON in local
  NED about home, or a GeoJSON/KML map converted about this mission's home.

Each navigation item becomes a ``LocalWaypoint``. Unreachable goals (inside an exclusion zone
or an obstacle inflated by the margin, outside the inclusion fence, above the ceiling, below
ground) are a ``MissionError`` naming the item, raised before takeoff.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from companion.errors import MissionError
from companion.geo import LocalFrame
from companion.mission.model import (
    AMSL_FRAMES,
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_RETURN_TO_LAUNCH,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    LocalMission,
    LocalWaypoint,
    MissionItem,
    MissionPlan,
)
from heli_common.geometry import point_in_polygon  # noqa: F401  (re-exported)
from heli_common.typed_config import require_numbers

if TYPE_CHECKING:
    from companion.world import Obstacle

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ConversionSettings:
    """How a mission becomes a local mission and a world.

    Parameters
    ----------
    margin_m : float
        Safety margin added around every obstacle (vehicle radius plus margin), m.
    default_acceptance_radius_m : float
        Acceptance radius of waypoints whose param2 is 0 (ArduPilot WPNAV_RADIUS-like), m.
    padding_m : float
        Added around the mission extent when there is no inclusion fence, m.
    ceiling_m : float
        Highest allowed altitude above home (world bound), m.
    floor_m : float
        Lowest altitude above home a waypoint may have (takeoff and land excepted), m.
    """

    margin_m: float = 3.0
    default_acceptance_radius_m: float = 2.0
    padding_m: float = 30.0
    ceiling_m: float = 120.0
    floor_m: float = 0.5

    def __post_init__(self) -> None:
        require_numbers(
            MissionError,
            "mission",
            self,
            positive=("default_acceptance_radius_m", "ceiling_m"),
            non_negative=("margin_m", "padding_m", "floor_m"),
        )


@dataclass(frozen=True)
class Zone:
    """An exclusion zone or world-file obstacle with the name errors use for it."""

    obstacle: Obstacle
    name: str


def mission_to_local(
    plan: MissionPlan,
    home_lla: tuple[float, float, float] | None = None,
    *,
    settings: ConversionSettings | None = None,
    world_file=None,
    dim: int = 3,
) -> LocalMission:
    """Convert a validated mission to local NED waypoints and a planning world.

    Parameters
    ----------
    plan : MissionPlan
    home_lla : (lat_deg, lon_deg, alt_m AMSL), optional
        Origin of the local frame: the vehicle's home. Default: ``plan.planned_home``.
    settings : ConversionSettings, optional
    world_file : path, optional
        World file whose obstacles are added: TOML/JSON (already in local NED about home) or
        GeoJSON/KML (longitude/latitude, converted about ``home_lla``).
    dim : int
        2 (north-east plane) or 3 (north-east-down) world.

    Returns
    -------
    LocalMission
        Waypoints in flight order. It always starts with a ``'takeoff'`` waypoint (seq 0 if the
        mission has no NAV_TAKEOFF: climb to the first waypoint's altitude above home).

    Raises
    ------
    MissionError
        No home, unsupported items, an unreachable waypoint ("item N is inside exclusion zone
        M"), a waypoint outside the inclusion fence, above the ceiling or below ground.
    """
    settings = settings or ConversionSettings()
    if dim not in (2, 3):
        raise MissionError(f"dim must be 2 or 3, got {dim}")
    plan.validate()
    home = home_lla if home_lla is not None else plan.planned_home
    if home is None:
        raise MissionError("no home position: the mission has no planned home and the vehicle reported none")
    frame = LocalFrame(*home)
    waypoints, end_action = items_to_waypoints(plan, frame, settings)
    zones = exclusion_zones(plan, frame)
    extra = load_world_obstacles(world_file, dim, frame)
    zones += [Zone(ob, f"obstacle {k} of world file {world_file}") for k, ob in enumerate(extra)]
    inclusion_ne_m = inclusion_polygon_ne(plan, frame)
    bounds_min, bounds_max = world_bounds(waypoints, zones, inclusion_ne_m, settings, dim)
    check_waypoints_reachable(waypoints, zones, inclusion_ne_m, settings, dim)
    world = build_world([z.obstacle for z in zones], bounds_min, bounds_max, settings.margin_m)
    rally = np.array(
        [frame.to_ned(r.lat_deg, r.lon_deg, home[2] + r.alt_m) for r in plan.rally], dtype=np.float64
    ).reshape(-1, 3)
    return LocalMission(frame=frame, waypoints=tuple(waypoints), world=world, rally_ned_m=rally, end_action=end_action)


# ----------------------------------------------------------------------------- waypoints


def item_ned_m(item: MissionItem, frame: LocalFrame, last_ned_m: np.ndarray) -> np.ndarray:
    """NED position of a navigation item; lat/lon 0, 0 means "above the last position"."""
    if item.frame in AMSL_FRAMES:
        alt_amsl = item.alt_m
    else:
        alt_amsl = frame.alt0_m + item.alt_m
    if item.has_position:
        n, e, d = frame.to_ned(item.lat_deg, item.lon_deg, alt_amsl)
        return np.array([float(n), float(e), float(d)])
    return np.array([last_ned_m[0], last_ned_m[1], frame.alt0_m - alt_amsl])


def items_to_waypoints(
    plan: MissionPlan, frame: LocalFrame, settings: ConversionSettings
) -> tuple[list[LocalWaypoint], str]:
    """Walk the items in order: speed changes apply to later legs; LAND/RTL end the mission."""
    waypoints: list[LocalWaypoint] = []
    last = np.zeros(3)
    speed = None
    end_action = "hover"
    radius0 = settings.default_acceptance_radius_m
    for index, item in enumerate(plan.items):
        seq = index + 1
        if end_action != "hover":
            log.warning("%s follows the mission's %s and is not flown", item.describe(seq), end_action.upper())
            continue
        if item.command == MAV_CMD_DO_CHANGE_SPEED:
            if item.speed_m_s is not None:
                speed = item.speed_m_s
            continue
        if item.command == MAV_CMD_NAV_TAKEOFF:
            pos = item_ned_m(item, frame, last)
            check_altitude(pos, item, seq, settings, allow_ground=False)
            waypoints.append(LocalWaypoint(seq, "takeoff", pos, radius0, 0.0, speed))
        elif item.command == MAV_CMD_NAV_WAYPOINT:
            pos = item_ned_m(item, frame, last)
            check_altitude(pos, item, seq, settings, allow_ground=False)
            radius = item.acceptance_radius_m or radius0
            waypoints.append(LocalWaypoint(seq, "waypoint", pos, radius, item.hold_s, speed))
        elif item.command == MAV_CMD_NAV_LAND:
            pos = item_ned_m(item, frame, last) if item.has_position else last.copy()
            pos[2] = ground_down_m(item, frame)
            waypoints.append(LocalWaypoint(seq, "land", pos, radius0, 0.0, speed))
            end_action = "land"
        elif item.command == MAV_CMD_NAV_RETURN_TO_LAUNCH:
            pos = np.array([0.0, 0.0, last[2]])
            waypoints.append(LocalWaypoint(seq, "rtl", pos, radius0, 0.0, speed))
            end_action = "rtl"
        last = waypoints[-1].pos_ned_m.copy() if waypoints else last
    if not waypoints:
        raise MissionError("the mission has no navigation item (takeoff, waypoint, land, RTL)")
    if waypoints[0].kind != "takeoff":
        first_air = next((w for w in waypoints if w.kind in ("waypoint", "takeoff")), None)
        if first_air is None:
            raise MissionError("the mission lands or returns without ever flying to a waypoint")
        climb = np.array([0.0, 0.0, first_air.pos_ned_m[2]])
        waypoints.insert(0, LocalWaypoint(0, "takeoff", climb, radius0, 0.0, None))
    return waypoints, end_action


def ground_down_m(item: MissionItem, frame: LocalFrame) -> float:
    """Down coordinate of the landing ground: home level unless an AMSL altitude is given."""
    if item.frame in AMSL_FRAMES and item.alt_m != 0.0:
        return frame.alt0_m - item.alt_m
    return 0.0


def check_altitude(
    pos_ned_m: np.ndarray, item: MissionItem, seq: int, settings: ConversionSettings, allow_ground: bool
) -> None:
    altitude_m = -float(pos_ned_m[2])
    if altitude_m > settings.ceiling_m + 1e-9:
        raise MissionError(
            f"{item.describe(seq)}: altitude {altitude_m:.1f} m above home is "
            f"above the ceiling of {settings.ceiling_m:.1f} m"
        )
    if not allow_ground and altitude_m < settings.floor_m:
        raise MissionError(
            f"{item.describe(seq)}: altitude {altitude_m:.1f} m above home is "
            f"below the minimum of {settings.floor_m:.1f} m"
        )


# ----------------------------------------------------------------------------- world


def exclusion_zones(plan: MissionPlan, frame: LocalFrame) -> list[Zone]:
    """Exclusion polygons -> Prism, exclusion circles -> Cylinder (full height)."""
    from companion.world import Cylinder, Prism

    zones: list[Zone] = []
    for k, polygon in enumerate(plan.polygons):
        if polygon.inclusion:
            continue
        lat = np.array([v[0] for v in polygon.vertices_deg])
        lon = np.array([v[1] for v in polygon.vertices_deg])
        n, e, _ = frame.to_ned(lat, lon, np.full(lat.shape, frame.alt0_m))
        try:
            prism = Prism(tuple(zip(n.tolist(), e.tolist())))
        except Exception as exc:  # WorldError: degenerate polygon
            raise MissionError(f"geofence polygon {k}: {exc}") from None
        zones.append(Zone(prism, f"{len(zones) + 1} (geofence polygon {k})"))
    for k, circle in enumerate(plan.circles):
        if circle.inclusion:
            continue
        n, e, _ = frame.to_ned(circle.lat_deg, circle.lon_deg, frame.alt0_m)
        zones.append(Zone(Cylinder((float(n), float(e)), circle.radius_m), f"{len(zones) + 1} (geofence circle {k})"))
    return zones


def load_world_obstacles(world_file, dim: int, frame: LocalFrame | None = None) -> list:
    """Obstacles of an optional world file (its bounds are ignored: the mission gives them); a
    map file (GeoJSON, KML) is converted about ``frame``'s origin, the mission's home."""
    if world_file is None:
        return []
    from companion.world import load_world

    home_lla = None if frame is None else (frame.lat0_deg, frame.lon0_deg, frame.alt0_m)
    world = load_world(world_file, home_lla=home_lla)
    obstacles = list(world.obstacles)
    for ob in obstacles:
        ob.check_dim(dim)
    return obstacles


def inclusion_polygon_ne(plan: MissionPlan, frame: LocalFrame) -> np.ndarray | None:
    """The inclusion fence as a polygon (P, 2) in north-east metres (a circle as 32 vertices)."""
    polygons = plan.inclusion_polygons
    circles = plan.inclusion_circles
    if len(polygons) + len(circles) > 1:
        log.warning("%d inclusion fences: only the first one bounds the world", len(polygons) + len(circles))
    if polygons:
        lat = np.array([v[0] for v in polygons[0].vertices_deg])
        lon = np.array([v[1] for v in polygons[0].vertices_deg])
        n, e, _ = frame.to_ned(lat, lon, np.full(lat.shape, frame.alt0_m))
        return np.column_stack([n, e])
    if circles:
        c = circles[0]
        n, e, _ = frame.to_ned(c.lat_deg, c.lon_deg, frame.alt0_m)
        ang = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
        return np.column_stack([float(n) + c.radius_m * np.cos(ang), float(e) + c.radius_m * np.sin(ang)])
    return None


def world_bounds(
    waypoints: list[LocalWaypoint],
    zones: list[Zone],
    inclusion_ne_m: np.ndarray | None,
    settings: ConversionSettings,
    dim: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds: the inclusion fence's box, else the extent of home, goals and zones + padding."""
    if inclusion_ne_m is not None:
        lo_ne = inclusion_ne_m.min(axis=0)
        hi_ne = inclusion_ne_m.max(axis=0)
    else:
        corners = [np.zeros(2)] + [w.pos_ned_m[:2] for w in waypoints]
        for zone in zones:
            lo, hi = zone.obstacle.aabb(2)
            corners += [np.asarray(lo[:2], dtype=float), np.asarray(hi[:2], dtype=float)]
        pts = np.vstack(corners)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        pad = settings.padding_m + settings.margin_m
        lo_ne = pts.min(axis=0) - pad
        hi_ne = pts.max(axis=0) + pad
    if dim == 2:
        return lo_ne.astype(np.float64), hi_ne.astype(np.float64)
    return (np.array([lo_ne[0], lo_ne[1], -settings.ceiling_m]), np.array([hi_ne[0], hi_ne[1], 0.0]))


def check_waypoints_reachable(
    waypoints: list[LocalWaypoint],
    zones: list[Zone],
    inclusion_ne_m: np.ndarray | None,
    settings: ConversionSettings,
    dim: int,
) -> None:
    """Every goal must be outside every inflated zone and inside the inclusion fence."""
    for w in waypoints:
        label = "the implied takeoff (seq 0)" if w.seq == 0 else f"item {w.seq} ({w.kind})"
        point = tuple(float(v) for v in w.pos_ned_m[:dim])
        for zone in zones:
            clearance_m = float(zone.obstacle.sdf(point))
            if clearance_m < 0.0:
                raise MissionError(f"{label} is inside exclusion zone {zone.name}: unreachable")
            if clearance_m < settings.margin_m:
                raise MissionError(
                    f"{label} is {clearance_m:.1f} m from exclusion zone "
                    f"{zone.name}, closer than the {settings.margin_m:.1f} m "
                    f"margin: unreachable"
                )
        if inclusion_ne_m is not None and not point_in_polygon(w.pos_ned_m[:2], inclusion_ne_m):
            raise MissionError(f"{label} is outside the inclusion geofence: unreachable")


def build_world(obstacles: list, bounds_min: np.ndarray, bounds_max: np.ndarray, margin_m: float):
    """``companion.world.World`` with the zones inflated by ``margin_m``."""
    from companion.world import World

    return World(obstacles, bounds_min, bounds_max, margin_m=margin_m)
