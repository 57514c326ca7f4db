"""Issue 10, item 6: sim-vehicle behaves as ArduCopter heli (reference firmware in ../shared/ardupilot).

Pure parts (rotor speed controller, stream scheduling, ADS-B traffic, frames), the autopilot's
start-up rules, and the MAVLink server in-process with a recording socket: nothing but HEARTBEAT
unasked, streams per link, DO_SET_HOME announcing origin and home, long STATUSTEXT in chunks.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_model.control import Setpoint
from heli_model.model import HeliModel
from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.adsb import AdsbSettings, RoundRobin, TrafficModel
from sim_vehicle.autopilot import Autopilot, QuietRefusal
from sim_vehicle.config import VehicleSettings, replace_path
from sim_vehicle.frames import Frames
from sim_vehicle.streams import GROUPS, LinkStreams, StreamTable, decode_interval

HOME = (47.397742, 8.545594, 488.0, 0.0)
GCS = ("127.0.0.1", 40001)
OTHER = ("127.0.0.1", 40002)
OUT = ("127.0.0.1", 40003)


@pytest.fixture(scope="module")
def model() -> HeliModel:
    return HeliModel.default()


def fly(vehicle: Autopilot, seconds: float) -> list[tuple]:
    events = []
    for _ in range(int(round(seconds / 0.5))):
        events += vehicle.step(0.5)
    return events


def texts(events: list[tuple]) -> list[str]:
    return [e[2] for e in events if e[0] == "text"]


# ================================================================ rotor speed controller (pure)
DEFAULT_RSC = rsc.RscSettings()


def run(
    state: rsc.RotorState,
    seconds: float,
    armed_at_s: float = 0.0,
    t0_s: float = 0.0,
    armed: bool = True,
    settings_: rsc.RscSettings = DEFAULT_RSC,
    dt_s: float = 0.01,
) -> tuple[rsc.RotorState, list]:
    history = []
    for k in range(int(round(seconds / dt_s))):
        t = t0_s + (k + 1) * dt_s
        state = rsc.update(state, armed=armed, armed_for_s=t - armed_at_s, dt_s=dt_s, settings=settings_)
        history.append((t, state))
    return state, history


def test_interlock_waits_for_the_arming_delay_then_the_rotor_runs_up_in_runup_time():
    state = rsc.RotorState(switch_engaged=True)
    state, history = run(state, 14.0)
    effective = [t for t, s in history if s.interlock]
    complete = [t for t, s in history if s.runup_complete]
    assert effective[0] == pytest.approx(2.0, abs=0.011)  # ARMING_DELAY_SEC
    assert complete[0] == pytest.approx(2.0 + 10.0, abs=0.02)  # + H_RSC_RUNUP_TIME
    ramped = [t for t, s in history if rsc.output_pwm_us(s, rsc.RscSettings()) == 1660]
    assert ramped[0] == pytest.approx(2.0 + 1.0, abs=0.02)  # servo 8 at H_RSC_SETPOINT after 1 s
    assert state.speed == 1.0 and state.above_critical(rsc.RscSettings())


def test_switch_off_or_disarm_runs_the_rotor_down_and_the_runup_is_lost_below_critical():
    state, _ = run(rsc.RotorState(switch_engaged=True), 13.0)
    assert state.runup_complete
    state = rsc.with_switch(state, False)
    state, history = run(state, 6.0, t0_s=13.0)
    assert not state.interlock and state.speed == pytest.approx(0.4, abs=0.05)
    lost = [t for t, s in history if not s.runup_complete][0]
    assert lost == pytest.approx(13.0 + 5.0, abs=0.02)  # 50 % (H_RSC_CRITICAL) after 5 s
    state, _ = run(rsc.with_switch(state, True), 2.0, armed=False)
    assert state.speed < 0.3 and not state.interlock  # disarmed: never engaged


@pytest.mark.parametrize("pwm, position", [(900, 0), (1199, 0), (1200, 1), (1500, 1), (1800, 1), (1801, 2), (2000, 2)])
def test_aux_switch_positions_as_ardupilot(pwm, position):
    assert rsc.switch_position(pwm) == position
    assert rsc.engages(position) == (position != rsc.SWITCH_LOW)


def test_rc8_override_expires_after_rc_override_time():
    s = rsc.RscSettings()
    assert rsc.rc8_pwm_us(1000, 2.9, s) == 1000
    assert rsc.rc8_pwm_us(1000, 3.1, s) == 1500  # back to the SITL's stick input: interlock engaged
    assert rsc.rc8_pwm_us(None, 0.0, s) == 1500


@settings(deadline=None, max_examples=50)
@given(st.lists(st.tuples(st.booleans(), st.booleans(), st.floats(0.0, 0.5)), min_size=1, max_size=60))
def test_rotor_speed_stays_in_range_and_never_complete_without_full_speed_first(steps):
    state = rsc.RotorState(switch_engaged=False)
    t = 0.0
    reached_full = False
    for switch, armed, dt in steps:
        state = rsc.update(
            rsc.with_switch(state, switch), armed=armed, armed_for_s=t, dt_s=dt, settings=rsc.RscSettings()
        )
        t += dt
        reached_full |= state.speed >= 1.0
        assert 0.0 <= state.speed <= 1.0
        assert not state.runup_complete or reached_full
        assert not state.interlock or (armed and switch and t - dt >= 2.0)


# ================================================================ streams (pure)
def test_set_message_interval_answers_as_the_reference_firmware():
    assert decode_interval(12345, 100000)[:2] == (mavlink.MAV_RESULT_DENIED, "No ap_message for mavlink id (12345)")
    assert decode_interval(33, -7)[0] == mavlink.MAV_RESULT_DENIED
    for too_fast in (1, 2500):
        result, text, _, _ = decode_interval(33, too_fast)
        assert result == mavlink.MAV_RESULT_DENIED
        assert text == "Requested rate for message ID 33 too fast. Increase SCHED_LOOP_RATE"
    assert decode_interval(33, 10000) == (mavlink.MAV_RESULT_ACCEPTED, "", "GLOBAL_POSITION_INT", 0.01)
    assert decode_interval(33, -1)[3] is None and decode_interval(33, 0)[3] == "default"
    assert decode_interval(float("nan"), 1000)[0] == mavlink.MAV_RESULT_DENIED


def test_group_lists_match_arducopter():
    assert GROUPS["POSITION"] == ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
    assert GROUPS["EXTRA1"][0] == "ATTITUDE" and GROUPS["EXTRA2"] == ("VFR_HUD",)
    assert {"SYS_STATUS", "MISSION_CURRENT", "GPS_RAW_INT"} <= set(GROUPS["EXT_STAT"])
    everywhere = {m for g in GROUPS.values() for m in g}
    assert not {"EXTENDED_SYS_STATE", "HOME_POSITION", "GPS_GLOBAL_ORIGIN"} & everywhere  # one by one only


def test_link_streams_rate_default_and_stop():
    link = LinkStreams()
    assert link.due(0.0) == [] and link.active == []
    link.set_interval("ATTITUDE", 0.2, 0.0)
    sent = [t for t in np.arange(0.0, 4.0, 0.01) if "ATTITUDE" in link.due(float(t))]
    assert len(sent) == 20 and sent[0] == 0.0
    assert link.default_interval_s("ATTITUDE") is None  # EXTRA1 at 0 Hz: "default" means off
    link.set_group("EXTRA1", 4, 4.0)
    assert link.interval_us("ATTITUDE") == 250000 and link.default_interval_s("ATTITUDE") == 0.25
    link.set_group("EXTRA1", 0, 5.0)
    assert link.interval_us("ATTITUDE") == -1 and link.due(6.0) == []


def test_requests_change_only_the_requesting_link_and_all_skips_params():
    table = StreamTable([OUT], [{"POSITION": 2}])
    assert table.link(OUT, 0.0).interval_us("GLOBAL_POSITION_INT") == 500000  # MAV1_POSITION at start
    assert table.link(GCS, 0.0).active == []
    assert table.set_message_interval(GCS, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 1e6, 0.0)[0] == 0
    changed = table.request_data_stream(OTHER, mavlink.MAV_DATA_STREAM_ALL, 3, 1, 0.0)
    assert "PARAMS" not in dict(changed) and dict(changed)["ADSB"] == 3
    assert table.link(GCS, 0.0).active == ["EXTENDED_SYS_STATE"]
    assert "EXTENDED_SYS_STATE" not in table.link(OTHER, 0.0).active  # in no group, as in ArduCopter
    assert table.request_data_stream(OTHER, 99, 3, 1, 0.0) == [] and table.request_data_stream(OTHER, 6, 3, 7, 0) == []
    assert table.number(OUT) == 1 and table.number(GCS) is None


# ================================================================ ADS-B traffic (pure)
def test_traffic_crosses_the_area_within_its_limits_and_replays_with_the_seed():
    s = AdsbSettings(count=4, radius_m=400.0)
    a, b = TrafficModel(s, np.random.default_rng(5)), TrafficModel(s, np.random.default_rng(5))
    assert [p.icao_address for p in a.aircraft] == [p.icao_address for p in b.aircraft]
    assert len({p.icao_address for p in a.aircraft}) == 4
    seen_inside = set()
    for _ in range(600):  # 300 s: several crossings each
        a.step(0.5)
        for plane in a.aircraft:
            assert 10.0 <= plane.ground_speed_m_s <= 40.0
            assert 5.0 <= -plane.pos_ned_m[2] <= 70.0 and plane.vel_ned_m_s[2] == 0.0
            assert math.hypot(*plane.pos_ned_m[:2]) <= 400.0 + 40.0 * 0.5 + 1e-6
            if math.hypot(*plane.pos_ned_m[:2]) < 200.0:
                seen_inside.add(plane.icao_address)
    assert a.spawned > 8 and len(seen_inside) > 4  # replaced after leaving; they do cross the middle
    a.apply_settings(AdsbSettings(count=1))
    assert len(a.aircraft) == 1


def test_round_robin_reports_each_aircraft_about_once_a_second():
    turn = RoundRobin()
    sent = [(t, turn.next(3, t)) for t in np.arange(0.0, 10.0, 0.2)]  # the ADSB stream at 5 Hz
    indices = [i for _, i in sent if i is not None]
    assert indices[:6] == [0, 1, 2, 0, 1, 2]
    assert 27 <= len(indices) <= 30 and RoundRobin().next(0, 0.0) is None


# ================================================================ frames (pure)
def test_origin_frame_home_and_relative_heights():
    frames = Frames(HOME[:3], origin_lla=(47.397742 - 30.0 / 111_132.95, 8.545594, 478.0))
    assert np.allclose(frames.start_in_origin_ned_m, (30.0, 0.0, -10.0), atol=0.05)
    assert np.allclose(frames.to_local((1.0, 2.0, -3.0)), (31.0, 2.0, -13.0), atol=0.05)
    assert np.allclose(frames.from_local(frames.to_local((1.0, 2.0, -3.0))), (1.0, 2.0, -3.0))
    assert np.allclose(frames.home_local_ned_m, frames.start_in_origin_ned_m)
    frames.set_home(47.397742 + 20.0 / 111_132.95, 8.545594, 490.0)
    assert np.allclose(frames.home_ground_ned_m, (20.0, 0.0, -2.0), atol=0.05)
    assert frames.height_above_home((0.0, 0.0, -12.0)) == pytest.approx(10.0, abs=0.05)
    assert frames.down_at_height_above_home(5.0) == pytest.approx(-7.0, abs=0.05)


# ================================================================ autopilot: helicopter start-up
def make_vehicle(model, settings_: VehicleSettings | None = None, origin=None) -> Autopilot:
    return Autopilot(model, settings_ or VehicleSettings(), HOME, np.random.default_rng(0), origin_lla=origin)


def test_arming_refused_with_the_interlock_engaged_and_reported_every_30_s(model):
    vehicle = make_vehicle(model)
    assert vehicle.arming.rotor.switch_engaged and vehicle.arming.rc8_us == 1500  # the SITL's RC8: MIDDLE
    assert vehicle.arm() == (False, "Arm: Motor Interlock Enabled")
    events = fly(vehicle, 61.0)
    assert texts(events).count("PreArm: Motor Interlock Enabled") == 2  # at 30 s and 60 s
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)[0] and vehicle.arm()[0]


def test_takeoff_needs_the_interlock_in_effect_then_waits_for_the_runup(model):
    vehicle = make_vehicle(model)
    vehicle.set_mode(ap.GUIDED)
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)[0] and vehicle.arm()[0]
    ok, reason = vehicle.takeoff(10.0)
    assert not ok and isinstance(reason, QuietRefusal)  # interlock off: FAILED without STATUSTEXT
    assert vehicle.arming.set_interlock_switch(rsc.SWITCH_HIGH)[0]  # accepted during the arming delay ...
    vehicle.step(1.0)
    assert not vehicle.takeoff(10.0)[0]  # ... but not in effect yet
    vehicle.step(1.01)
    assert vehicle.arming.rotor.interlock and vehicle.takeoff(10.0)[0]
    states = []
    for _ in range(int(14.0 / 0.25)):
        vehicle.step(0.25)
        states.append((vehicle.time_s, vehicle.landed, vehicle.ground.taking_off, vehicle.arming.rotor.runup_complete))
    lift_off = next(t for t, landed, _, _ in states if not landed)
    assert lift_off == pytest.approx(2.0 + 10.0, abs=0.6)  # after the 10 s run-up, not before
    assert not any(taking_off for t, _, taking_off, _ in states if t < 11.9)  # ON_GROUND while waiting
    assert any(taking_off for t, _, taking_off, _ in states if t > 12.5)
    fly(vehicle, 10.0)
    assert abs(vehicle.height_above_home_m - 10.0) < 0.2 and not vehicle.ground.taking_off
    ok, reason = vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)
    assert not ok and "flight" in reason and vehicle.arming.rotor.interlock


def test_rc8_override_sets_the_switch_and_expires_back_to_engaged(model):
    vehicle = make_vehicle(model)
    vehicle.arming.rc_override(1000)
    events = vehicle.step(0.1)
    assert "RC8: MotorInterlock LOW" in texts(events) and vehicle.arm()[0]
    events = fly(vehicle, 4.0)  # no new override for RC_OVERRIDE_TIME: RC8 back to 1500 us
    assert "RC8: MotorInterlock MIDDLE" in texts(events) and vehicle.arming.rotor.switch_engaged


def test_auto_mission_takeoff_waits_for_interlock_and_runup(model):
    from sim_vehicle.mission_store import MissionItem

    items = [
        MissionItem(0, 0, 16, 0, 1, 0, 0, 0, 0, 473977420, 85455940, 488.0),
        MissionItem(1, 3, 22, 0, 1, 0, 0, 0, 0, 0, 0, 5.0),
    ]
    vehicle = make_vehicle(model)
    vehicle.mission.set_items(items)
    vehicle.set_mode(ap.AUTO)
    vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)
    assert vehicle.arm()[0]
    fly(vehicle, 4.0)
    assert vehicle.landed and vehicle.armed  # interlock off: the takeoff item waits (auto-disarm after 5 s)
    events = fly(vehicle, 2.0)
    assert not vehicle.armed and ("disarmed", "landed and idle for 5 s") in events


def test_set_home_moves_relative_heights_and_rtl_but_not_the_local_frame(model):
    origin = (HOME[0] - 30.0 / 111_132.95, HOME[1], 478.0)
    vehicle = make_vehicle(model, origin=origin)
    assert np.allclose(vehicle.local_ned_m, (30.0, 0.0, -10.0), atol=0.05)
    vehicle.set_mode(ap.GUIDED)
    vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)
    vehicle.arm()
    vehicle.arming.set_interlock_switch(rsc.SWITCH_HIGH)
    fly(vehicle, 12.5)
    assert vehicle.takeoff(8.0)[0]
    fly(vehicle, 10.0)
    assert np.allclose(vehicle.local_ned_m, (30.0, 0.0, -18.0), atol=0.2)
    lat, lon = HOME[0] + 20.0 / 111_132.95, HOME[1]
    assert not vehicle.set_home(float("nan"), lon, 490.0)[0] and not vehicle.set_home(95.0, lon, 490.0)[0]
    assert vehicle.set_home(lat, lon, 490.0)[0]
    assert vehicle.height_above_home_m == pytest.approx(6.0, abs=0.2)  # home 2 m higher
    assert np.allclose(vehicle.frames.home_local_ned_m, (50.0, 0.0, -12.0), atol=0.05)
    assert np.allclose(vehicle.local_ned_m, (30.0, 0.0, -18.0), atol=0.2)  # the EKF origin did not move
    # a local-frame target is metres from the origin, not from home
    assert vehicle.set_guided_setpoint(Setpoint(pos_ned_m=vehicle.frames.from_local((40.0, 5.0, -18.0))))[0]
    fly(vehicle, 12.0)
    assert np.allclose(vehicle.local_ned_m, (40.0, 5.0, -18.0), atol=0.3)
    assert vehicle.set_mode(ap.RTL)[0]
    for _ in range(200):
        vehicle.step(0.5)
        if not vehicle.armed:
            break
    assert not vehicle.armed and np.allclose(vehicle.pos_ned_m[:2], (20.0, 0.0), atol=1.0)  # the new home


# ================================================================ server in-process, recording socket
class RecordingSocket:
    """Stands in for the server's UDP socket: records what is sent where."""

    def __init__(self) -> None:
        self.sent: list[tuple[tuple, bytes]] = []

    def sendto(self, data: bytes, address: tuple) -> int:
        self.sent.append((address, bytes(data)))
        return len(data)

    def recvfrom(self, size: int):
        raise BlockingIOError

    def close(self) -> None:
        pass


