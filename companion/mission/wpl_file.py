"""``QGC WPL 110`` waypoint files (Mission Planner, MAVProxy ``wp load``/``wp save``, QGroundControl).

Format (MAVProxy ``mavwp.MAVWPLoader``, Mission Planner): the header line ``QGC WPL 110``, then
one mission item per line with 12 tab-separated columns::

    INDEX CURRENT FRAME COMMAND PARAM1 PARAM2 PARAM3 PARAM4 X/LAT Y/LON Z/ALT AUTOCONTINUE

Line with index 0 is the home position (ArduPilot's mission item 0); the mission is the items
with index 1.. in order. The format holds no geofence and no rally points: ``.plan`` files do.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from companion.errors import MissionError
from companion.mission.model import MissionItem, MissionPlan

log = logging.getLogger(__name__)

WPL_HEADER = "QGC WPL 110"
WPL_COLUMNS = 12


def read_wpl_text(text: str, source: str = "<waypoints>") -> MissionPlan:
    """Parse the text of a ``QGC WPL 110`` file.

    Returns
    -------
    MissionPlan
        Validated; ``planned_home`` from the index-0 line if present.

    Raises
    ------
    MissionError
        Wrong header, wrong column count, non-numeric values, out-of-order indices (each with
        its line number), unsupported commands, empty mission.
    """
    lines = text.splitlines()
    if not lines or lines[0].strip() != WPL_HEADER:
        first = lines[0].strip() if lines else ""
        raise MissionError(f"{source}: line 1: expected header {WPL_HEADER!r}, got {first!r}")
    home = None
    items: list[MissionItem] = []
    expected_index = None
    for line_no, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        index, item = parse_wpl_line(line, line_no, source)
        if expected_index is None:
            expected_index = index
        if index != expected_index:
            raise MissionError(f"{source}: line {line_no}: item index {index}, expected {expected_index}")
        expected_index += 1
        if index == 0:
            home = (item.lat_deg, item.lon_deg, item.alt_m)
        else:
            items.append(item)
    try:
        plan = MissionPlan(items=tuple(items), planned_home=home if home and any(home) else None)
    except MissionError as exc:
        raise MissionError(f"{source}: {exc}") from None
    try:
        plan.validate()
    except MissionError as exc:
        # items are named by their seq, which is the file's index column
        raise MissionError(f"{source}: {exc}") from None
    return plan


def parse_wpl_line(line: str, line_no: int, source: str) -> tuple[int, MissionItem]:
    """One item line -> (index, MissionItem)."""
    fields = line.split("\t") if "\t" in line else line.split()
    fields = [f.strip() for f in fields if f.strip() != ""]
    if len(fields) != WPL_COLUMNS:
        raise MissionError(
            f"{source}: line {line_no}: {len(fields)} columns, expected "
            f"{WPL_COLUMNS} (index current frame command p1 p2 p3 p4 lat lon "
            f"alt autocontinue)"
        )
    try:
        index, current, frame, command = (int(fields[k]) for k in range(4))
        p1, p2, p3, p4, lat, lon, alt = (float(fields[k]) for k in range(4, 11))
        autocontinue = int(float(fields[11]))
    except ValueError as exc:
        raise MissionError(f"{source}: line {line_no}: not a number: {exc}") from None
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
        raise MissionError(f"{source}: line {line_no}: latitude/longitude/altitude must be numbers")
    if abs(lat) > 90.0:
        raise MissionError(f"{source}: line {line_no}: latitude {lat} deg is out of range [-90, 90]")
    if abs(lon) > 180.0:
        raise MissionError(f"{source}: line {line_no}: longitude {lon} deg is out of range [-180, 180]")
    del current
    item = MissionItem(
        command=command,
        frame=frame,
        param1=p1,
        param2=p2,
        param3=p3,
        param4=p4,
        lat_deg=lat,
        lon_deg=lon,
        alt_m=alt,
        autocontinue=bool(autocontinue),
    )
    return index, item


def read_wpl_file(path: str | Path) -> MissionPlan:
    """Read and validate a ``QGC WPL 110`` file (see ``read_wpl_text``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(f"cannot read mission file {path}: {exc}") from None
    return read_wpl_text(text, str(path))


def format_number(value: float) -> str:
    """Shortest exact text of a float (``nan`` for NaN, as MAVProxy reads it)."""
    if not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if value == int(value) and abs(value) < 1e15:
        return f"{value:.1f}"
    return repr(float(value))


def wpl_line(index: int, item: MissionItem, current: int = 0) -> str:
    cols = [str(index), str(current), str(int(item.frame)), str(int(item.command))]
    cols += [format_number(v) for v in (item.param1, item.param2, item.param3, item.param4)]
    cols += [format_number(item.lat_deg), format_number(item.lon_deg), format_number(item.alt_m)]
    cols.append("1" if item.autocontinue else "0")
    return "\t".join(cols)


def plan_to_wpl_text(plan: MissionPlan) -> str:
    """``MissionPlan`` -> ``QGC WPL 110`` text (home as index 0, then the items)."""
    if plan.polygons or plan.circles or plan.rally:
        log.warning(
            "QGC WPL 110 holds no geofence or rally points: %d polygons, %d circles and "
            "%d rally points are not written (use a .plan file)",
            len(plan.polygons),
            len(plan.circles),
            len(plan.rally),
        )
    home = plan.planned_home or (0.0, 0.0, 0.0)
    home_item = MissionItem(command=16, frame=0, lat_deg=home[0], lon_deg=home[1], alt_m=home[2])
    lines = [WPL_HEADER, wpl_line(0, home_item, current=1)]
    lines += [wpl_line(k + 1, item) for k, item in enumerate(plan.items)]
    return "\n".join(lines) + "\n"


def write_wpl_file(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan``'s mission as a ``QGC WPL 110`` file (atomic replace)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(plan_to_wpl_text(plan), encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        raise MissionError(f"cannot write mission file {path}: {exc}") from None
