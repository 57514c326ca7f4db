"""Autopilot behaviour (modes, arming, takeoff, landing, RTL, AUTO, GUIDED timeout) and pacing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model.control import Setpoint
from heli_model.model import HeliModel
from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.autopilot import Autopilot, Leg
from sim_vehicle.clock import SimClock, WallTimer
from sim_vehicle.config import VehicleSettings, replace_path
from sim_vehicle.mission_store import MissionItem

HOME = (47.397742, 8.545594, 488.0, 0.0)


@pytest.fixture(scope="module")
def model() -> HeliModel:
    return HeliModel.default()


def make_vehicle(model: HeliModel, vehicle_settings: VehicleSettings | None = None) -> Autopilot:
    return Autopilot(model, vehicle_settings or VehicleSettings(), HOME, np.random.default_rng(0))


def fly(vehicle: Autopilot, seconds: float) -> list[tuple]:
    events = []
    for _ in range(int(round(seconds / 0.5))):
        events += vehicle.step(0.5)
    return events


def arm_with_interlock(vehicle: Autopilot) -> None:
    """ArduCopter heli start-up: interlock switch low, arm, switch high (effective after the arming delay)."""
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)[0]
    ok, reason = vehicle.arm()
    assert ok, reason
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_HIGH)[0]


def arm_and_run_up(vehicle: Autopilot) -> None:
    """Arm as above and wait on the ground until the rotor has run up."""
    arm_with_interlock(vehicle)
    s = vehicle.settings.rsc
    fly(vehicle, s.arming_delay_s + s.runup_time_s + 0.5)
    assert vehicle.arming.rotor.runup_complete and vehicle.armed and vehicle.landed


def airborne_at_10m(model: HeliModel) -> Autopilot:
    vehicle = make_vehicle(model)
    assert vehicle.set_mode(ap.GUIDED)[0]
    arm_and_run_up(vehicle)
    assert vehicle.takeoff(10.0)[0]
    fly(vehicle, 12.0)
    return vehicle


def item(
    seq: int,
    command: int,
    lat: float = 0.0,
    lon: float = 0.0,
    z: float = 0.0,
    p1: float = 0.0,
    p2: float = 0.0,
    frame: int = 3,
) -> MissionItem:
    return MissionItem(seq, frame, command, 0, 1, p1, p2, 0.0, 0.0, int(round(lat * 1e7)), int(round(lon * 1e7)), z)


def north_east_deg(north_m: float, east_m: float) -> tuple[float, float]:
    lat = HOME[0] + north_m / 111_132.95
    lon = HOME[1] + east_m / (111_319.49 * math.cos(math.radians(HOME[0])))
    return lat, lon


# ---------------------------------------------------------------- legs
@settings(deadline=None, max_examples=40)
@given(st.lists(st.floats(-200, 200), min_size=6, max_size=6), st.floats(1.0, 12.0), st.floats(0.5, 5.0))
def test_leg_profile_starts_and_ends_at_rest_within_limits(coords, speed, accel):
    start, end = np.array(coords[:3]), np.array(coords[3:])
    leg = Leg(start, end, speed, 2.5, 1.5, accel, t0_s=3.0)
    p0, v0, _ = leg.sample(3.0)
    p1, v1, _ = leg.sample(3.0 + leg.duration_s + 1e-9)
    assert np.allclose(p0, start) and np.allclose(v0, 0.0)
    assert np.allclose(p1, end, atol=1e-6) and np.allclose(v1, 0.0)
    for t in np.linspace(3.0, 3.0 + leg.duration_s, 25):
        _, v, a = leg.sample(t)
        assert math.hypot(v[0], v[1]) <= speed + 1e-9
        assert -2.5 - 1e-9 <= v[2] <= 1.5 + 1e-9
        assert np.linalg.norm(a) <= accel + 1e-9


# ---------------------------------------------------------------- arming and modes
def test_prearm_checks(model):
    vehicle = make_vehicle(model)
    assert vehicle.set_mode(ap.AUTO)[0]  # allowed while disarmed
    ok, reason = vehicle.arm()
    assert not ok and "mission" in reason
    assert vehicle.set_mode(ap.LAND)[0]
    assert not vehicle.arm()[0]
    assert not vehicle.set_mode(99)[0]
    assert vehicle.mode == ap.LAND


def test_takeoff_reaches_altitude_and_disarm_is_refused_in_flight(model):
    vehicle = make_vehicle(model)
    assert not vehicle.takeoff(10.0)[0]  # not armed
    assert vehicle.arm() == (False, "Arm: Motor Interlock Enabled")  # the SITL's RC8 (1500 us) engages it
    arm_and_run_up(vehicle)
    assert not vehicle.takeoff(10.0)[0]  # not GUIDED
    vehicle.set_mode(ap.GUIDED)
    assert not vehicle.takeoff(float("nan"))[0]
    assert vehicle.takeoff(10.0)[0]
    fly(vehicle, 12.0)
    assert not vehicle.landed
    assert abs(-vehicle.pos_ned_m[2] - 10.0) < 0.1
    assert np.linalg.norm(vehicle.pos_ned_m[:2]) < 0.1
    assert not vehicle.disarm()[0]
    assert vehicle.armed


def test_guided_position_target_30m_is_reached_and_held(model):
    vehicle = airborne_at_10m(model)
    assert vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(30.0, 0.0, -10.0)))[0]
    fly(vehicle, 15.0)
    errors = []
    for _ in range(10):
        vehicle.step(0.5)
        errors.append(np.linalg.norm(vehicle.pos_ned_m - (30.0, 0.0, -10.0)))
    assert max(errors) < 0.5
    assert float(np.max(np.abs(vehicle.airframe.delta))) < 1.0


def test_guided_setpoint_refused_outside_guided_or_invalid(model):
    vehicle = airborne_at_10m(model)
    assert not vehicle.set_guided_setpoint(Setpoint(vel_ned_m_s=(float("inf"), 0.0, 0.0)))[0]
    assert not vehicle.set_guided_setpoint(Setpoint(vel_ned_m_s=(500.0, 0.0, 0.0)))[0]
    vehicle.set_mode(ap.LOITER)
    assert not vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(1.0, 0.0, -10.0)))[0]


def test_guided_velocity_timeout_brakes_to_hover(model):
    vehicle = airborne_at_10m(model)
    assert vehicle.set_guided_setpoint(Setpoint(vel_ned_m_s=(3.0, 0.0, 0.0)))[0]
    fly(vehicle, 2.0)
    assert vehicle.vel_ned_m_s[0] > 2.0  # following the velocity setpoint
    events = fly(vehicle, 10.0)  # no new setpoint: GUID_TIMEOUT (3 s) then brake
    assert any(e[0] == "text" and "timeout" in e[2] for e in events)
    assert np.linalg.norm(vehicle.vel_ned_m_s) < 0.1
    assert abs(-vehicle.pos_ned_m[2] - 10.0) < 0.3
    assert vehicle.mode == ap.GUIDED


def test_land_disarms_on_touchdown_and_never_goes_below_ground(model):
    vehicle = airborne_at_10m(model)
    assert vehicle.set_mode(ap.LAND)[0]
    lowest = 0.0
    events = []
    for _ in range(60):
        events += vehicle.step(0.5)
        lowest = max(lowest, vehicle.pos_ned_m[2])
    assert ("disarmed", "landed") in events
    assert vehicle.landed and not vehicle.armed
    assert lowest <= 0.0


def test_rtl_climbs_returns_and_lands_at_home(model):
    vehicle = airborne_at_10m(model)
    vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(25.0, -20.0, -10.0)))
    fly(vehicle, 15.0)
    assert vehicle.set_mode(ap.RTL)[0]
    highest = 0.0
    for _ in range(120):
        vehicle.step(0.5)
        highest = max(highest, -vehicle.pos_ned_m[2])
        if not vehicle.armed:
            break
    assert not vehicle.armed
    assert highest > 14.0  # climbed to RTL_ALT (15 m) before returning
    assert np.linalg.norm(vehicle.pos_ned_m[:2]) < 1.0


def test_auto_mission_reaches_items_in_order_and_lands(model):
    lat1, lon1 = north_east_deg(20.0, 0.0)
    lat2, lon2 = north_east_deg(20.0, 20.0)
    mission = [
        item(0, 16, HOME[0], HOME[1], HOME[2], frame=0),
        item(1, 22, z=8.0),
        item(2, 16, lat1, lon1, 8.0, p1=1.0, p2=1.0),
        item(3, 178, p1=1.0, p2=8.0),
        item(4, 16, lat2, lon2, 12.0),
        item(5, 21, lat2, lon2, 0.0),
    ]
    vehicle = make_vehicle(model)
    vehicle.mission.set_items(mission)
    assert vehicle.set_mode(ap.AUTO)[0]
    arm_with_interlock(vehicle)  # the takeoff item waits on the ground for the rotor run-up
    events = []
    for _ in range(200):
        events += vehicle.step(0.5)
        if not vehicle.armed:
            break
    reached = [e[1] for e in events if e[0] == "mission_item_reached"]
    assert reached == [1, 2, 4, 5]
    assert not vehicle.armed and vehicle.landed
    assert np.allclose(vehicle.pos_ned_m, (20.0, 20.0, 0.0), atol=1.0)
    assert vehicle.navigation.speed_m_s == 8.0


def test_idle_on_ground_disarms_after_delay(model):
    vehicle = make_vehicle(model, replace_path(VehicleSettings(), "flight.disarm_delay_s", 4.0))
    vehicle.set_mode(ap.GUIDED)
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)[0]
    assert vehicle.arm()[0]
    fly(vehicle, 1.5)
    assert vehicle.armed
    events = fly(vehicle, 1.0)  # interlock off: half of DISARM_DELAY, as ArduCopter heli
    assert not vehicle.armed and any(e[0] == "disarmed" for e in events)
    assert np.allclose(vehicle.pos_ned_m, 0.0)


def test_no_auto_disarm_while_the_rotor_turns(model):
    vehicle = make_vehicle(model)
    vehicle.set_mode(ap.GUIDED)
    arm_and_run_up(vehicle)
    fly(vehicle, 30.0)  # three times DISARM_DELAY on the ground with the rotor at speed
    assert vehicle.armed and vehicle.arming.rotor.above_critical(vehicle.settings.rsc)


def test_new_mission_does_not_disturb_disarmed_vehicle(model):
    vehicle = make_vehicle(model)
    vehicle.mission.set_items([item(0, 16, HOME[0], HOME[1], HOME[2], frame=0), item(1, 22, z=5.0)])
    assert vehicle.mission.has_mission and vehicle.mission.current == 1
    fly(vehicle, 2.0)
    assert vehicle.landed and np.allclose(vehicle.pos_ned_m, 0.0)
    assert not vehicle.mission.set_current(7)[0]


# ---------------------------------------------------------------- pacing (clock.py)
class FakeWall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_sim_clock_runs_speedup_times_faster():
    wall = FakeWall()
    clock = SimClock(0.0025, speedup=10.0, max_lag_s=0.5, wall_s=wall)
    wall.t += 0.1  # 0.1 s wall at 10x = 1 s simulated = 400 steps
    due = clock.steps_due()
    assert due == 400
    clock.advance(due)
    assert clock.time_s == pytest.approx(1.0)
    assert clock.steps_due() == 0
    assert clock.wall_until_step_s(40) == pytest.approx(0.01)


def test_sim_clock_slips_instead_of_bursting_and_changes_speed_without_jump():
    wall = FakeWall()
    clock = SimClock(0.0025, speedup=1.0, max_lag_s=0.5, wall_s=wall)
    wall.t += 5.0  # the process was stopped for 5 s
    due = clock.steps_due()
    assert due == 200  # only max_lag_s (0.5 s) is caught up
    assert clock.slipped_wall_s == pytest.approx(4.5)
    clock.advance(due)
    clock.set_speedup(4.0)
    wall.t += 0.25
    assert clock.steps_due() == 400


def test_wall_timer_fires_once_per_period():
    wall = FakeWall()
    timer = WallTimer(1.0, wall)
    assert timer.due()
    assert not timer.due()
    wall.t += 0.99
    assert not timer.due()
    wall.t += 0.02
    assert timer.due()
    wall.t += 10.0  # missed many: fires once, not ten times
    assert timer.due() and not timer.due()


def test_direct_setpoints_right_after_takeoff_command_lift_off(model):
    vehicle = make_vehicle(model)
    vehicle.set_mode(ap.GUIDED)
    arm_and_run_up(vehicle)
    vehicle.takeoff(5.0)
    vehicle.step(0.02)  # still on the ground
    assert vehicle.landed
    for k in range(300):  # a companion streaming a climbing trajectory at 20 Hz
        t = k * 0.05
        down = -min(5.0, 1.0 * t)
        vel = -1.0 if t < 5.0 else 0.0
        assert vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(0.0, 0.0, down), vel_ned_m_s=(0.0, 0.0, vel)))[0]
        vehicle.step(0.05)
    assert not vehicle.landed
    assert abs(-vehicle.pos_ned_m[2] - 5.0) < 0.2


def test_recover_after_internal_error_holds_position(model):
    vehicle = airborne_at_10m(model)
    vehicle.set_guided_setpoint(Setpoint(vel_ned_m_s=(1.0, 0.0, 0.0)))
    vehicle.step(1.0)
    vehicle.recover("test")
    events = fly(vehicle, 8.0)
    assert any(e[0] == "text" and "internal error" in e[2] for e in events)
    assert np.linalg.norm(vehicle.vel_ned_m_s) < 0.1 and vehicle.armed and not vehicle.landed


def test_rtl_goes_to_the_nearest_rally_point(model):
    vehicle = airborne_at_10m(model)
    lat, lon = north_east_deg(40.0, 0.0)
    far_lat, far_lon = north_east_deg(-80.0, 0.0)
    vehicle.mission.set_rally([item(0, 5100, lat, lon, 20.0), item(1, 5100, far_lat, far_lon, 20.0)])
    vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(30.0, 0.0, -10.0)))
    fly(vehicle, 12.0)
    vehicle.set_mode(ap.RTL)
    for _ in range(120):
        vehicle.step(0.5)
        if not vehicle.armed:
            break
    assert not vehicle.armed
    assert np.allclose(vehicle.pos_ned_m[:2], (40.0, 0.0), atol=1.0)


# ---------------------------------------------------------------- geofence
@settings(deadline=None, max_examples=60)
@given(
    st.floats(-50, 50),
    st.floats(-50, 50),
    st.floats(1, 40),
    st.floats(1, 40),
    st.floats(-100, 100),
    st.floats(-100, 100),
)
def test_point_in_rectangle_polygon_matches_the_box(cn, ce, hn, he, pn, pe):
    poly = np.array([[cn - hn, ce - he], [cn + hn, ce - he], [cn + hn, ce + he], [cn - hn, ce + he]])
    inside = abs(pn - cn) < hn and abs(pe - ce) < he
    on_edge = abs(abs(pn - cn) - hn) < 1e-9 or abs(abs(pe - ce) - he) < 1e-9
    if not on_edge:
        assert ap.point_in_polygon(np.array([pn, pe]), poly) == inside


def test_fence_breach_switches_to_rtl_when_enabled(model):
    fence_settings = replace_path(VehicleSettings(), "flight.fence_enable", 1)
    vehicle = make_vehicle(model, fence_settings)
    corners = [north_east_deg(n, e) for n, e in ((-20, -20), (20, -20), (20, 20), (-20, 20))]
    polygon = [item(i, ap.CMD_FENCE_POLYGON_INCLUSION, lat, lon, p1=4.0) for i, (lat, lon) in enumerate(corners)]
    vehicle.fence.set_items(polygon + [item(4, ap.CMD_FENCE_CIRCLE_EXCLUSION, *north_east_deg(-10.0, 0.0), p1=3.0)])
    assert len(vehicle.fence.area.inclusion_polygons) == 1 and len(vehicle.fence.area.exclusion_circles) == 1
    vehicle.set_mode(ap.GUIDED)
    arm_and_run_up(vehicle)
    vehicle.takeoff(10.0)
    fly(vehicle, 12.0)
    assert vehicle.fence.breached is None
    vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(40.0, 0.0, -10.0)))  # leaves the polygon at 20 m
    events = []
    for _ in range(40):
        events += vehicle.step(0.5)
        if vehicle.mode == ap.RTL:
            break
    assert vehicle.mode == ap.RTL and "outside an inclusion polygon" in vehicle.fence.breached
    assert 19.0 < vehicle.pos_ned_m[0] < 26.0
    assert any(e[0] == "text" and "Fence" in e[2] for e in events)


def test_fence_is_not_enforced_by_default(model):
    vehicle = airborne_at_10m(model)
    corners = [north_east_deg(n, e) for n, e in ((-5, -5), (5, -5), (5, 5), (-5, 5))]
    vehicle.fence.set_items(
        [item(i, ap.CMD_FENCE_POLYGON_INCLUSION, lat, lon, p1=4.0) for i, (lat, lon) in enumerate(corners)]
    )
    vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(20.0, 0.0, -10.0)))
    fly(vehicle, 10.0)
    assert vehicle.mode == ap.GUIDED and vehicle.fence.breached is None


def test_completed_mission_restarts_from_item_1(model):
    mission = [item(0, 16, HOME[0], HOME[1], HOME[2], frame=0), item(1, 22, z=3.0), item(2, 21)]
    vehicle = make_vehicle(model)
    vehicle.mission.set_items(mission)
    vehicle.set_mode(ap.AUTO)
    for flight in range(2):
        arm_with_interlock(vehicle)
        events = []
        for _ in range(100):
            events += vehicle.step(0.5)
            if not vehicle.armed:
                break
        assert [e[1] for e in events if e[0] == "mission_item_reached"] == [1, 2], f"flight {flight}"
        assert vehicle.mission.finished


def test_leaving_auto_mid_item_reports_nothing_and_resumes_later(model):
    lat, lon = north_east_deg(40.0, 0.0)
    mission = [
        item(0, 16, HOME[0], HOME[1], HOME[2], frame=0),
        item(1, 22, z=5.0),
        item(2, 16, lat, lon, 5.0),
        item(3, 21),
    ]
    vehicle = make_vehicle(model)
    vehicle.mission.set_items(mission)
    vehicle.set_mode(ap.AUTO)
    arm_with_interlock(vehicle)
    events = fly(vehicle, 8.0 + 12.0)  # 12 s of rotor start-up first
    assert vehicle.mission.current == 2
    vehicle.set_mode(ap.GUIDED)
    vehicle.set_guided_setpoint(Setpoint(pos_ned_m=(0.0, 10.0, -5.0)))
    events = fly(vehicle, 10.0)
    assert not any(e[0] == "mission_item_reached" for e in events)
    vehicle.set_mode(ap.AUTO)
    for _ in range(120):
        events += vehicle.step(0.5)
        if not vehicle.armed:
            break
    assert [e[1] for e in events if e[0] == "mission_item_reached"] == [2, 3]
    assert np.allclose(vehicle.pos_ned_m[:2], (40.0, 0.0), atol=1.0)


# ---------------------------------------------------------------- MAVLink server fed with fuzzed messages
FUZZ_TYPES = (
    "COMMAND_LONG",
    "COMMAND_INT",
    "SET_MODE",
    "REQUEST_DATA_STREAM",
    "TIMESYNC",
    "RC_CHANNELS_OVERRIDE",
    "SET_POSITION_TARGET_LOCAL_NED",
    "SET_POSITION_TARGET_GLOBAL_INT",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
    "MISSION_ITEM",
    "MISSION_REQUEST_LIST",
    "MISSION_REQUEST_INT",
    "MISSION_REQUEST",
    "MISSION_CLEAR_ALL",
    "MISSION_SET_CURRENT",
    "MISSION_ACK",
    "PARAM_REQUEST_LIST",
    "PARAM_REQUEST_READ",
    "PARAM_SET",
)
FUZZ_FLOATS = (0.0, 1.0, -1.0, 4.0, 10.0, float("nan"), float("inf"), -float("inf"), 1e30, -1e30, 0.5, 1e9)
FUZZ_INTS = (
    0,
    1,
    1,
    2,
    3,
    4,
    5,
    6,
    9,
    16,
    17,
    20,
    21,
    22,
    176,
    178,
    179,
    192,
    218,
    300,
    400,
    410,
    511,
    512,
    520,
    1000,
    2000,
    5001,
    5100,
    255,
)


def fuzz_message(mavlink, rng: np.random.Generator, gcs) -> bytes | None:
    kind = FUZZ_TYPES[int(rng.integers(len(FUZZ_TYPES)))]
    cls = mavlink.mavlink_map[getattr(mavlink, f"MAVLINK_MSG_ID_{kind}")]
    args = []
    for name, ftype, length in zip(cls.fieldnames, cls.fieldtypes, cls.array_lengths):
        if ftype == "char":
            args.append(
                [b"WPNAV_SPEED", b"SIM_SPEEDUP", b"LQI_R_COL", b"FENCE_ENABLE", b"X", b""][int(rng.integers(6))]
            )
        elif length:
            args.append([int(v) for v in rng.integers(0, 2, length)])
        elif ftype in ("float", "double"):
            args.append(float(rng.uniform(-1000, 1000)) if rng.random() < 0.2 else FUZZ_FLOATS[int(rng.integers(12))])
        elif name == "target_system":
            args.append(int(rng.choice([0, 1, 1, 2])))
        elif name == "target_component":
            args.append(int(rng.choice([0, 1, 1])))
        else:
            args.append(FUZZ_INTS[int(rng.integers(len(FUZZ_INTS)))])
    try:
        return cls(*args).pack(gcs)
    except Exception:  # a value the field cannot hold: the sender could not send it either
        return None


def test_server_survives_fuzzed_messages_while_flying(model, caplog):
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from sim_vehicle.mavlink import MavlinkServer

    link_settings = replace_path(VehicleSettings(), "link.out", ())
    vehicle = make_vehicle(model, link_settings)
    server = MavlinkServer(vehicle, link_settings, 1, 0)
    try:
        vehicle.set_mode(ap.GUIDED)
        arm_and_run_up(vehicle)
        assert vehicle.takeoff(10.0)[0]
        vehicle.run_steps(4000)
        rng = np.random.default_rng(3)
        gcs = mavlink.MAVLink(None, 255, 190)
        sent = 0
        for k in range(3000):
            buf = fuzz_message(mavlink, rng, gcs)
            if buf is not None:
                server._handle_datagram(buf, ("127.0.0.1", 9))
                sent += 1
            if k % 50 == 0:
                server._handle_events(vehicle.run_steps(40))
                server._send_due_streams()
        assert sent > 1000
        assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")]
        assert np.all(np.isfinite(vehicle.airframe.x))
        assert vehicle.pos_ned_m[2] <= 0.0
    finally:
        server.close()


def test_condition_yaw_turns_the_hovering_vehicle(model):
    vehicle = airborne_at_10m(model)
    assert not vehicle.set_yaw(float("nan"))[0]
    assert vehicle.set_yaw(math.radians(90.0))[0]
    fly(vehicle, 8.0)
    assert abs(vehicle.euler_rad[2] - math.pi / 2) < 0.05
    assert np.linalg.norm(vehicle.pos_ned_m - (0.0, 0.0, -10.0)) < 0.5
