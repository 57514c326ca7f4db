"""QGroundControl ``.plan`` files (JSON, ``fileType`` ``"Plan"``): reader and writer.

Format: QGroundControl developer guide, "Plan File Format" (mission version 2, geoFence version
2, rallyPoints version 2). Supported: ``SimpleItem`` mission items, geofence inclusion/exclusion
polygons and circles, rally points, ``plannedHomePosition``, ``cruiseSpeed``/``hoverSpeed``.
``ComplexItem`` entries (survey, corridor scan, structure scan) are *not* supported: the reader
rejects them with an error naming the item; convert them to waypoints in QGroundControl first.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from companion.errors import MissionError
from companion.mission.model import (
    AMSL_FRAMES,
    NAV_COMMANDS,
    FenceCircle,
    FencePolygon,
    MissionItem,
    MissionPlan,
    RallyPoint,
)
from heli_common.mavlink_ids import mavlink

PLAN_FILE_TYPE = "Plan"
MAV_AUTOPILOT_ARDUPILOTMEGA = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
MAV_TYPE_HELICOPTER = mavlink.MAV_TYPE_HELICOPTER


def read_plan_text(text: str, source: str = "<plan>") -> MissionPlan:
    """Parse the JSON text of a ``.plan`` file.

    Parameters
    ----------
    text : str
    source : str
        File name for error messages.

    Returns
    -------
    MissionPlan
        Validated (``MissionPlan.validate``).

    Raises
    ------
    MissionError
        Broken JSON (with line and column), missing or mistyped fields (with their JSON path),
        complex items, unsupported commands, coordinates out of range, an empty mission.
    """
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MissionError(f"{source}: broken JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    plan = parse_plan_document(doc, source)
    plan.validate()
    return plan


def read_plan_file(path: str | Path) -> MissionPlan:
    """Read and validate a QGroundControl ``.plan`` file (see ``read_plan_text``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(f"cannot read mission file {path}: {exc}") from None
    return read_plan_text(text, str(path))


def parse_plan_document(doc, source: str) -> MissionPlan:
    """Build a ``MissionPlan`` from a decoded ``.plan`` JSON document (not yet validated)."""
    require_type(doc, dict, "top level", source)
    file_type = doc.get("fileType")
    if file_type != PLAN_FILE_TYPE:
        raise MissionError(
            f"{source}: fileType is {file_type!r}, expected {PLAN_FILE_TYPE!r} (is this a QGroundControl .plan file?)"
        )
    mission = require_key(doc, "mission", dict, "", source)
    items_json = require_key(mission, "items", list, "mission", source)
    items = tuple(parse_item(entry, index, source) for index, entry in enumerate(items_json))
    home = parse_planned_home(mission.get("plannedHomePosition"), source)
    polygons, circles = parse_geofence(doc.get("geoFence"), source)
    rally = parse_rally(doc.get("rallyPoints"), source)
    return MissionPlan(
        items=items,
        polygons=polygons,
        circles=circles,
        rally=rally,
        planned_home=home,
        cruise_speed_m_s=optional_number(mission, "cruiseSpeed", source),
        hover_speed_m_s=optional_number(mission, "hoverSpeed", source),
    )


def require_type(value, kind, where: str, source: str):
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        names = {
            dict: "an object",
            list: "an array",
            int: "an integer",
            float: "a number",
            (int, float): "a number",
            bool: "true or false",
        }
        raise MissionError(f"{source}: {where} must be {names.get(kind, kind)}, got {type(value).__name__}")
    return value


def require_key(obj: dict, key: str, kind, parent: str, source: str):
    where = f"{parent}.{key}" if parent else key
    if key not in obj:
        raise MissionError(f"{source}: missing field {where}")
    return require_type(obj[key], kind, where, source)


def optional_number(obj: dict, key: str, source: str) -> float | None:
    value = obj.get(key)
    if value is None:
        return None
    return float(require_type(value, (int, float), f"mission.{key}", source))


def param_value(value, where: str, source: str) -> float:
    """A ``params`` entry: a number, or ``null`` meaning NaN (QGroundControl's convention)."""
    if value is None:
        return math.nan
    return float(require_type(value, (int, float), where, source))


def parse_item(entry, index: int, source: str) -> MissionItem:
    """One entry of ``mission.items`` -> ``MissionItem`` (SimpleItem only)."""
    where = f"mission.items[{index}] (item {index + 1})"
    require_type(entry, dict, where, source)
    item_type = entry.get("type", "SimpleItem")
    if item_type == "ComplexItem":
        kind = entry.get("complexItemType", "complex item")
        raise MissionError(
            f"{source}: {where} is a ComplexItem ({kind}): unsupported; convert it to waypoints in QGroundControl"
        )
    if item_type != "SimpleItem":
        raise MissionError(f"{source}: {where}: unknown item type {item_type!r}")
    command = require_key(entry, "command", int, where, source)
    frame = require_key(entry, "frame", int, where, source)
    params = require_key(entry, "params", list, where, source)
    if len(params) != 7:
        raise MissionError(
            f"{source}: {where}.params has {len(params)} entries, expected 7 "
            f"(param1..param4, latitude, longitude, altitude)"
        )
    values = [param_value(v, f"{where}.params[{k}]", source) for k, v in enumerate(params)]
    if command in NAV_COMMANDS:
        for k, name in ((4, "latitude"), (5, "longitude"), (6, "altitude")):
            if not math.isfinite(values[k]):
                raise MissionError(f"{source}: {where}: {name} params[{k}] is missing (null)")
    lat, lon, alt = (0.0 if not math.isfinite(v) else v for v in values[4:7])
    auto = entry.get("autoContinue", True)
    return MissionItem(
        command=command,
        frame=frame,
        param1=values[0],
        param2=values[1],
        param3=values[2],
        param4=values[3],
        lat_deg=lat,
        lon_deg=lon,
        alt_m=alt,
        autocontinue=bool(auto),
    )


def parse_planned_home(value, source: str) -> tuple[float, float, float] | None:
    if value is None:
        return None
    require_type(value, list, "mission.plannedHomePosition", source)
    if len(value) != 3:
        raise MissionError(f"{source}: mission.plannedHomePosition must be [lat, lon, alt], got {len(value)} values")
    lat, lon, alt = (float(require_type(v, (int, float), "mission.plannedHomePosition", source)) for v in value)
    return lat, lon, alt


def parse_geofence(fence, source: str) -> tuple[tuple[FencePolygon, ...], tuple[FenceCircle, ...]]:
    if fence is None:
        return (), ()
    require_type(fence, dict, "geoFence", source)
    polygons = []
    for k, entry in enumerate(require_type(fence.get("polygons", []), list, "geoFence.polygons", source)):
        where = f"geoFence.polygons[{k}]"
        require_type(entry, dict, where, source)
        vertices = require_key(entry, "polygon", list, where, source)
        pairs = []
        for j, vertex in enumerate(vertices):
            require_type(vertex, list, f"{where}.polygon[{j}]", source)
            if len(vertex) != 2:
                raise MissionError(f"{source}: {where}.polygon[{j}] must be [lat, lon]")
            lat, lon = (float(require_type(v, (int, float), f"{where}.polygon[{j}]", source)) for v in vertex)
            pairs.append((lat, lon))
        inclusion = bool(entry.get("inclusion", True))
        try:
            polygons.append(FencePolygon(tuple(pairs), inclusion))
        except MissionError as exc:
            raise MissionError(f"{source}: {where}: {exc}") from None
    circles = []
    for k, entry in enumerate(require_type(fence.get("circles", []), list, "geoFence.circles", source)):
        where = f"geoFence.circles[{k}]"
        require_type(entry, dict, where, source)
        circle = require_key(entry, "circle", dict, where, source)
        center = require_key(circle, "center", list, f"{where}.circle", source)
        if len(center) != 2:
            raise MissionError(f"{source}: {where}.circle.center must be [lat, lon]")
        lat, lon = (float(require_type(v, (int, float), f"{where}.circle.center", source)) for v in center)
        radius = float(require_key(circle, "radius", (int, float), f"{where}.circle", source))
        inclusion = bool(entry.get("inclusion", True))
        try:
            circles.append(FenceCircle(lat, lon, radius, inclusion))
        except MissionError as exc:
            raise MissionError(f"{source}: {where}: {exc}") from None
    return tuple(polygons), tuple(circles)


def parse_rally(rally, source: str) -> tuple[RallyPoint, ...]:
    if rally is None:
        return ()
    require_type(rally, dict, "rallyPoints", source)
    points = []
    for k, entry in enumerate(require_type(rally.get("points", []), list, "rallyPoints.points", source)):
        where = f"rallyPoints.points[{k}]"
        require_type(entry, list, where, source)
        if len(entry) != 3:
            raise MissionError(f"{source}: {where} must be [lat, lon, alt]")
        lat, lon, alt = (float(require_type(v, (int, float), where, source)) for v in entry)
        try:
            points.append(RallyPoint(lat, lon, alt))
        except MissionError as exc:
            raise MissionError(f"{source}: {where}: {exc}") from None
    return tuple(points)


# ----------------------------------------------------------------------------- writer


def json_number(value: float):
    """NaN -> ``null`` (QGroundControl's convention), integral floats stay floats."""
    return None if value is None or not math.isfinite(value) else float(value)


def item_to_json(item: MissionItem, jump_id: int) -> dict:
    entry = {
        "autoContinue": bool(item.autocontinue),
        "command": int(item.command),
        "doJumpId": jump_id,
        "frame": int(item.frame),
        "params": [
            json_number(item.param1),
            json_number(item.param2),
            json_number(item.param3),
            json_number(item.param4),
            float(item.lat_deg),
            float(item.lon_deg),
            float(item.alt_m),
        ],
        "type": "SimpleItem",
    }
    if item.is_nav:
        entry["AMSLAltAboveTerrain"] = None
        entry["Altitude"] = float(item.alt_m)
        entry["AltitudeMode"] = 2 if item.frame in AMSL_FRAMES else 1
    return entry


def plan_to_document(plan: MissionPlan) -> dict:
    """``MissionPlan`` -> ``.plan`` JSON document (QGroundControl reads it)."""
    home = plan.planned_home
    if home is None:
        home = next(((i.lat_deg, i.lon_deg, 0.0) for i in plan.items if i.has_position), (0.0, 0.0, 0.0))
    mission = {
        "cruiseSpeed": plan.cruise_speed_m_s if plan.cruise_speed_m_s is not None else 15.0,
        "firmwareType": MAV_AUTOPILOT_ARDUPILOTMEGA,
        "globalPlanAltitudeMode": 1,
        "hoverSpeed": plan.hover_speed_m_s if plan.hover_speed_m_s is not None else 5.0,
        "items": [item_to_json(item, k + 1) for k, item in enumerate(plan.items)],
        "plannedHomePosition": [float(home[0]), float(home[1]), float(home[2])],
        "vehicleType": MAV_TYPE_HELICOPTER,
        "version": 2,
    }
    geofence = {
        "circles": [
            {"circle": {"center": [c.lat_deg, c.lon_deg], "radius": c.radius_m}, "inclusion": c.inclusion, "version": 1}
            for c in plan.circles
        ],
        "polygons": [
            {"inclusion": p.inclusion, "polygon": [list(v) for v in p.vertices_deg], "version": 1}
            for p in plan.polygons
        ],
        "version": 2,
    }
    rally = {"points": [[r.lat_deg, r.lon_deg, r.alt_m] for r in plan.rally], "version": 2}
    return {
        "fileType": PLAN_FILE_TYPE,
        "geoFence": geofence,
        "groundStation": "QGroundControl",
        "mission": mission,
        "rallyPoints": rally,
        "version": 1,
    }


def write_plan_file(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as a QGroundControl ``.plan`` file (atomic replace)."""
    path = Path(path)
    text = json.dumps(plan_to_document(plan), indent=4) + "\n"
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        raise MissionError(f"cannot write mission file {path}: {exc}") from None
