"""The pure steps of ``companion run --resume`` (companion.flight.resume, issue 11)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.flight.resume import remaining_waypoints, resume_mission, resume_refusal
from companion.mission.model import LocalMission, LocalWaypoint


def wp(seq, kind="waypoint"):
    return LocalWaypoint(seq, kind, np.array([float(seq), 0.0, -15.0]), 2.0)


# takeoff 1, waypoint 2, (a DO_ command at 3), waypoints 4, 5, 6, RTL 7: exclusion_zones.plan
MISSION = (wp(1, "takeoff"), wp(2), wp(4), wp(5), wp(6), wp(7, "rtl"))


@pytest.mark.parametrize(
    "current, expected",
    [
        (4, [4, 5, 6, 7]),  # the leg to item 4 was flown: fly it again from here
        (3, [4, 5, 6, 7]),  # a command item: on at the next goal
        (0, [2, 4, 5, 6, 7]),  # home: the whole mission, takeoff left out (it flies)
        (1, [2, 4, 5, 6, 7]),  # the takeoff item
        (7, [7]),  # the way home
        (8, []),  # past the last item: only the mission's end is left
    ],
)
def test_the_goals_left_start_at_the_current_item(current, expected):
    assert [w.seq for w in remaining_waypoints(MISSION, current)] == expected


def test_the_resumed_mission_keeps_the_world_and_the_end():
    mission = LocalMission(frame=None, waypoints=MISSION, world="the world", end_action="rtl")
    resumed = resume_mission(mission, 5)
    assert [w.seq for w in resumed.waypoints] == [5, 6, 7]
    assert resumed.world == "the world" and resumed.end_action == "rtl"
    assert len(mission.waypoints) == 6, "the original is unchanged"


@pytest.mark.parametrize(
    "items, airborne, words", [(0, True, "no mission"), (0, False, "no mission"), (7, False, "not flying")]
)
def test_resume_is_refused_without_a_mission_or_on_the_ground(items, airborne, words):
    reason = resume_refusal(mission_items=items, airborne=airborne)
    assert reason.startswith("cannot resume") and words in reason


def test_a_flying_vehicle_with_a_mission_can_be_resumed():
    assert resume_refusal(mission_items=7, airborne=True) is None
