"""The fleet's missions: picking them from a directory, their homes and first headings, and
generating crossing and head-on missions (the files of ``mission_files/fleet/`` and of
``benchmarks/fleet.py``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from companion.errors import ConfigError, MissionError

__all__ = [
    "MISSION_SUFFIXES",
    "select_missions",
    "mission_home",
    "first_leg_heading_deg",
    "crossing_missions",
    "head_on_missions",
    "write_missions",
    "planned_length_m",
]

#: Mission files the fleet takes from a directory (sorted by name).
MISSION_SUFFIXES = (".plan", ".waypoints")


def select_missions(mission_dir: str | Path, count: int) -> list[Path]:
    """The first ``count`` mission files (``*.plan``, ``*.waypoints``, sorted) of ``mission_dir``.

    Raises
    ------
    ConfigError
        ``count`` < 1, no such directory, or fewer files than ``count`` (naming the directory and
        how many it has).
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ConfigError(f"--vehicles: expected an integer >= 1, got {count!r}")
    directory = Path(mission_dir)
    if not directory.is_dir():
        raise ConfigError(f"--mission-dir: {directory} is not a directory")
    files = sorted(p for p in directory.iterdir() if p.is_file() and p.suffix.lower() in MISSION_SUFFIXES)
    if len(files) < count:
        raise ConfigError(
            f"--mission-dir: {directory} has {len(files)} mission file(s) (*.plan, *.waypoints), "
            f"fewer than --vehicles {count}"
        )
    return files[:count]


def mission_home(path: str | Path) -> tuple[float, float, float]:
    """The home (lat deg, lon deg, alt m AMSL) a mission file plans from: a ``.plan``'s
    ``mission.plannedHomePosition``, a ``QGC WPL 110`` file's item 0.

    Raises
    ------
    MissionError
        The file is invalid or gives no home (naming the file).
    """
    from companion.mission import load_mission_file

    plan = load_mission_file(path)
    if plan.planned_home is None:
        raise MissionError(
            f"{path}: the mission gives no home (plannedHomePosition, or item 0 of a "
            f"QGC WPL file): the fleet starts each vehicle at its mission's home"
        )
    return plan.planned_home


def first_leg_heading_deg(path: str | Path) -> float:
    """Bearing (degrees from north, 0-360) from a mission's home to its first waypoint away from
    home (more than 1 m horizontally); 0 when there is none. The fleet parks each vehicle
    facing it."""
    from companion.mission import load_mission_file, mission_to_local

    local = mission_to_local(load_mission_file(path), home_lla=mission_home(path))
    for w in local.waypoints:
        n, e = float(w.pos_ned_m[0]), float(w.pos_ned_m[1])
        if math.hypot(n, e) > 1.0:
            return math.degrees(math.atan2(e, n)) % 360.0
    return 0.0


def _mission_plan(home_lla, waypoints_ned_m, *, alt_m: float, speed_m_s: float):
    """A ``MissionPlan``: takeoff to ``alt_m`` above home, the speed, the waypoints (NED about
    home, flown at ``alt_m`` above home), RTL."""
    from companion.geo import LocalFrame
    from companion.mission.model import (
        MAV_CMD_DO_CHANGE_SPEED,
        MAV_CMD_NAV_RETURN_TO_LAUNCH,
        MAV_CMD_NAV_TAKEOFF,
        MAV_CMD_NAV_WAYPOINT,
        MAV_FRAME_MISSION,
        MissionItem,
        MissionPlan,
    )

    frame = LocalFrame(*home_lla)
    items = [
        MissionItem(MAV_CMD_NAV_TAKEOFF, alt_m=float(alt_m)),
        MissionItem(MAV_CMD_DO_CHANGE_SPEED, frame=MAV_FRAME_MISSION, param1=1.0, param2=float(speed_m_s), param3=-1.0),
    ]
    for n, e in waypoints_ned_m:
        lat, lon, _ = frame.to_lla(n, e, 0.0)
        items.append(
            MissionItem(
                MAV_CMD_NAV_WAYPOINT,
                param2=2.0,
                lat_deg=round(float(lat), 8),
                lon_deg=round(float(lon), 8),
                alt_m=float(alt_m),
            )
        )
    items.append(MissionItem(MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=MAV_FRAME_MISSION))
    return MissionPlan(
        items=tuple(items),
        planned_home=tuple(float(v) for v in home_lla),
        cruise_speed_m_s=float(speed_m_s),
        hover_speed_m_s=5.0,
    )


