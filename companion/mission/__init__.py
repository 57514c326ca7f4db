"""Mission files and missions: ``.plan`` / ``QGC WPL 110`` in and out, local NED conversion.

>>> plan = load_mission_file("mission_files/exclusion_zones.plan")       # doctest: +SKIP
>>> local = mission_to_local(plan, home_lla=(47.397742, 8.545594, 488.0))  # doctest: +SKIP
>>> local.waypoints[1].pos_ned_m, local.world                            # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

from companion.errors import MissionError
from companion.mission.convert import ConversionSettings, mission_to_local
from companion.mission.model import (
    SUPPORTED_COMMANDS,
    FenceCircle,
    FencePolygon,
    LocalMission,
    LocalWaypoint,
    MissionItem,
    MissionPlan,
    RallyPoint,
)
from companion.mission.plan_file import read_plan_file, read_plan_text, write_plan_file
from companion.mission.wpl_file import read_wpl_file, read_wpl_text, write_wpl_file

__all__ = [
    "ConversionSettings",
    "FenceCircle",
    "FencePolygon",
    "LocalMission",
    "LocalWaypoint",
    "MissionItem",
    "MissionPlan",
    "RallyPoint",
    "SUPPORTED_COMMANDS",
    "load_mission_file",
    "mission_file_kind",
    "mission_to_local",
    "read_plan_file",
    "read_plan_text",
    "read_wpl_file",
    "read_wpl_text",
    "save_mission_file",
    "write_plan_file",
    "write_wpl_file",
]

PLAN_SUFFIXES = (".plan",)
WPL_SUFFIXES = (".waypoints", ".txt", ".wpl", ".mission")


def mission_file_kind(path: str | Path) -> str:
    """``'plan'`` or ``'wpl'`` from the file name's extension (error naming the file if neither)."""
    suffix = Path(path).suffix.lower()
    if suffix in PLAN_SUFFIXES:
        return "plan"
    if suffix in WPL_SUFFIXES:
        return "wpl"
    raise MissionError(
        f"{path}: unknown mission file extension {suffix!r}; use .plan (QGroundControl) or .waypoints (QGC WPL 110)"
    )


def load_mission_file(path: str | Path) -> MissionPlan:
    """Read and validate a ``.plan`` or ``QGC WPL 110`` file (chosen by extension).

    A ``.waypoints``/``.txt`` file that is really JSON, or the reverse, is detected by content.

    Raises
    ------
    MissionError
        Naming the file and the line, field or item at fault.
    """
    path = Path(path)
    if not path.is_file():
        raise MissionError(f"mission file {path} does not exist")
    kind = mission_file_kind(path)
    try:
        head = path.read_text(encoding="utf-8", errors="replace").lstrip()[:20]
    except OSError as exc:
        raise MissionError(f"cannot read mission file {path}: {exc}") from None
    if head.startswith("QGC WPL"):
        kind = "wpl"
    elif head.startswith("{") and kind == "wpl":
        kind = "plan"
    return read_plan_file(path) if kind == "plan" else read_wpl_file(path)


def save_mission_file(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as ``.plan`` or ``QGC WPL 110`` by the extension of ``path``."""
    if mission_file_kind(path) == "plan":
        write_plan_file(plan, path)
    else:
        write_wpl_file(plan, path)
