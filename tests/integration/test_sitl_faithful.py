"""Issue 10, item 6: a real ``sim-vehicle`` process behaves as ArduCopter heli does (pymavlink).

What the reference firmware (../shared/ardupilot/arducopter-heli) was seen to do, checked here
against the simulator: nothing but HEARTBEAT unasked; streams per link at the requested rate
until disabled (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM); arming refused with the motor
interlock engaged ("Arm: Motor Interlock Enabled"); the interlock switch accepted during the
arming delay but NAV_TAKEOFF refused (FAILED, no STATUSTEXT) until it is in effect; the climb
after the rotor run-up; the EKF origin apart from home (--origin, DO_SET_HOME) with
LOCAL_POSITION_NED from the origin; EXTENDED_SYS_STATE and ADSB_VEHICLE traffic on request only.
"""

from __future__ import annotations

import math
import socket
import time

import pymap3d
import pytest
from flight_support import TrackListener, wait_until
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import MavlinkPeer, start_sim_vehicle

from heli_common.ports import free_port

pytestmark = pytest.mark.integration

M = mavlink
HOME = (47.397742, 8.545594, 488.0)


class Listener:
    """A passive UDP listener on an ``--out`` address: it never sends anything."""

    def __init__(self) -> None:
        self.port = free_port()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", self.port))
        self.sock.settimeout(0.1)
        self.mav = M.MAVLink(None)
        self.mav.robust_parsing = True

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def collect(self, seconds: float) -> list:
        out = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                data = self.sock.recv(65535)
            except (TimeoutError, OSError):
                continue
            out += [m for m in self.mav.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
        return out

    def close(self) -> None:
        self.sock.close()


def collect(gcs: MavlinkPeer, seconds: float) -> list:
    out = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        out += gcs.receive(0.05)
    return out


def types(messages: list) -> list[str]:
    return [m.get_type() for m in messages]


def stamps(messages: list, kind: str) -> list[int]:
    return [m.time_boot_ms for m in messages if m.get_type() == kind]


def test_streams_only_as_requested_per_link_at_the_requested_rate():
    listener = Listener()
    try:
        with (
            TrackListener() as track,
            start_sim_vehicle(out=[listener.address, track.address], speedup=5.0) as sim,
            MavlinkPeer(sim.port, sim.sysid) as gcs,
            MavlinkPeer(sim.port, sim.sysid, 251) as other,
        ):
            # unasked: a peer gets HEARTBEAT only; an --out listener also the origin and home, once, at start
            heard = collect(gcs, 3.0)
            assert set(types(heard)) == {"HEARTBEAT"}
            passive = listener.collect(1.0)
            assert set(types(passive)) <= {"HEARTBEAT", "GPS_GLOBAL_ORIGIN", "HOME_POSITION"}
            # SET_MESSAGE_INTERVAL: LOCAL_POSITION_NED at 4 Hz (simulated) to this peer only, then off
            ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 250_000)
            assert ack.result == M.MAV_RESULT_ACCEPTED
            got = collect(gcs, 2.0)
            times = stamps(got, "LOCAL_POSITION_NED")
            assert len(times) >= 20
            rate_hz = (len(times) - 1) / ((times[-1] - times[0]) / 1000.0)
            assert rate_hz == pytest.approx(4.0, rel=0.1)
            assert "LOCAL_POSITION_NED" not in types(collect(other, 1.0))
            assert "LOCAL_POSITION_NED" not in types(listener.collect(0.5))
            gcs.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
            assert gcs.last["MESSAGE_INTERVAL"].interval_us == 250_000
            assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, -1).result == 0
            collect(gcs, 0.3)
            assert "LOCAL_POSITION_NED" not in types(collect(gcs, 1.5))
            # unknown message: DENIED with ArduPilot's words
            ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 12345, 100_000)
            assert ack.result == M.MAV_RESULT_DENIED
            text = gcs.last.get("STATUSTEXT") or gcs.wait("STATUSTEXT", 2.0)
            assert text is not None and text.text == "No ap_message for mavlink id (12345)"
            # REQUEST_DATA_STREAM POSITION (as MAVProxy asks): its group only, on the other peer's link
            other.send(other.mav.request_data_stream_encode(sim.sysid, 1, M.MAV_DATA_STREAM_POSITION, 5, 1))
            got = types(collect(other, 1.5))
            assert "GLOBAL_POSITION_INT" in got and "LOCAL_POSITION_NED" in got
            assert "ATTITUDE" not in got and "EXTENDED_SYS_STATE" not in got
            assert "GLOBAL_POSITION_INT" not in types(collect(gcs, 0.5))
            other.send(other.mav.request_data_stream_encode(sim.sysid, 1, M.MAV_DATA_STREAM_POSITION, 0, 0))
            collect(other, 0.3)
            assert "GLOBAL_POSITION_INT" not in types(collect(other, 1.0))
            # EXTENDED_SYS_STATE (landed state) only on request; REQUEST_MESSAGE answers once
            assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE).result == 0
            state = gcs.last.get("EXTENDED_SYS_STATE") or gcs.wait("EXTENDED_SYS_STATE", 2.0)
            assert state.landed_state == M.MAV_LANDED_STATE_ON_GROUND
            assert "EXTENDED_SYS_STATE" not in types(collect(gcs, 1.0))
            gcs.request("EXTENDED_SYS_STATE", rate_hz=2.0)
            assert types(collect(gcs, 1.5)).count("EXTENDED_SYS_STATE") >= 3
            # the TrackListener (a logger on an --out port) asked for its track itself
            wait_until(lambda: len(track.track) > 10, 10.0, "the TrackListener's LOCAL_POSITION_NED")
    finally:
        listener.close()


