"""Mission -> local NED waypoints and world: geometry, speeds, ends, and unreachable goals."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import MissionError
from companion.geo import LocalFrame
from companion.mission import (
    ConversionSettings,
    FenceCircle,
    FencePolygon,
    MissionItem,
    MissionPlan,
    RallyPoint,
    load_mission_file,
    mission_to_local,
)
from companion.mission.convert import point_in_polygon
from companion.world import Cylinder

REPO = Path(__file__).resolve().parents[3]
HOME = (47.397742, 8.545594, 488.0)
FRAME = LocalFrame(*HOME)


def ll(n, e):
    lat, lon, _ = FRAME.to_lla(n, e, 0.0)
    return float(lat), float(lon)


def wp(n, e, alt, hold=0.0, radius=0.0, frame=3):
    return MissionItem(16, frame, hold, radius, 0.0, math.nan, *ll(n, e), alt)


def circle(n, e, r, inclusion=False):
    return FenceCircle(*ll(n, e), r, inclusion)


def polygon(points, inclusion=False):
    return FencePolygon(tuple(ll(n, e) for n, e in points), inclusion)


def test_waypoints_in_ned_with_radius_hold_speed():
    plan = MissionPlan(
        items=(
            MissionItem(22, 3, alt_m=12.0),
            wp(40, 10, 15, hold=2, radius=1.5),
            MissionItem(178, 2, 1, 3.5, -1, 0),
            wp(0, 50, 20),
            MissionItem(20, 2),
        ),
        planned_home=HOME,
    )
    local = mission_to_local(plan)
    kinds = [w.kind for w in local.waypoints]
    assert kinds == ["takeoff", "waypoint", "waypoint", "rtl"]
    assert [w.seq for w in local.waypoints] == [1, 2, 4, 5]
    assert np.allclose(local.waypoints[0].pos_ned_m, [0, 0, -12], atol=1e-6)
    assert np.allclose(local.waypoints[1].pos_ned_m, [40, 10, -15], atol=1e-3)
    assert local.waypoints[1].acceptance_radius_m == 1.5 and local.waypoints[1].hold_s == 2.0
    assert local.waypoints[1].speed_m_s is None and local.waypoints[2].speed_m_s == 3.5
    assert local.waypoints[2].acceptance_radius_m == ConversionSettings().default_acceptance_radius_m
    assert np.allclose(local.waypoints[3].pos_ned_m, [0, 0, -20], atol=1e-3)
    assert local.end_action == "rtl"


def test_amsl_frame_and_land_here():
    plan = MissionPlan(items=(wp(20, 0, HOME[2] + 30.0, frame=0), MissionItem(21, 3)), planned_home=HOME)
    local = mission_to_local(plan)
    # no NAV_TAKEOFF: an implied takeoff (seq 0) climbs to the first waypoint's altitude
    assert local.waypoints[0].seq == 0 and local.waypoints[0].kind == "takeoff"
    assert local.waypoints[0].altitude_m == pytest.approx(30.0, abs=1e-3)
    assert local.waypoints[1].altitude_m == pytest.approx(30.0, abs=1e-3)
    land = local.waypoints[2]
    assert land.kind == "land" and np.allclose(land.pos_ned_m, [20, 0, 0], atol=1e-3)
    assert local.end_action == "land"


def test_items_after_land_are_not_flown():
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), MissionItem(21, 3), wp(5, 5, 10)), planned_home=HOME)
    assert [w.kind for w in mission_to_local(plan).waypoints] == ["takeoff", "land"]


def test_exclusion_zones_become_obstacles_and_inclusion_bounds():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(60, 0, 10)),
        polygons=(
            polygon([(-20, -20), (80, -20), (80, 40), (-20, 40)], True),
            polygon([(25, -10), (35, -10), (35, 10), (25, 10)]),
        ),
        circles=(circle(45, 20, 5.0),),
        planned_home=HOME,
    )
    local = mission_to_local(plan, settings=ConversionSettings(margin_m=2.0))
    world = local.world
    kinds = sorted(type(ob).__name__ for ob in world.obstacles)
    assert kinds == ["Cylinder", "Prism"]
    assert np.allclose(world.bounds_min[:2], [-20, -20], atol=0.01)
    assert np.allclose(world.bounds_max[:2], [80, 40], atol=0.01)
    assert world.bounds_min[2] == -120.0 and world.bounds_max[2] == 0.0
    # the straight leg crosses the exclusion polygon
    assert not world.segment_free(np.array([0.0, 0.0, -10.0]), np.array([60.0, 0.0, -10.0]))
    assert world.is_free(np.array([[45.0, 28.0, -10.0]]))[0]
    assert not world.is_free(np.array([[45.0, 26.0, -10.0]]))[0]  # within 5 m + 2 m margin


def test_bounds_from_extent_with_padding_and_2d():
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), wp(50, -30, 10)), planned_home=HOME)
    s = ConversionSettings(padding_m=10.0, margin_m=1.0)
    local = mission_to_local(plan, settings=s, dim=2)
    assert local.world.bounds_min.shape == (2,)
    assert np.allclose(local.world.bounds_min, [-11, -41], atol=0.01)
    assert np.allclose(local.world.bounds_max, [61, 11], atol=0.01)


def test_waypoint_inside_exclusion_zone_is_unreachable():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10), wp(60, 0, 10)),
        circles=(circle(-50, -50, 5.0), circle(60, 2, 6.0)),
        planned_home=HOME,
    )
    with pytest.raises(
        MissionError,
        match=r"item 3 \(waypoint\) is inside exclusion zone 2 "
        r"\(geofence circle 1\): unreachable",
    ):
        mission_to_local(plan)


def test_waypoint_within_margin_is_unreachable():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)),
        polygons=(polygon([(31, -5), (40, -5), (40, 5), (31, 5)]),),
        planned_home=HOME,
    )
    with pytest.raises(MissionError, match=r"item 2 \(waypoint\) is 1.0 m from exclusion zone 1"):
        mission_to_local(plan, settings=ConversionSettings(margin_m=3.0))


def test_home_inside_exclusion_zone():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)), circles=(circle(0, 0, 4.0),), planned_home=HOME
    )
    with pytest.raises(MissionError, match=r"item 1 \(takeoff\) is inside exclusion zone 1"):
        mission_to_local(plan)


def test_outside_inclusion_fence():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)),
        polygons=(polygon([(-10, -10), (20, -10), (20, 10), (-10, 10)], True),),
        planned_home=HOME,
    )
    with pytest.raises(MissionError, match=r"item 2 \(waypoint\) is outside the inclusion"):
        mission_to_local(plan)


def test_altitude_limits():
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 150)), planned_home=HOME)
    with pytest.raises(MissionError, match=r"item 2 \(NAV_WAYPOINT\): altitude 150.0 m .* ceiling"):
        mission_to_local(plan)
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), wp(30, 0, -5)), planned_home=HOME)
    with pytest.raises(MissionError, match="below the minimum"):
        mission_to_local(plan)


def test_no_home():
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)))
    with pytest.raises(MissionError, match="no home position"):
        mission_to_local(plan)
    local = mission_to_local(plan, home_lla=HOME)  # the vehicle's home is enough
    assert local.frame.lat0_deg == HOME[0]


def test_rally_points_in_ned():
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)), rally=(RallyPoint(*ll(5, 6), 20.0),), planned_home=HOME
    )
    local = mission_to_local(plan)
    assert local.rally_ned_m.shape == (1, 3)
    assert np.allclose(local.rally_ned_m[0], [5, 6, -20], atol=1e-3)


def test_world_file_adds_obstacles(tmp_path):
    world_file = tmp_path / "w.toml"
    world_file.write_text(
        "[world]\nbounds_min = [-100.0, -100.0, -120.0]\nbounds_max = [100.0, 100.0, 0.0]\n"
        '[[obstacles]]\ntype = "sphere"\ncenter = [15.0, 0.0, -10.0]\nradius = 4.0\n'
    )
    plan = MissionPlan(items=(MissionItem(22, 3, alt_m=10), wp(30, 0, 10)), planned_home=HOME)
    local = mission_to_local(plan, world_file=world_file)
    assert len(local.world.obstacles) == 1
    assert not local.world.segment_free(np.array([0.0, 0.0, -10.0]), np.array([30.0, 0.0, -10.0]))


def test_paper_mission_blocks_the_straight_line():
    plan = load_mission_file(REPO / "mission_files" / "paper_cluttered_100m.plan")
    local = mission_to_local(plan)
    assert len(local.world.obstacles) == 30
    start, goal = local.waypoints[0].pos_ned_m, local.waypoints[1].pos_ned_m
    assert np.allclose(goal[:2], [99, 99], atol=0.01)
    assert not local.world.segment_free(start, goal)


def test_exclusion_sample_auto_legs_cross_zones():
    local = mission_to_local(load_mission_file(REPO / "mission_files" / "exclusion_zones.plan"))
    goals = local.goals_ned_m
    blocked = [not local.world.segment_free(goals[i], goals[i + 1]) for i in range(len(goals) - 1)]
    assert sum(blocked) >= 2


def test_bad_settings():
    with pytest.raises(MissionError, match="margin_m"):
        ConversionSettings(margin_m=-1.0)


@settings(deadline=None, max_examples=30)
@given(st.floats(-200, 200), st.floats(-200, 200))
def test_point_in_square_polygon_property(n, e):
    square = np.array([[-50.0, -50.0], [50.0, -50.0], [50.0, 50.0], [-50.0, 50.0]])
    inside = point_in_polygon(np.array([n, e]), square)
    assert inside == (abs(n) < 50 and abs(e) < 50) or min(abs(abs(n) - 50), abs(abs(e) - 50)) < 1e-9


@settings(deadline=None, max_examples=25)
@given(st.floats(-80, 80), st.floats(-80, 80), st.floats(2, 15))
def test_circle_zone_clearance_matches_ned_distance(n, e, r):
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10), wp(90, 90, 10)), circles=(circle(n, e, r),), planned_home=HOME
    )
    try:
        local = mission_to_local(plan, settings=ConversionSettings(margin_m=0.0, padding_m=5))
    except MissionError:
        # the goal or the takeoff is inside the circle: check that this is geometrically true
        assert min(math.hypot(n, e), math.hypot(90 - n, 90 - e)) <= r + 1e-6
        return
    ob = local.world.obstacles[0]
    assert isinstance(ob, Cylinder)
    assert ob.radius_m == pytest.approx(r)
    assert np.allclose(ob.center_ne_m, [n, e], atol=1e-3)