def decode(sent: list[tuple[tuple, bytes]], to: tuple | None = None) -> list:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    out = []
    for address, data in sent:
        if to is None or address == to:
            out += [m for m in parser.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
    return out


@pytest.fixture
def server(model):
    from sim_vehicle.mavlink import MavlinkServer

    settings_ = replace_path(VehicleSettings(), "link.out", (f"{OUT[0]}:{OUT[1]}",))
    vehicle = make_vehicle(model, settings_)
    srv = MavlinkServer(vehicle, settings_, 1, 0)
    real = srv.sock
    srv.sock = RecordingSocket()
    yield srv
    real.close()


def gcs_send(server, msg, address=GCS, source_system: int = 250) -> None:
    server._handle_datagram(msg.pack(mavlink.MAVLink(None, source_system, 190)), address)


def advance(server, seconds: float) -> None:
    for _ in range(int(round(seconds / 0.05))):
        server._handle_events(server.autopilot.run_steps(20))
        server.clock.advance(20)
        server._send_due_streams()


def command(server, cmd: int, *params: float, address=GCS, to=GCS) -> list:
    """Send COMMAND_LONG from ``address``; what the server then sent to ``to``."""
    p = list(params) + [0.0] * (7 - len(params))
    start = len(server.sock.sent)
    gcs_send(server, mavlink.MAVLink_command_long_message(1, 1, cmd, 0, *p), address)
    return decode(server.sock.sent[start:], to)


def test_nothing_but_heartbeat_unasked_then_streams_per_link(server):
    gcs_send(server, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    gcs_send(server, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), OTHER)
    server._send_heartbeat()
    advance(server, 5.0)
    assert {m.get_type() for m in decode(server.sock.sent)} == {"HEARTBEAT"}
    replies = command(server, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 100000)
    assert replies[-1].get_type() == "COMMAND_ACK" and replies[-1].result == mavlink.MAV_RESULT_ACCEPTED
    server.sock.sent.clear()
    advance(server, 2.0)
    to_gcs = [m.get_type() for m in decode(server.sock.sent, GCS)]
    assert 19 <= to_gcs.count("LOCAL_POSITION_NED") <= 21  # 10 Hz of simulated time
    assert "LOCAL_POSITION_NED" not in [m.get_type() for m in decode(server.sock.sent, OTHER)]
    assert "LOCAL_POSITION_NED" not in [m.get_type() for m in decode(server.sock.sent, OUT)]
    replies = command(server, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
    assert [m.get_type() for m in replies][:2] == ["MESSAGE_INTERVAL", "COMMAND_ACK"] and replies[
        0
    ].interval_us == 100000
    command(server, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, -1)
    server.sock.sent.clear()
    advance(server, 1.0)
    assert "LOCAL_POSITION_NED" not in [m.get_type() for m in decode(server.sock.sent)]


def test_request_data_stream_on_an_out_link_sets_its_mav_parameter_param_set_waits_for_a_restart(server):
    gcs_send(server, mavlink.MAVLink_request_data_stream_message(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 4, 1), OUT)
    assert server.params.value(server.params.lookup("MAV1_POSITION")) == 4.0
    server.sock.sent.clear()
    advance(server, 1.0)
    kinds = [m.get_type() for m in decode(server.sock.sent, OUT)]
    assert 4 <= kinds.count("GLOBAL_POSITION_INT") <= 5 and "LOCAL_POSITION_NED" in kinds and "ATTITUDE" not in kinds
    gcs_send(server, mavlink.MAVLink_param_set_message(1, 1, b"MAV1_EXTRA1", 5.0, mavlink.MAV_PARAM_TYPE_INT16), OUT)
    server.sock.sent.clear()
    advance(server, 1.0)
    assert "ATTITUDE" not in [m.get_type() for m in decode(server.sock.sent, OUT)]  # RebootRequired in ArduPilot
    assert server.settings.link.mav1.extra1 == 5


def test_do_set_home_acks_then_announces_origin_and_home_to_every_link(server):
    gcs_send(server, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    lat = HOME[0] + 20.0 / 111_132.95
    start = len(server.sock.sent)
    replies = command(server, mavlink.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, lat, HOME[1], 490.0)
    assert [m.get_type() for m in replies] == ["COMMAND_ACK", "GPS_GLOBAL_ORIGIN", "HOME_POSITION"]
    assert [m.get_type() for m in decode(server.sock.sent[start:], OUT)] == ["GPS_GLOBAL_ORIGIN", "HOME_POSITION"]
    home = replies[2]
    assert abs(home.latitude - round(lat * 1e7)) < 50 and home.altitude == 490000  # COMMAND_LONG: float32 degrees
    assert (home.x, home.y, home.z) == pytest.approx((20.0, 0.0, -2.0), abs=0.5)  # float32 latitude: 0.4 m steps
    assert replies[1].latitude == 473977420 and replies[1].altitude == 488000  # the origin stays
    replies = command(server, mavlink.MAV_CMD_DO_SET_HOME, 1)  # here
    assert replies[0].result == mavlink.MAV_RESULT_ACCEPTED and replies[2].latitude == 473977420


def test_aux_function_rc_override_from_the_gcs_sysid_only_and_chunked_statustext(server):
    replies = command(server, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert replies[0].result == mavlink.MAV_RESULT_FAILED
    assert any(m.get_type() == "STATUSTEXT" and m.text == "Arm: Motor Interlock Enabled" for m in replies)
    override = mavlink.MAVLink_rc_channels_override_message(1, 1, *([65535] * 7), 1000)
    gcs_send(server, override, source_system=250)  # not MAV_GCS_SYSID: ignored, as ArduPilot does
    advance(server, 0.1)
    assert server.autopilot.arming.rotor.switch_engaged
    gcs_send(server, override, source_system=255)
    advance(server, 0.1)
    assert not server.autopilot.arming.rotor.switch_engaged
    assert command(server, mavlink.MAV_CMD_DO_AUX_FUNCTION, 32, 3)[0].result == mavlink.MAV_RESULT_DENIED
    assert command(server, mavlink.MAV_CMD_DO_AUX_FUNCTION, 41, 2)[0].result == mavlink.MAV_RESULT_FAILED
    replies = command(server, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 33, 1)
    chunks = [m for m in replies if m.get_type() == "STATUSTEXT"]
    assert [c.chunk_seq for c in chunks] == [0, 1] and len({c.id for c in chunks}) == 1 and chunks[0].id > 0
    assert "".join(c.text for c in chunks) == "Requested rate for message ID 33 too fast. Increase SCHED_LOOP_RATE"
    assert command(server, mavlink.MAV_CMD_DO_SET_MODE, 1, ap.GUIDED)[0].result == mavlink.MAV_RESULT_ACCEPTED
    replies = command(server, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    assert replies[0].result == mavlink.MAV_RESULT_FAILED and len(replies) == 1  # disarmed: no STATUSTEXT
    replies = command(server, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert replies[0].result == mavlink.MAV_RESULT_ACCEPTED
    replies = command(server, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    assert replies[0].result == mavlink.MAV_RESULT_FAILED and len(replies) == 1  # interlock off: likewise


# ================================================================ settings and parameters
def test_settings_and_parameters_of_the_new_behaviour():
    from sim_vehicle.config import SimConfigError, settings_from_dict
    from sim_vehicle.params import ParameterTable

    tree = settings_from_dict(
        {"link": {"mav1": {"position": 4}}, "rsc": {"runup_time_s": 5.0}, "adsb": {"count": 2, "radius_m": 300.0}}
    )
    assert tree.link.mav1.as_groups()["POSITION"] == 4 and tree.link.mav2.position == 0
    assert tree.rsc.runup_time_s == 5.0 and tree.adsb.count == 2
    for bad, key in (
        ({"adsb": {"count": -1}}, "adsb"),
        ({"rsc": {"mode": 7}}, "rsc"),
        ({"link": {"mav1": {"extra1": -2}}}, "link.mav1"),
        ({"link": {"mav4": {}}}, "mav4"),
    ):
        with pytest.raises(SimConfigError, match=key):
            settings_from_dict(bad)
    table = ParameterTable(VehicleSettings())
    defaults = {
        "H_RSC_MODE": 2,
        "H_RSC_RUNUP_TIME": 10,
        "H_RSC_RAMP_TIME": 1,
        "H_RSC_CRITICAL": 50,
        "MAV1_POSITION": 0,
        "MAV3_ADSB": 0,
        "MAV_GCS_SYSID": 255,
        "SIM_ADSB_COUNT": 0,
    }
    assert {name: table.value(table.lookup(name)) for name in defaults} == defaults  # ArduPilot's defaults
    assert table.set("H_RSC_RUNUP_TIME", 6.0)[0] and table.settings.rsc.runup_time_s == 6.0
    assert table.set("MAV2_EXTRA1", 3.0)[0] and table.settings.link.mav2.extra1 == 3
    assert not table.set("H_RSC_MODE", 9.0)[0] and not table.set("SIM_ADSB_COUNT", 1000.0)[0]
