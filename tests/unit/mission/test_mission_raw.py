"""MissionPlan <-> MAVLink mission/fence/rally item lists (ArduPilot conventions)."""

import math

import pytest

from companion.errors import MissionError
from companion.mission import FenceCircle, FencePolygon, MissionItem, MissionPlan, RallyPoint
from companion.mission.raw import RawItem, fence_to_raw, mission_to_raw, rally_to_raw, raw_to_fence, raw_to_plan

HOME = (47.397742, 8.545594, 488.0)
PLAN = MissionPlan(
    items=(
        MissionItem(22, 3, alt_m=15.0),
        MissionItem(16, 3, 2.0, 1.5, 0.0, math.nan, 47.3981234, 8.5459876, 20.0),
        MissionItem(178, 2, 1.0, 4.0, -1.0, 0.0),
        MissionItem(20, 2),
    ),
    polygons=(
        FencePolygon(((47.0, 8.0), (47.1, 8.0), (47.1, 8.1), (47.0, 8.1)), True),
        FencePolygon(((47.05, 8.05), (47.06, 8.05), (47.06, 8.06)), False),
    ),
    circles=(FenceCircle(47.02, 8.02, 12.5, False),),
    rally=(RallyPoint(47.01, 8.01, 25.0),),
    planned_home=HOME,
)


def test_mission_list_has_home_at_seq0():
    raw = mission_to_raw(PLAN)
    assert [r.seq for r in raw] == list(range(5))
    assert raw[0].command == 16 and raw[0].frame == 0 and raw[0].x == 473977420
    assert raw[2].x == 473981234 and raw[2].y == 85459876 and raw[2].param2 == 1.5
    assert all(r.mission_type == 0 for r in raw)


def test_fence_encoding():
    raw = fence_to_raw(PLAN)
    assert [r.command for r in raw] == [5001] * 4 + [5002] * 3 + [5004]
    assert raw[0].param1 == 4 and raw[4].param1 == 3 and raw[-1].param1 == 12.5
    assert all(r.mission_type == 1 for r in raw)


def test_round_trip_through_raw():
    back = raw_to_plan(mission_to_raw(PLAN), fence_to_raw(PLAN), rally_to_raw(PLAN))
    assert back.planned_home == pytest.approx(HOME)
    assert [i.command for i in back.items] == [22, 16, 178, 20]
    assert back.items[1].lat_deg == pytest.approx(47.3981234, abs=1e-9)
    assert math.isnan(back.items[1].param4)
    assert back.polygons == PLAN.polygons and back.circles == PLAN.circles
    assert back.rally == PLAN.rally


def test_incomplete_polygon_is_an_error():
    raw = fence_to_raw(PLAN)[:3]
    with pytest.raises(MissionError, match="polygon of 4 vertices is incomplete"):
        raw_to_fence(raw)


def test_unknown_fence_command():
    raw = [RawItem(0, 0, 16, 0, 1, 0, 0, 0, 0, 0, 0, 0, 1)]
    with pytest.raises(MissionError, match="fence item 0: unknown fence command 16"):
        raw_to_fence(raw)
