"""Bad input against a real, flying ``sim-vehicle``; two instances side by side; CLI and tlog.

Issue 2: random bytes, truncated frames, wrong CRC, unknown messages, commands with NaN or
out-of-range parameters, mission items out of order or past the count, absurd parameters: each
is dropped or refused with the right MAV_RESULT / MAV_MISSION_RESULT and a log line; the vehicle
keeps flying and loses nothing stored.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import REPO_ROOT, MavlinkPeer, start_sim_vehicle

from heli_common.ports import free_port

pytestmark = pytest.mark.integration

GUIDED, AUTO = 4, 3
NAN = float("nan")
MISSION = [  # frame, command, p1..p4, x, y, z
    (0, 16, 0.0, 0.0, 0.0, 0.0, 473977420, 85455940, 488.0),
    (3, 22, 0.0, 0.0, 0.0, 0.0, 0, 0, 10.0),
    (3, 16, 0.0, 2.0, 0.0, 0.0, 473978320, 85455940, 10.0),
]


def take_off(gcs: MavlinkPeer, alt_m: float, timeout_s: float = 30.0) -> None:
    """GUIDED takeoff as with ArduCopter heli (interlock, run-up), position telemetry requested."""
    gcs.request("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
    gcs.heli_takeoff(alt_m)
    reached = gcs.wait("GLOBAL_POSITION_INT", timeout_s, lambda m: abs(m.relative_alt / 1000.0 - alt_m) < 0.2)
    assert reached is not None


def v2_frame(msgid: int, payload: bytes, seq: int = 0, sysid: int = 250, compid: int = 190) -> bytes:
    """A MAVLink 2 frame with an arbitrary message id and a (meaningless) checksum."""
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16)
    return header + payload + b"\x12\x34"


def stored_mission(gcs: MavlinkPeer) -> list[tuple]:
    items = gcs.download()
    assert items is not None
    return [(i.frame, i.command, i.param1, i.param2, i.param3, i.param4, i.x, i.y, i.z) for i in items]


def test_bad_input_is_refused_and_the_vehicle_keeps_flying():
    with start_sim_vehicle(speedup=5.0) as sim, MavlinkPeer(sim.port, sim.sysid) as gcs:
        assert gcs.upload(MISSION) == mavlink.MAV_MISSION_ACCEPTED
        take_off(gcs, 10.0)
        gcs.send(gcs.mav.param_set_encode(sim.sysid, 1, b"WPNAV_SPEED", 600.0, mavlink.MAV_PARAM_TYPE_REAL32))
        assert gcs.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "WPNAV_SPEED").param_value == 600.0

        # ---- malformed packets
        rng = np.random.default_rng(7)
        good = gcs.mav.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs.mav)
        wrong_crc = bytearray(gcs.mav.command_long_encode(sim.sysid, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs.mav))
        wrong_crc[-1] ^= 0xFF  # would disarm in flight if it were accepted
        for _ in range(20):
            gcs.send_raw(rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes())
        gcs.send_raw(good[: len(good) // 2])  # truncated
        gcs.send_raw(bytes(wrong_crc))  # wrong CRC
        gcs.send_raw(v2_frame(0xABCDE, b"\x01\x02\x03"))  # unknown message id
        gcs.send_raw(b"")  # empty datagram

        # ---- commands with NaN or out-of-range parameters, unknown commands
        M = mavlink
        cases = [
            (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, NAN), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, -50.0), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_COMPONENT_ARM_DISARM, (NAN,), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_COMPONENT_ARM_DISARM, (0.0,), M.MAV_RESULT_FAILED, False),  # disarm in flight
            (M.MAV_CMD_DO_SET_MODE, (1, 99), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_DO_SET_MODE, (1, NAN), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_SET_MESSAGE_INTERVAL, (NAN, 1000), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_SET_MESSAGE_INTERVAL, (33, -7), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_MISSION_START, (1e9,), M.MAV_RESULT_DENIED, False),
            (M.MAV_CMD_DO_CHANGE_SPEED, (1, 1e6), M.MAV_RESULT_DENIED, False),
            (31999, (), M.MAV_RESULT_UNSUPPORTED, False),
            (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, NAN), M.MAV_RESULT_DENIED, True),
            (31999, (), M.MAV_RESULT_UNSUPPORTED, True),
        ]
        for command, params, expected, use_int in cases:
            ack = gcs.command(command, *params, use_int=use_int)
            assert ack is not None, f"no COMMAND_ACK for {command} {params}"
            assert ack.result == expected, f"command {command} {params}: {ack.result} != {expected}"

        # ---- mission items out of order and past the count: refused, old mission intact
        gcs.send(gcs.mav.mission_count_encode(sim.sysid, 1, 2, 0))
        assert gcs.wait("MISSION_REQUEST_INT", 3.0, lambda m: m.seq == 0) is not None
        for seq in (1, 5):
            frame, cmd, p1, p2, p3, p4, x, y, z = MISSION[2]
            gcs.send(gcs.mav.mission_item_int_encode(sim.sysid, 1, seq, frame, cmd, 0, 1, p1, p2, p3, p4, x, y, 50.0))
            ack = gcs.wait("MISSION_ACK", 3.0)
            assert ack is not None and ack.type == mavlink.MAV_MISSION_INVALID_SEQUENCE
        # abandon that upload; an item belonging to no upload is refused as well
        cancelled = gcs.wait("MISSION_ACK", 10.0)  # the upload timeout is 5 s of wall-clock time
        assert cancelled is not None and cancelled.type == mavlink.MAV_MISSION_OPERATION_CANCELLED
        gcs.send(gcs.mav.mission_item_int_encode(sim.sysid, 1, 0, 3, 16, 0, 1, 0, 0, 0, 0, 1, 1, 5.0))
        ack = gcs.wait("MISSION_ACK", 3.0)
        assert ack is not None and ack.type == mavlink.MAV_MISSION_DENIED
        assert stored_mission(gcs) == [
            tuple(float(v) if i < 6 or i == 8 else v for i, v in enumerate(row)) for row in MISSION
        ]

        # ---- absurd parameters: refused, PARAM_VALUE echoes the unchanged value
        for value in (NAN, 1e9, -3.0):
            gcs.send(gcs.mav.param_set_encode(sim.sysid, 1, b"WPNAV_SPEED", value, mavlink.MAV_PARAM_TYPE_REAL32))
            echo = gcs.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "WPNAV_SPEED")
            assert echo is not None and echo.param_value == 600.0

        # ---- still flying, still armed, in GUIDED at 10 m; every refusal was logged
        heartbeat = gcs.wait("HEARTBEAT", 3.0)
        assert heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and heartbeat.custom_mode == GUIDED
        position = gcs.wait("GLOBAL_POSITION_INT", 3.0)
        assert abs(position.relative_alt / 1000.0 - 10.0) < 0.5
        assert sim.is_running()
        log = sim.log_text()
        for kind in ("bad_crc", "unknown_id", "truncated"):
            assert f"({kind}:" in log, f"no log line for {kind}"
        assert "MAV_CMD_NAV_TAKEOFF refused" in log and "UNSUPPORTED" in log
        assert "INVALID_SEQUENCE" in log and "PARAM_SET refused" in log


def test_two_instances_side_by_side_and_tlog(tmp_path):
    tlog = tmp_path / "flight.tlog"
    with (
        start_sim_vehicle(instance=0, speedup=5.0, extra_args=["--tlog", str(tlog)]) as sim0,
        start_sim_vehicle(instance=1, speedup=5.0) as sim1,
        MavlinkPeer(sim0.port, sim0.sysid) as gcs0,
        MavlinkPeer(sim1.port, sim1.sysid) as gcs1,
    ):
        assert (sim0.sysid, sim1.sysid) == (1, 2)
        assert gcs0.wait("HEARTBEAT", 3.0).get_srcSystem() == 1
        assert gcs1.wait("HEARTBEAT", 3.0).get_srcSystem() == 2
        gcs0.request("GLOBAL_POSITION_INT")
        assert gcs0.upload(MISSION) == mavlink.MAV_MISSION_ACCEPTED
        take_off(gcs1, 5.0)
        # instance 0 did not move and got no mission from instance 1; instance 1 has no mission
        assert gcs0.wait("GLOBAL_POSITION_INT", 3.0).relative_alt == 0
        assert not gcs0.wait("HEARTBEAT", 3.0).base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        assert len(stored_mission(gcs0)) == 3 and stored_mission(gcs1) == []
        assert abs(gcs1.wait("GLOBAL_POSITION_INT", 3.0).relative_alt / 1000.0 - 5.0) < 0.5
    # the tlog opens with pymavlink (as MAVProxy / MAVExplorer do) and holds both directions
    log = mavutil.mavlink_connection(str(tlog))
    types = set()
    while (msg := log.recv_match()) is not None:
        types.add((msg.get_type(), msg.get_srcSystem()))
    assert ("HEARTBEAT", 1) in types and ("GLOBAL_POSITION_INT", 1) in types
    assert ("MISSION_COUNT", 250) in types  # received traffic is recorded too


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--speedup", "-3"], "--speedup"),
        (["--home", "95,8,400"], "--home"),
        (["--out", "localhost"], "--out"),
        (["--profile", "/no/such/profile.toml"], "--profile"),
        (["--config", "/no/such/settings.toml"], "settings.toml"),
    ],
)
def test_cli_errors_are_one_line_without_traceback(args, fragment):
    port = free_port()
    proc = subprocess.run(
        [sys.executable, "-m", "sim_vehicle.cli", "--port", str(port), *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=str(REPO_ROOT),
    )
    assert proc.returncode == 2
    lines = [line for line in proc.stderr.splitlines() if line.strip() and " INFO " not in line]
    assert len(lines) == 1 and lines[0].startswith("sim-vehicle: error:") and fragment in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_port_in_use_is_a_clear_error():
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("0.0.0.0", 0))
        port = busy.getsockname()[1]
        proc = subprocess.run(
            [sys.executable, "-m", "sim_vehicle.cli", "--port", str(port), "--no-default-out"],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=str(REPO_ROOT),
        )
    assert proc.returncode == 2 and f"UDP port {port}" in proc.stderr and "Traceback" not in proc.stderr


def test_guided_global_int_velocity_and_yaw_setpoints():
    with start_sim_vehicle(speedup=10.0) as sim, MavlinkPeer(sim.port, sim.sysid) as gcs:
        take_off(gcs, 8.0)
        gcs.request("ATTITUDE")
        # SET_POSITION_TARGET_GLOBAL_INT: 15 m north of home at 12 m relative altitude, yaw 90 deg
        lat = int(round((47.397742 + 15.0 / 111_132.95) * 1e7))
        mask = 0b100111111000  # position + yaw
        target = None
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            gcs.send(
                gcs.mav.set_position_target_global_int_encode(
                    0,
                    sim.sysid,
                    1,
                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    mask,
                    lat,
                    85455940,
                    12.0,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                    1.5707963,
                    0,
                )
            )
            local = gcs.wait("LOCAL_POSITION_NED", 0.2)
            if local is not None and abs(local.x - 15.0) < 0.3 and abs(local.z + 12.0) < 0.3 and abs(local.y) < 0.3:
                target = local
                break
        assert target is not None, sim.log_tail()
        attitude = gcs.wait("ATTITUDE", 10.0, lambda m: abs(m.yaw - 1.5707963) < 0.05)
        assert attitude is not None
        # velocity-only setpoints (type_mask ignores position, acceleration, yaw): fly east at 2 m/s
        mask = 0b110111000111
        moving = None
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and moving is None:
            gcs.send(
                gcs.mav.set_position_target_local_ned_encode(
                    0, sim.sysid, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, 0, 0, 0, 0.0, 2.0, 0.0, 0, 0, 0, 0, 0
                )
            )
            moving = gcs.wait("LOCAL_POSITION_NED", 0.2, lambda m: abs(m.vy - 2.0) < 0.1 and abs(m.vx) < 0.1)
        assert moving is not None
        # then silence: GUID_TIMEOUT brakes the vehicle to a hover
        stopped = gcs.wait(
            "LOCAL_POSITION_NED", 15.0, lambda m: abs(m.vx) < 0.05 and abs(m.vy) < 0.05 and m.y > moving.y + 1.0
        )
        assert stopped is not None and abs(stopped.z + 12.0) < 0.5
        assert "GUID_TIMEOUT" in sim.log_text()


def test_requests_streams_timesync_and_wall_clock_heartbeats():
    M = mavlink
    with start_sim_vehicle(speedup=5.0) as sim, MavlinkPeer(sim.port, sim.sysid) as gcs:
        # as ArduCopter: nothing but HEARTBEAT until asked
        unasked = set()
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            unasked |= {m.get_type() for m in gcs.receive(0.1)}
        assert unasked <= {"HEARTBEAT"}, unasked
        # AUTOPILOT_VERSION on request, with the capabilities MAVSDK and QGC need
        for command, params in (
            (M.MAV_CMD_REQUEST_MESSAGE, (M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,)),
            (M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, (1,)),
        ):
            gcs.last.pop("AUTOPILOT_VERSION", None)
            assert gcs.command(command, *params).result == M.MAV_RESULT_ACCEPTED
            version = gcs.last.get("AUTOPILOT_VERSION") or gcs.wait("AUTOPILOT_VERSION", 3.0)
            assert version is not None
            for bit in (
                M.MAV_PROTOCOL_CAPABILITY_MISSION_INT,
                M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY,
            ):
                assert version.capabilities & bit
        # HOME_POSITION on request (both ways)
        assert gcs.command(M.MAV_CMD_GET_HOME_POSITION).result == M.MAV_RESULT_ACCEPTED
        home = gcs.last.get("HOME_POSITION") or gcs.wait("HOME_POSITION", 3.0)
        assert (home.latitude, home.longitude, home.altitude) == (473977420, 85455940, 488000)
        gcs.last.pop("HOME_POSITION")
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION).result == M.MAV_RESULT_ACCEPTED
        assert gcs.last.get("HOME_POSITION") or gcs.wait("HOME_POSITION", 3.0)
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, 12345).result == M.MAV_RESULT_FAILED  # as ArduPilot answers
        # TIMESYNC answered
        gcs.send(gcs.mav.timesync_encode(0, 123456789))
        sync = gcs.wait("TIMESYNC", 3.0, lambda m: m.ts1 == 123456789)
        assert sync is not None and sync.tc1 > 0
        # SET_MESSAGE_INTERVAL: ATTITUDE at 5 Hz of simulated time, then off
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 200000).result == 0
        first = gcs.wait("ATTITUDE", 3.0)
        stamps = [first.time_boot_ms]
        while stamps[-1] - stamps[0] < 4000:
            stamps.append(gcs.wait("ATTITUDE", 3.0).time_boot_ms)
        # 5 Hz of simulated time: 200 ms between stamps (a period the vehicle's loop skips when
        # the machine is loaded, as ArduPilot's scheduler does, shows as one gap of 400 ms)
        gaps = np.diff(stamps)
        assert len(stamps) >= 15 and float(np.median(gaps)) == pytest.approx(200.0, abs=10.0), gaps
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, -1).result == 0
        gcs.request("SYSTEM_TIME", rate_hz=1.0)
        gcs.wait("SYSTEM_TIME", 2.0)
        assert gcs.wait("ATTITUDE", 2.0) is None
        # heartbeats at 1 Hz of wall-clock time: far fewer than one per simulated second at 5x
        start = gcs.wait("SYSTEM_TIME", 3.0)
        beats = 0
        while True:
            assert gcs.wait("HEARTBEAT", 3.0) is not None, "a heartbeat is missing"
            beats += 1
            now = gcs.last.get("SYSTEM_TIME", start)
            if now.time_boot_ms - start.time_boot_ms >= 15000:
                break
        sim_s = (now.time_boot_ms - start.time_boot_ms) / 1000.0
        wall_s = (now.time_unix_usec - start.time_unix_usec) / 1e6
        assert beats <= 0.5 * sim_s and abs(beats - wall_s) <= 2.0
        # every stream group at once (REQUEST_DATA_STREAM ALL, as MAVProxy asks); SERVO_OUTPUT_RAW in 1000..2000 us
        gcs.send(gcs.mav.request_data_stream_encode(sim.sysid, 1, M.MAV_DATA_STREAM_ALL, 4, 1))
        assert gcs.wait("GLOBAL_POSITION_INT", 3.0) is not None
        servo = gcs.wait("SERVO_OUTPUT_RAW", 3.0)
        assert all(1000 <= getattr(servo, f"servo{i}_raw") <= 2000 for i in range(1, 5))
        for kind in ("SYS_STATUS", "LOCAL_POSITION_NED", "VFR_HUD", "MISSION_CURRENT", "ATTITUDE", "RC_CHANNELS"):
            assert gcs.wait(kind, 3.0) is not None, kind