def test_interlock_arming_delay_runup_and_takeoff():
    with (
        start_sim_vehicle(speedup=5.0) as sim,
        MavlinkPeer(sim.port, sim.sysid) as gcs,
        MavlinkPeer(sim.port, sim.sysid, source_system=255) as rc,
    ):
        gcs.request("EXTENDED_SYS_STATE", "GLOBAL_POSITION_INT", "RPM", rate_hz=10.0)
        assert gcs.set_mode(4).result == M.MAV_RESULT_ACCEPTED
        # the SITL's RC8 (1500 us) engages the interlock: arming refused, as ArduPilot words it
        ack = gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        assert ack.result == M.MAV_RESULT_FAILED
        text = gcs.last.get("STATUSTEXT") or gcs.wait("STATUSTEXT", 2.0)
        assert text.text == "Arm: Motor Interlock Enabled"
        # an RC8 override counts only from MAV_GCS_SYSID (255); it moves the switch (announced as
        # ArduPilot does) and lapses after RC_OVERRIDE_TIME (3 s), back to RC8 1500 us: engaged again
        gcs.request("RC_CHANNELS", rate_hz=10.0)
        override = [65535] * 7 + [1000]
        gcs.send(gcs.mav.rc_channels_override_encode(sim.sysid, 1, *override))
        assert gcs.wait("RC_CHANNELS", 1.0, lambda m: m.chan8_raw == 1000) is None
        rc.send(rc.mav.rc_channels_override_encode(sim.sysid, 1, *override))
        assert gcs.wait("STATUSTEXT", 2.0, lambda m: m.text == "RC8: MotorInterlock LOW") is not None
        assert gcs.last["RC_CHANNELS"].chan8_raw == 1000 or gcs.wait("RC_CHANNELS", 0.3, lambda m: m.chan8_raw == 1000)

        assert gcs.wait("STATUSTEXT", 3.0, lambda m: m.text == "RC8: MotorInterlock MIDDLE") is not None
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0).result == M.MAV_RESULT_FAILED
        # DO_AUX_FUNCTION 32 low: arming accepted
        assert gcs.set_interlock(False).result == M.MAV_RESULT_ACCEPTED
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0).result == M.MAV_RESULT_ACCEPTED
        armed_ms = gcs.wait("GLOBAL_POSITION_INT", 2.0).time_boot_ms
        assert "Arming motors" in [
            m.text for m in collect(gcs, 0.5) + [gcs.last["STATUSTEXT"]] if m.get_type() == "STATUSTEXT"
        ]
        # takeoff refused while the interlock is off: FAILED and no STATUSTEXT
        gcs.last.pop("STATUSTEXT", None)
        assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0).result == M.MAV_RESULT_FAILED
        assert gcs.wait("STATUSTEXT", 0.3) is None, gcs.last["STATUSTEXT"].text
        assert "STATUSTEXT" not in gcs.last, gcs.last["STATUSTEXT"].text
        # the switch is accepted during the arming delay (DO_AUX_FUNCTION 32 high), the takeoff is not
        assert gcs.set_interlock(True).result == M.MAV_RESULT_ACCEPTED
        refused = gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0)
        now_ms = gcs.wait("GLOBAL_POSITION_INT", 2.0).time_boot_ms
        if now_ms - armed_ms < 1800:  # still inside ARMING_DELAY_SEC (2 s simulated)
            assert refused.result == M.MAV_RESULT_FAILED
        accepted = None
        while accepted is None:
            ack = gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0)
            position = gcs.wait("GLOBAL_POSITION_INT", 2.0)
            if ack.result == M.MAV_RESULT_ACCEPTED:
                accepted = position.time_boot_ms
            assert position.time_boot_ms - armed_ms < 5000, "takeoff still refused 5 s after arming"
        assert accepted - armed_ms >= 1900  # not before the arming delay
        # the vehicle stays ON_GROUND until the rotor has run up (H_RSC_RUNUP_TIME 10 s), then climbs
        samples = []
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            for msg in gcs.receive(0.1):
                if msg.get_type() == "GLOBAL_POSITION_INT":
                    state = gcs.last.get("EXTENDED_SYS_STATE")
                    rpm = gcs.last.get("RPM")
                    samples.append(
                        (
                            msg.time_boot_ms,
                            msg.relative_alt / 1000.0,
                            state.landed_state if state else None,
                            rpm.rpm1 if rpm else None,
                        )
                    )
            if samples and samples[-1][1] > 9.8:
                break
        lift_off_ms = next(t for t, alt, _, _ in samples if alt > 0.3)
        assert lift_off_ms - armed_ms >= 2000 + 10_000 - 300  # arming delay + run-up
        waiting = [(state, rpm) for t, alt, state, rpm in samples if t < armed_ms + 2000 + 10_000 - 500]
        assert all(state == M.MAV_LANDED_STATE_ON_GROUND for state, _ in waiting if state is not None)
        rpms = [rpm for _, rpm in waiting if rpm is not None]
        assert rpms and rpms == sorted(rpms) and rpms[-1] > 1000.0  # the rotor running up
        assert M.MAV_LANDED_STATE_TAKEOFF in {state for _, _, state, _ in samples}
        assert samples[-1][1] > 9.8
        # switching the interlock off in flight is refused (the simulated vehicle cannot autorotate)
        assert gcs.set_interlock(False).result == M.MAV_RESULT_FAILED


