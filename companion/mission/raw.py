"""MissionPlan <-> the three MAVLink item lists of the mission protocol (MISSION_ITEM_INT).

MAVLink mission protocol (mavlink.io "Mission Protocol"), ArduPilot conventions:

- mission (MAV_MISSION_TYPE_MISSION = 0): seq 0 is the home position (NAV_WAYPOINT, frame
  GLOBAL, altitude AMSL); the plan's items follow as seq 1..N;
- fence (MAV_MISSION_TYPE_FENCE = 1): polygons as runs of NAV_FENCE_POLYGON_VERTEX_INCLUSION /
  _EXCLUSION items whose param1 is the vertex count; circles as NAV_FENCE_CIRCLE_INCLUSION /
  _EXCLUSION with param1 the radius in metres; frame GLOBAL;
- rally (MAV_MISSION_TYPE_RALLY = 2): NAV_RALLY_POINT items, frame GLOBAL_RELATIVE_ALT.

Latitude and longitude travel as degrees * 1e7 integers. Pure data conversion: the link turns
``RawItem`` into MAVSDK's ``MissionRaw.MissionItem``.
"""

from __future__ import annotations

from collections.abc import Sequence

from companion.errors import MissionError
from companion.mission.model import (
    MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
    MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
    MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    MAV_CMD_NAV_FENCE_RETURN_POINT,
    MAV_CMD_NAV_RALLY_POINT,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    FenceCircle,
    FencePolygon,
    MissionItem,
    MissionPlan,
    RallyPoint,
)
from heli_common.mavlink_ids import mavlink
from heli_common.mission_item import MissionItemInt

MAV_MISSION_TYPE_MISSION = mavlink.MAV_MISSION_TYPE_MISSION
MAV_MISSION_TYPE_FENCE = mavlink.MAV_MISSION_TYPE_FENCE
MAV_MISSION_TYPE_RALLY = mavlink.MAV_MISSION_TYPE_RALLY
DEG_E7 = 1e7


#: A MISSION_ITEM_INT, field for field (``x``/``y`` are degrees * 1e7): the project's one
#: mission item record, shared with the SITL vehicle.
RawItem = MissionItemInt


def deg_to_e7(value_deg: float) -> int:
    return int(round(value_deg * DEG_E7))


def e7_to_deg(value_e7: int) -> float:
    return value_e7 / DEG_E7


def mission_to_raw(
    plan: MissionPlan, home_lla: tuple[float, float, float] | None = None, *, with_home: bool = True
) -> list[RawItem]:
    """The mission list: home at seq 0 (if ``with_home``), then ``plan.items``.

    Parameters
    ----------
    home_lla : (lat_deg, lon_deg, alt_m AMSL) or None
        Home for seq 0; default ``plan.planned_home``, else zeros (ArduPilot overwrites it).
    """
    raw: list[RawItem] = []
    if with_home:
        home = home_lla or plan.planned_home or (0.0, 0.0, 0.0)
        raw.append(
            RawItem(
                0,
                MAV_FRAME_GLOBAL,
                MAV_CMD_NAV_WAYPOINT,
                1,
                1,
                0.0,
                0.0,
                0.0,
                0.0,
                deg_to_e7(home[0]),
                deg_to_e7(home[1]),
                float(home[2]),
                MAV_MISSION_TYPE_MISSION,
            )
        )
    for item in plan.items:
        # MAVSDK requires exactly one item flagged current: the first one
        raw.append(
            RawItem(
                len(raw),
                int(item.frame),
                int(item.command),
                int(not raw),
                int(item.autocontinue),
                float(item.param1),
                float(item.param2),
                float(item.param3),
                float(item.param4),
                deg_to_e7(item.lat_deg),
                deg_to_e7(item.lon_deg),
                float(item.alt_m),
                MAV_MISSION_TYPE_MISSION,
            )
        )
    return raw


def fence_to_raw(plan: MissionPlan) -> list[RawItem]:
    """The fence list: every polygon's vertices, then every circle."""
    raw: list[RawItem] = []
    for polygon in plan.polygons:
        command = (
            MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
            if polygon.inclusion
            else MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        )
        count = float(len(polygon.vertices_deg))
        for lat, lon in polygon.vertices_deg:
            raw.append(
                RawItem(
                    len(raw),
                    MAV_FRAME_GLOBAL,
                    command,
                    0,
                    1,
                    count,
                    0.0,
                    0.0,
                    0.0,
                    deg_to_e7(lat),
                    deg_to_e7(lon),
                    0.0,
                    MAV_MISSION_TYPE_FENCE,
                )
            )
    for circle in plan.circles:
        command = MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION if circle.inclusion else MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
        raw.append(
            RawItem(
                len(raw),
                MAV_FRAME_GLOBAL,
                command,
                0,
                1,
                float(circle.radius_m),
                0.0,
                0.0,
                0.0,
                deg_to_e7(circle.lat_deg),
                deg_to_e7(circle.lon_deg),
                0.0,
                MAV_MISSION_TYPE_FENCE,
            )
        )
    return raw