def crossing_missions(
    count: int,
    *,
    centre_lla=(47.397742, 8.545594, 488.0),
    radius_m: float = 70.0,
    beyond_m: float = 30.0,
    alt_m: float = 15.0,
    speed_m_s: float = 7.0,
    first_bearing_deg: float = 0.0,
) -> list:
    """``count`` missions whose legs cross at one point at about the same time.

    Vehicle ``i``'s home is ``radius_m`` from ``centre_lla`` at bearing ``first_bearing_deg +
    360 i / count``; it takes off to ``alt_m`` above home, flies through the centre to
    ``beyond_m`` past it at ``speed_m_s`` and returns home (RTL: back through the centre). Every
    home is at the centre's altitude, so all fly at one altitude: they truly conflict.

    Returns
    -------
    list of companion.mission.MissionPlan
    """
    from companion.geo import LocalFrame

    if count < 1:
        raise ConfigError(f"count: expected >= 1, got {count}")
    centre = LocalFrame(*centre_lla)
    plans = []
    for i in range(count):
        bearing = math.radians(first_bearing_deg + 360.0 * i / count)
        u = np.array([math.cos(bearing), math.sin(bearing)])
        home_ne = radius_m * u
        lat, lon, _ = centre.to_lla(home_ne[0], home_ne[1], 0.0)
        home = (round(float(lat), 8), round(float(lon), 8), float(centre_lla[2]))
        far_ne = -beyond_m * u - home_ne  # about the vehicle's home
        plans.append(_mission_plan(home, [far_ne], alt_m=alt_m, speed_m_s=speed_m_s))
    return plans


def head_on_missions(
    *,
    centre_lla=(47.397742, 8.545594, 488.0),
    half_length_m: float = 60.0,
    alt_m: float = 15.0,
    speed_m_s: float = 7.0,
    bearing_deg: float = 90.0,
) -> list:
    """Two missions along one corridor, head-on: each flies from its home to the other's and back
    (RTL), at one altitude. Returns two ``MissionPlan``."""
    return crossing_missions(
        2,
        centre_lla=centre_lla,
        radius_m=half_length_m,
        beyond_m=half_length_m,
        alt_m=alt_m,
        speed_m_s=speed_m_s,
        first_bearing_deg=bearing_deg,
    )


def write_missions(plans, out_dir: str | Path, stem: str = "uav") -> list[Path]:
    """Write ``plans`` as ``out_dir/<stem><k>.plan`` (k from 1); returns the paths in order."""
    from companion.mission import write_plan_file

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, plan in enumerate(plans, start=1):
        path = out / f"{stem}{k}.plan"
        write_plan_file(plan, path)
        paths.append(path)
    return paths


def planned_length_m(path: str | Path) -> float:
    """Length (m, 3D) of a mission flown in straight lines from its home on the ground: the
    climb, the legs and, when it ends with RTL or LAND, the descent to the ground; what a flown
    track's length is compared with (its extra path)."""
    from companion.mission import load_mission_file, mission_to_local

    plan = load_mission_file(path)
    local = mission_to_local(plan, home_lla=mission_home(path))
    points = [np.zeros(3)] + [np.asarray(w.pos_ned_m, dtype=float) for w in local.waypoints]
    if local.end_action == "rtl":
        points.append(np.zeros(3))
    elif local.end_action == "land":
        points.insert(-1, np.array([points[-1][0], points[-1][1], points[-2][2]]))
    return float(sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:])))
