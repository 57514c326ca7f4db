"""Mission data model: what a ground station stores on the vehicle, in global and local form.

Global form (``MissionPlan``) holds MAVLink mission items exactly as a ground station edits them
(MAV_CMD number, MAV_FRAME, param1..4, latitude/longitude in degrees, altitude in metres), plus
the geofence (inclusion/exclusion polygons and circles), the rally points and the planned home.
It is what ``.plan`` and ``QGC WPL 110`` files hold and what the mission protocol transfers.

Local form (``LocalMission``) is what the planner flies (paper section 3: a sequence of goals in
a cluttered world): waypoints in NED metres about home with acceptance radius, hold time and
speed, and the ``companion.world.World`` made from the exclusion zones.

Only the commands a helicopter mission of the paper needs are supported
(``SUPPORTED_COMMANDS``); anything else is a ``MissionError`` naming the item, raised when the
file is read, i.e. long before takeoff.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.errors import MissionError
from heli_common.mavlink_ids import mavlink

# MAV_CMD numbers (pymavlink's generated enums)
MAV_CMD_NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
MAV_CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
MAV_CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
MAV_CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
MAV_CMD_DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
MAV_CMD_NAV_FENCE_RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
MAV_CMD_NAV_RALLY_POINT = mavlink.MAV_CMD_NAV_RALLY_POINT

SUPPORTED_COMMANDS = {
    MAV_CMD_NAV_WAYPOINT: "NAV_WAYPOINT",
    MAV_CMD_NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH",
    MAV_CMD_NAV_LAND: "NAV_LAND",
    MAV_CMD_NAV_TAKEOFF: "NAV_TAKEOFF",
    MAV_CMD_DO_CHANGE_SPEED: "DO_CHANGE_SPEED",
}
#: commands that carry a position (x = lat, y = lon, z = alt)
NAV_COMMANDS = frozenset({MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LAND, MAV_CMD_NAV_TAKEOFF})

# MAV_FRAME numbers (pymavlink's generated enums)
MAV_FRAME_GLOBAL = mavlink.MAV_FRAME_GLOBAL
MAV_FRAME_MISSION = mavlink.MAV_FRAME_MISSION
MAV_FRAME_GLOBAL_RELATIVE_ALT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
MAV_FRAME_GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
#: frames whose altitude is metres AMSL
AMSL_FRAMES = frozenset({MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_INT})
#: frames whose altitude is metres above home
RELATIVE_FRAMES = frozenset({MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
SUPPORTED_FRAMES = AMSL_FRAMES | RELATIVE_FRAMES | {MAV_FRAME_MISSION}


def command_name(command: int) -> str:
    """Human name of a MAV_CMD (``"MAV_CMD 31000"`` when unknown to pymavlink)."""
    if command in SUPPORTED_COMMANDS:
        return SUPPORTED_COMMANDS[command]
    entry = mavlink.enums["MAV_CMD"].get(command)
    if entry is not None and not entry.name.endswith("ENUM_END"):
        return entry.name.removeprefix("MAV_CMD_")
    return f"MAV_CMD {command}"


def check_lat_lon_deg(lat_deg: float, lon_deg: float, where: str) -> None:
    """Raise ``MissionError`` naming ``where`` if a latitude/longitude is not a valid angle."""
    if not (isinstance(lat_deg, (int, float)) and math.isfinite(lat_deg)):
        raise MissionError(f"{where}: latitude {lat_deg!r} is not a number")
    if not (isinstance(lon_deg, (int, float)) and math.isfinite(lon_deg)):
        raise MissionError(f"{where}: longitude {lon_deg!r} is not a number")
    if abs(lat_deg) > 90.0:
        raise MissionError(f"{where}: latitude {lat_deg} deg is out of range [-90, 90]")
    if abs(lon_deg) > 180.0:
        raise MissionError(f"{where}: longitude {lon_deg} deg is out of range [-180, 180]")


@dataclass(frozen=True)
class MissionItem:
    """One mission item (MAVLink MISSION_ITEM_INT semantics, degrees instead of 1e7 integers).

    Parameters
    ----------
    command : int
        MAV_CMD (one of ``SUPPORTED_COMMANDS``).
    frame : int
        MAV_FRAME: 0/5 altitude AMSL, 3/6 altitude above home, 2 for DO commands.
    param1, param2, param3, param4 : float
        Command parameters (NaN = unset). NAV_WAYPOINT: param1 hold time s, param2 acceptance
        radius m. DO_CHANGE_SPEED: param2 speed m/s (-1 = no change).
    lat_deg, lon_deg, alt_m : float
        Position (0, 0 = "here" for takeoff/land, as in ArduPilot); altitude per ``frame``.
    autocontinue : bool
    """

    command: int
    frame: int = MAV_FRAME_GLOBAL_RELATIVE_ALT
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    alt_m: float = 0.0
    autocontinue: bool = True

    @property
    def is_nav(self) -> bool:
        """True if the item carries a position to fly to."""
        return self.command in NAV_COMMANDS

    @property
    def has_position(self) -> bool:
        """True if latitude/longitude are given (not 0, 0 meaning "current position")."""
        return self.is_nav and not (self.lat_deg == 0.0 and self.lon_deg == 0.0)

    @property
    def hold_s(self) -> float:
        """NAV_WAYPOINT hold time in seconds (0 when unset)."""
        if self.command != MAV_CMD_NAV_WAYPOINT or not math.isfinite(self.param1):
            return 0.0
        return max(0.0, float(self.param1))

    @property
    def acceptance_radius_m(self) -> float | None:
        """NAV_WAYPOINT acceptance radius in metres (None when unset or 0: use the default)."""
        if self.command != MAV_CMD_NAV_WAYPOINT or not math.isfinite(self.param2) or self.param2 <= 0.0:
            return None
        return float(self.param2)

    @property
    def speed_m_s(self) -> float | None:
        """DO_CHANGE_SPEED speed in m/s (None for "no change" or other commands)."""
        if self.command != MAV_CMD_DO_CHANGE_SPEED or not math.isfinite(self.param2) or self.param2 <= 0.0:
            return None
        return float(self.param2)

    def describe(self, index: int) -> str:
        """``"item 3 (NAV_WAYPOINT)"``: how errors name this item."""
        return f"item {index} ({command_name(self.command)})"


@dataclass(frozen=True)
class FencePolygon:
    """A geofence polygon.

    Parameters
    ----------
    vertices_deg : tuple of (lat_deg, lon_deg)
        At least 3 vertices, in order (closed implicitly).
    inclusion : bool
        True: the vehicle must stay inside; False: an exclusion zone (obstacle).
    """

    vertices_deg: tuple[tuple[float, float], ...]
    inclusion: bool

    def __post_init__(self) -> None:
        kind = "inclusion" if self.inclusion else "exclusion"
        if len(self.vertices_deg) < 3:
            raise MissionError(f"fence {kind} polygon has {len(self.vertices_deg)} vertices, needs at least 3")
        for k, (lat, lon) in enumerate(self.vertices_deg):
            check_lat_lon_deg(lat, lon, f"fence {kind} polygon vertex {k}")


@dataclass(frozen=True)
class FenceCircle:
    """A geofence circle (centre in degrees, radius in metres; inclusion or exclusion)."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    inclusion: bool

    def __post_init__(self) -> None:
        kind = "inclusion" if self.inclusion else "exclusion"
        check_lat_lon_deg(self.lat_deg, self.lon_deg, f"fence {kind} circle")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise MissionError(f"fence {kind} circle: radius {self.radius_m} m must be > 0")