def rally_to_raw(plan: MissionPlan) -> list[RawItem]:
    """The rally list (altitudes above home)."""
    return [
        RawItem(
            k,
            MAV_FRAME_GLOBAL_RELATIVE_ALT,
            MAV_CMD_NAV_RALLY_POINT,
            0,
            1,
            0.0,
            0.0,
            0.0,
            0.0,
            deg_to_e7(r.lat_deg),
            deg_to_e7(r.lon_deg),
            float(r.alt_m),
            MAV_MISSION_TYPE_RALLY,
        )
        for k, r in enumerate(plan.rally)
    ]


def raw_to_mission_items(
    raw: list[RawItem], *, with_home: bool = True
) -> tuple[tuple[MissionItem, ...], tuple[float, float, float] | None]:
    """Mission list -> (items, home). With ``with_home`` seq 0 is taken as home."""
    ordered = sorted(raw, key=lambda r: r.seq)
    home = None
    if with_home and ordered:
        first = ordered[0]
        home = (e7_to_deg(first.x), e7_to_deg(first.y), float(first.z))
        ordered = ordered[1:]
    items = tuple(
        MissionItem(
            command=r.command,
            frame=r.frame,
            param1=r.param1,
            param2=r.param2,
            param3=r.param3,
            param4=r.param4,
            lat_deg=e7_to_deg(r.x),
            lon_deg=e7_to_deg(r.y),
            alt_m=float(r.z),
            autocontinue=bool(r.autocontinue),
        )
        for r in ordered
    )
    if home is not None and home[0] == 0.0 and home[1] == 0.0:
        home = None
    return items, home


def raw_to_fence(raw: list[RawItem]) -> tuple[tuple[FencePolygon, ...], tuple[FenceCircle, ...]]:
    """Fence list -> (polygons, circles).

    Raises
    ------
    MissionError
        A polygon run shorter than its vertex count, or an unknown fence command.
    """
    ordered = sorted(raw, key=lambda r: r.seq)
    polygons: list[FencePolygon] = []
    circles: list[FenceCircle] = []
    k = 0
    while k < len(ordered):
        item = ordered[k]
        if item.command in (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
            count = int(round(item.param1))
            run = ordered[k : k + count]
            if count < 3 or len(run) < count or any(r.command != item.command for r in run):
                raise MissionError(f"fence item {item.seq}: polygon of {count} vertices is incomplete")
            polygons.append(
                FencePolygon(
                    tuple((e7_to_deg(r.x), e7_to_deg(r.y)) for r in run),
                    item.command == MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                )
            )
            k += count
        elif item.command in (MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
            circles.append(
                FenceCircle(
                    e7_to_deg(item.x),
                    e7_to_deg(item.y),
                    float(item.param1),
                    item.command == MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                )
            )
            k += 1
        elif item.command == MAV_CMD_NAV_FENCE_RETURN_POINT:
            k += 1  # the companion does not use ArduPilot's fence return point
        else:
            raise MissionError(f"fence item {item.seq}: unknown fence command {item.command}")
    return tuple(polygons), tuple(circles)


def raw_to_rally(raw: list[RawItem]) -> tuple[RallyPoint, ...]:
    """Rally list -> rally points (non-rally commands are an error naming the item)."""
    points = []
    for item in sorted(raw, key=lambda r: r.seq):
        if item.command != MAV_CMD_NAV_RALLY_POINT:
            raise MissionError(f"rally item {item.seq}: unknown rally command {item.command}")
        points.append(RallyPoint(e7_to_deg(item.x), e7_to_deg(item.y), float(item.z)))
    return tuple(points)


def raw_to_plan(
    mission: Sequence[RawItem], fence: Sequence[RawItem] = (), rally: Sequence[RawItem] = (), *, with_home: bool = True
) -> MissionPlan:
    """The three downloaded lists -> ``MissionPlan`` (not validated: a download keeps any item)."""
    items, home = raw_to_mission_items(list(mission), with_home=with_home)
    polygons, circles = raw_to_fence(list(fence))
    return MissionPlan(
        items=items, polygons=polygons, circles=circles, rally=raw_to_rally(list(rally)), planned_home=home
    )
