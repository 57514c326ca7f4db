"""RawItem <-> MAVSDK MissionRaw.MissionItem conversion (no vehicle needed)."""

import math
from pathlib import Path

from companion.link.mission_transfer import from_mavsdk_item, to_mavsdk_item
from companion.mission import load_mission_file
from companion.mission.raw import fence_to_raw, mission_to_raw, rally_to_raw

REPO = Path(__file__).resolve().parents[3]


def test_items_survive_the_mavsdk_struct():
    plan = load_mission_file(REPO / "mission_files" / "exclusion_zones.plan")
    for raw_list in (mission_to_raw(plan), fence_to_raw(plan), rally_to_raw(plan)):
        for raw in raw_list:
            back = from_mavsdk_item(to_mavsdk_item(raw))
            for name in ("seq", "frame", "command", "current", "autocontinue", "x", "y", "mission_type"):
                assert getattr(back, name) == getattr(raw, name), name
            for name in ("param1", "param2", "param3", "param4", "z"):
                a, b = getattr(back, name), getattr(raw, name)
                assert (math.isnan(a) and math.isnan(b)) or a == b, name


def test_exactly_one_current_item_in_the_mission():
    plan = load_mission_file(REPO / "mission_files" / "square.waypoints")
    raw = mission_to_raw(plan)
    assert [r.current for r in raw].count(1) == 1 and raw[0].current == 1