@dataclass(frozen=True)
class RallyPoint:
    """A rally point: latitude/longitude in degrees, altitude in metres above home."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        check_lat_lon_deg(self.lat_deg, self.lon_deg, "rally point")


@dataclass(frozen=True)
class MissionPlan:
    """Mission, geofence and rally points, as stored on the vehicle (global form).

    Parameters
    ----------
    items : tuple of MissionItem
        The mission, without the home item (ArduPilot's seq 0 is carried in ``planned_home``).
    polygons, circles : tuple of FencePolygon / FenceCircle
    rally : tuple of RallyPoint
    planned_home : (lat_deg, lon_deg, alt_m AMSL) or None
    cruise_speed_m_s, hover_speed_m_s : float or None
        QGroundControl's default speeds (kept for round trips).
    """

    items: tuple[MissionItem, ...]
    polygons: tuple[FencePolygon, ...] = ()
    circles: tuple[FenceCircle, ...] = ()
    rally: tuple[RallyPoint, ...] = ()
    planned_home: tuple[float, float, float] | None = None
    cruise_speed_m_s: float | None = None
    hover_speed_m_s: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "items", tuple(self.items))
        object.__setattr__(self, "polygons", tuple(self.polygons))
        object.__setattr__(self, "circles", tuple(self.circles))
        object.__setattr__(self, "rally", tuple(self.rally))
        if self.planned_home is not None:
            lat, lon, alt = (float(v) for v in self.planned_home)
            check_lat_lon_deg(lat, lon, "planned home position")
            object.__setattr__(self, "planned_home", (lat, lon, alt))

    def validate(self) -> None:
        """Check that the mission can be flown by the companion.

        Raises
        ------
        MissionError
            Empty mission; unsupported command or frame (naming the item and command);
            latitude/longitude out of range; no position to fly to. Items are named by their
            sequence number on the vehicle: ``items[k]`` is "item k+1" (seq 0 is home, as in
            ArduPilot, QGroundControl's list and the WPL file's index column).
        """
        if not self.items:
            raise MissionError("the mission is empty: it has no mission items")
        for index, item in enumerate(self.items):
            validate_item(item, index + 1)
        if not any(item.has_position or item.command == MAV_CMD_NAV_TAKEOFF for item in self.items):
            raise MissionError("the mission has no takeoff and no waypoint with a position")

    @property
    def exclusion_polygons(self) -> tuple[FencePolygon, ...]:
        return tuple(p for p in self.polygons if not p.inclusion)

    @property
    def inclusion_polygons(self) -> tuple[FencePolygon, ...]:
        return tuple(p for p in self.polygons if p.inclusion)

    @property
    def exclusion_circles(self) -> tuple[FenceCircle, ...]:
        return tuple(c for c in self.circles if not c.inclusion)

    @property
    def inclusion_circles(self) -> tuple[FenceCircle, ...]:
        return tuple(c for c in self.circles if c.inclusion)


def validate_item(item: MissionItem, index: int) -> None:
    """Raise ``MissionError`` naming item ``index`` (its vehicle seq) if it cannot be flown."""
    if item.command not in SUPPORTED_COMMANDS:
        supported = ", ".join(f"{name} ({num})" for num, name in SUPPORTED_COMMANDS.items())
        raise MissionError(
            f"item {index}: unsupported command {command_name(item.command)} ({item.command}); supported: {supported}"
        )
    if item.is_nav and item.frame not in AMSL_FRAMES | RELATIVE_FRAMES:
        raise MissionError(
            f"{item.describe(index)}: unsupported frame {item.frame}; use "
            f"GLOBAL (0), GLOBAL_RELATIVE_ALT (3) or their _INT variants (5, 6)"
        )
    if item.is_nav:
        check_lat_lon_deg(item.lat_deg, item.lon_deg, item.describe(index))
        if not math.isfinite(item.alt_m):
            raise MissionError(f"{item.describe(index)}: altitude {item.alt_m} is not a number")
    if item.command == MAV_CMD_NAV_WAYPOINT:
        if math.isfinite(item.param1) and item.param1 < 0:
            raise MissionError(f"{item.describe(index)}: hold time param1 {item.param1} s < 0")
        if math.isfinite(item.param2) and item.param2 < 0:
            raise MissionError(f"{item.describe(index)}: acceptance radius param2 {item.param2} m < 0")


# ----------------------------------------------------------------------------- local form

WAYPOINT_KINDS = ("takeoff", "waypoint", "land", "rtl")


@dataclass(frozen=True)
class LocalWaypoint:
    """One goal of the local mission.

    Parameters
    ----------
    seq : int
        Vehicle sequence number of the mission item it comes from (``plan.items[seq - 1]``;
        as in MISSION_ITEM_REACHED and in error messages).
    kind : str
        ``'takeoff'`` (climb vertically to ``pos_ned_m``), ``'waypoint'``, ``'land'`` (fly to
        ``pos_ned_m`` at the current altitude then descend; ``pos_ned_m[2]`` is the ground,
        0 = home level) or ``'rtl'`` (fly to home at the current altitude, then land).
    pos_ned_m : ndarray, shape (3,)
        Goal in local NED metres about home.
    acceptance_radius_m : float
        Radius within which the goal counts as reached.
    hold_s : float
        Hover time at the goal.
    speed_m_s : float or None
        Cruise speed for the leg to this goal (None: the daemon's default).
    """

    seq: int
    kind: str
    pos_ned_m: np.ndarray
    acceptance_radius_m: float
    hold_s: float = 0.0
    speed_m_s: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in WAYPOINT_KINDS:
            raise MissionError(f"waypoint kind {self.kind!r} is not one of {WAYPOINT_KINDS}")
        pos = np.asarray(self.pos_ned_m, dtype=np.float64).reshape(3)
        pos.setflags(write=False)
        object.__setattr__(self, "pos_ned_m", pos)

    @property
    def altitude_m(self) -> float:
        """Height above home (= -down)."""
        return float(-self.pos_ned_m[2])


@dataclass(frozen=True)
class LocalMission:
    """A mission in the local NED frame about home, ready for planning.

    Parameters
    ----------
    frame : companion.geo.LocalFrame
        Origin = home.
    waypoints : tuple of LocalWaypoint
        In flight order.
    world : companion.world.World
        Obstacles from the exclusion zones (and the world file), bounds from the inclusion
        polygon or the mission extent.
    rally_ned_m : ndarray, shape (R, 3)
    end_action : str
        ``'land'``, ``'rtl'`` or ``'hover'`` (the mission ends with neither).
    """

    frame: object
    waypoints: tuple[LocalWaypoint, ...]
    world: object
    rally_ned_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    end_action: str = "hover"

    @property
    def goals_ned_m(self) -> np.ndarray:
        """All waypoint positions, shape (W, 3)."""
        if not self.waypoints:
            return np.zeros((0, 3))
        return np.vstack([w.pos_ned_m for w in self.waypoints])