def test_origin_apart_from_home_and_do_set_home():
    origin = (round(HOME[0] - 30.0 / 111_132.95, 7), round(HOME[1] - 20.0 / 75_300.0, 7), 478.0)
    expected_home = pymap3d.geodetic2ned(*HOME, *origin)  # home from the origin, NED metres
    with (
        start_sim_vehicle(speedup=5.0, extra_args=["--origin", ",".join(f"{v:.7f}" for v in origin)]) as sim,
        MavlinkPeer(sim.port, sim.sysid) as gcs,
    ):
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN).result == 0
        got = gcs.last.get("GPS_GLOBAL_ORIGIN") or gcs.wait("GPS_GLOBAL_ORIGIN", 2.0)
        assert (got.latitude, got.longitude, got.altitude) == tuple(round(v * 1e7) for v in origin[:2]) + (478000,)
        assert gcs.command(M.MAV_CMD_GET_HOME_POSITION).result == 0
        home = gcs.last.get("HOME_POSITION") or gcs.wait("HOME_POSITION", 2.0)
        assert (home.latitude, home.longitude, home.altitude) == (473977420, 85455940, 488000)
        assert (home.x, home.y, home.z) == pytest.approx(expected_home, abs=0.05)
        gcs.request("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT")
        local = gcs.wait("LOCAL_POSITION_NED", 2.0)
        assert (local.x, local.y, local.z) == pytest.approx(expected_home, abs=0.05)  # on the ground at home
        # GUIDED: SET_POSITION_TARGET_LOCAL_NED is metres from the origin, not from home
        gcs.heli_takeoff(6.0)
        target = (expected_home[0] + 15.0, expected_home[1] - 5.0, expected_home[2] - 6.0)
        reached = None
        deadline = time.monotonic() + 40.0
        while reached is None and time.monotonic() < deadline:
            gcs.send(
                gcs.mav.set_position_target_local_ned_encode(
                    0, sim.sysid, 1, M.MAV_FRAME_LOCAL_NED, 0b110111111000, *target, 0, 0, 0, 0, 0, 0, 0, 0
                )
            )
            reached = gcs.wait("LOCAL_POSITION_NED", 0.3, lambda m: math.dist((m.x, m.y, m.z), target) < 0.3)
        assert reached is not None, sim.log_tail()
        position = gcs.wait("GLOBAL_POSITION_INT", 2.0)
        north, east, _ = pymap3d.geodetic2ned(position.lat * 1e-7, position.lon * 1e-7, position.alt / 1000.0, *HOME)
        assert (north, east) == pytest.approx((15.0, -5.0), abs=0.5) and abs(position.relative_alt - 6000) < 300
        # DO_SET_HOME (COMMAND_INT, relative altitude): ACK, then GPS_GLOBAL_ORIGIN and HOME_POSITION
        lat, lon = HOME[0] + 10.0 / 111_132.95, HOME[1]
        gcs.last.pop("HOME_POSITION", None)
        gcs.last.pop("GPS_GLOBAL_ORIGIN", None)
        ack = gcs.command(
            M.MAV_CMD_DO_SET_HOME,
            0,
            0,
            0,
            0,
            round(lat * 1e7),
            round(lon * 1e7),
            2.0,
            use_int=True,
            frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        )
        assert ack.result == M.MAV_RESULT_ACCEPTED
        announced = gcs.last.get("HOME_POSITION") or gcs.wait("HOME_POSITION", 2.0)
        assert gcs.last["GPS_GLOBAL_ORIGIN"].latitude == round(origin[0] * 1e7)  # announced too, unchanged
        assert announced.latitude == round(lat * 1e7) and announced.altitude == 490000
        new_home = pymap3d.geodetic2ned(lat, lon, 490.0, *origin)
        assert (announced.x, announced.y, announced.z) == pytest.approx(new_home, abs=0.05)
        # the local frame did not move; relative altitude is now above the new home (2 m higher)
        local = gcs.wait("LOCAL_POSITION_NED", 2.0)
        assert math.dist((local.x, local.y, local.z), target) < 0.3
        position = gcs.wait("GLOBAL_POSITION_INT", 2.0)
        assert abs(position.relative_alt - 4000) < 300
        # COMMAND_LONG DO_SET_HOME with param1 = 1: here
        gcs.last.pop("HOME_POSITION", None)
        assert gcs.command(M.MAV_CMD_DO_SET_HOME, 1).result == M.MAV_RESULT_ACCEPTED
        here = gcs.last.get("HOME_POSITION") or gcs.wait("HOME_POSITION", 2.0)
        assert (here.x, here.y) == pytest.approx(target[:2], abs=0.5)


