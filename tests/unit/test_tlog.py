"""heli_common.tlog writes what pymavlink reads back as a telemetry log (issue 14, item 3)."""

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.tlog import TlogWriter


def frames() -> list[bytes]:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    out = [
        mav.heartbeat_encode(
            mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, mavlink.MAV_STATE_ACTIVE
        ).pack(mav)
    ]
    out.append(mav.local_position_ned_encode(1234, 1.0, -2.0, -10.0, 0.5, 0.0, 0.0).pack(mav))
    mav.signing.secret_key = bytes(range(32))
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = 1
    out.append(mav.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0).pack(mav))
    return out


def test_pymavlink_reads_every_frame_back_with_its_time(tmp_path):
    times = iter([1000.0, 1000.0, 1000.25, 1000.5, 1001.0])
    path = tmp_path / "companion.tlog"
    log = TlogWriter(path, clock=lambda: next(times))
    for frame in frames():
        log.write(frame)
    log.close()
    log.write(b"ignored once closed")
    assert log.frames == 3
    reader = mavutil.mavlink_connection(str(path))
    got = []
    while (msg := reader.recv_match()) is not None:
        got.append((msg.get_type(), round(msg._timestamp, 3)))
    assert got == [("HEARTBEAT", 1000.0), ("LOCAL_POSITION_NED", 1000.25), ("COMMAND_LONG", 1000.5)]


def test_a_restarted_writer_appends(tmp_path):
    path = tmp_path / "a.tlog"
    for _ in range(2):
        log = TlogWriter(path)
        log.write(frames()[0])
        log.close()
    reader = mavutil.mavlink_connection(str(path))
    assert sum(1 for _ in iter(lambda: reader.recv_match(type="HEARTBEAT"), None)) == 2