def test_adsb_traffic_on_request():
    with (
        start_sim_vehicle(speedup=2.0, extra_args=["--adsb-traffic", "2", "--seed", "4"]) as sim,
        MavlinkPeer(sim.port, sim.sysid) as gcs,
    ):
        assert "ADSB_VEHICLE" not in types(collect(gcs, 1.5))  # not unasked
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ADSB_VEHICLE, 200_000).result == 0
        reports = [m for m in collect(gcs, 4.0) if m.get_type() == "ADSB_VEHICLE"]
        by_icao: dict[int, list] = {}
        for r in reports:
            by_icao.setdefault(r.ICAO_address, []).append(r)
        assert len(by_icao) == 2
        for icao, seen in by_icao.items():
            assert 5 <= len(seen) <= 10  # about 1 Hz of simulated time each (4 s wall at 2x)
            first, last = seen[0], seen[-1]
            assert first.callsign == f"SIM{icao}" and first.squawk == 1200 and first.tslc == 1
            assert first.flags == 511 and first.emitter_type in (1, 2, 7, 14)
            assert 1000 <= first.hor_velocity <= 4000 and first.ver_velocity == 0 and 0 <= first.heading < 36000
            north, east, down = pymap3d.geodetic2ned(first.lat * 1e-7, first.lon * 1e-7, first.altitude / 1000.0, *HOME)
            assert math.hypot(north, east) <= 520.0 and 5.0 - 0.1 <= -down <= 70.1
            moved = pymap3d.geodetic2ned(last.lat * 1e-7, last.lon * 1e-7, last.altitude / 1000.0, *HOME)
            assert math.hypot(moved[0] - north, moved[1] - east) > 10.0  # flying, not parked
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ADSB_VEHICLE, -1).result == 0
        collect(gcs, 0.3)
        assert "ADSB_VEHICLE" not in types(collect(gcs, 1.5))
