"""Property-based fuzz of ``sim-vehicle``'s MAVLink input (issue 11).

The vehicle's :class:`~sim_vehicle.mavlink.MavlinkServer` runs in-process, flying in
GUIDED at 10 m with a stored three-item mission, its socket replaced by a queue so that every
hypothesis-generated datagram goes through ``_receive`` and ``_handle_datagram`` exactly as a
UDP datagram would. Datagrams: random bytes, valid frames with one byte changed (bad CRC or a
changed header), truncated frames, and valid messages with extreme fields (COMMAND_LONG /
COMMAND_INT with any command and NaN/inf/huge parameters, SET_POSITION_TARGET_* with NaN,
MISSION_COUNT with huge counts, mission items out of order, PARAM_SET with absurd values ...).

Properties, after every example:

- no exception escapes, and the server logged no ERROR (its handlers' catch-alls stayed unused);
- every datagram is counted in ``packets_in``, and every non-empty one raised ``messages_in`` or
  a drop counter (``bad_crc``, ``unknown_id``, ``bad_data``, ``truncated`` ...);
- the stored mission, fence and rally lists change only when the server acknowledged a complete
  upload (MISSION_ACK ACCEPTED); the test then uploads the reference mission again;
- every parameter is finite and within its range;
- after 0.5 s of simulated flight the vehicle's state is finite and above the ground.

MISSION_CLEAR_ALL is left out of the junk: without MAVLink signing a vehicle obeys it from
anyone (ArduPilot does too), so it is not junk but a command.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_model.model import HeliModel
from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.autopilot import Autopilot
from sim_vehicle.config import VehicleSettings, replace_path

HOME = (47.397742, 8.545594, 488.0, 0.0)
GCS = ("127.0.0.1", 40001)
SYSID = 1
MISSION_TYPES = (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY)
MISSION = [  # frame, command, p1..p4, x, y, z (as tests/integration/test_sitl_robustness.py)
    (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0, 0.0, 473977420, 85455940, 488.0),
    (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, 0.0, 0, 0, 10.0),
    (
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mavlink.MAV_CMD_NAV_WAYPOINT,
        0.0,
        2.0,
        0.0,
        0.0,
        473978320,
        85455940,
        10.0,
    ),
]
#: Counters that are not a per-datagram verdict (``ignored`` and ``commands`` count messages
#: already in ``messages_in``).
NOT_A_VERDICT = {"packets_in", "packets_out", "ignored", "commands"}


class QueueSocket:
    """Stands in for the server's UDP socket: datagrams in from a queue, datagrams out recorded."""

    def __init__(self) -> None:
        self.inbox: collections.deque = collections.deque()
        self.sent: list[tuple[tuple, bytes]] = []

    def recvfrom(self, size: int):
        if not self.inbox:
            raise BlockingIOError
        return self.inbox.popleft()

    def sendto(self, data: bytes, address: tuple) -> int:
        self.sent.append((address, bytes(data)))
        return len(data)

    def close(self) -> None:
        pass


class Errors(logging.Handler):
    """Collects the ERROR (and worse) records of a logger while in a ``with`` block."""

    def __init__(self, logger: str) -> None:
        super().__init__(logging.ERROR)
        self.logger = logging.getLogger(logger)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def __enter__(self) -> Errors:
        self.logger.addHandler(self)
        return self

    def __exit__(self, *exc) -> None:
        self.logger.removeHandler(self)


def decode(sent: list[tuple[tuple, bytes]]) -> list:
    """The messages in the recorded datagrams."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    out = []
    for _, data in sent:
        out += [m for m in parser.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
    return out


def verdicts(stats) -> int:
    """Messages accepted plus datagrams (or parts) dropped, whatever counters the server has."""
    return sum(v for k, v in dataclasses.asdict(stats).items() if k not in NOT_A_VERDICT and isinstance(v, int))


def feed(server, data: bytes, address=GCS) -> None:
    """One datagram through the server's receive path."""
    server.sock.inbox.append((data, address))
    server._receive()


def fly(server, seconds: float) -> None:
    """Run the simulation as ``run_once`` does, without the wall clock."""
    steps = int(round(seconds * server.settings.timing.physics_rate_hz))
    for _ in range(0, steps, 20):
        server._handle_events(server.autopilot.run_steps(20))
        server.clock.advance(20)
        server._send_due_streams()


def upload(server, rows, mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION) -> int:
    """Upload ``rows`` through the protocol; returns the final MISSION_ACK type."""
    gcs = mavlink.MAVLink(None, 250, 190)
    start = len(server.sock.sent)
    feed(server, gcs.mission_count_encode(SYSID, 1, len(rows), mission_type).pack(gcs))
    for seq, (frame, cmd, p1, p2, p3, p4, x, y, z) in enumerate(rows):
        feed(
            server,
            gcs.mission_item_int_encode(SYSID, 1, seq, frame, cmd, 0, 1, p1, p2, p3, p4, x, y, z, mission_type).pack(
                gcs
            ),
        )
    acks = [m for m in decode(server.sock.sent[start:]) if m.get_type() == "MISSION_ACK"]
    return acks[-1].type if acks else -1


@pytest.fixture(scope="module")
def flying():
    """A server whose vehicle hovers at 10 m in GUIDED with MISSION stored (shared by the examples)."""
    from sim_vehicle.mavlink import MavlinkServer

    vehicle_settings = replace_path(VehicleSettings(), "link.out", ())
    vehicle = Autopilot(HeliModel.default(), vehicle_settings, HOME, np.random.default_rng(0))
    server = MavlinkServer(vehicle, vehicle_settings, SYSID, 0)
    real = server.sock
    server.sock = QueueSocket()
    try:
        assert upload(server, MISSION) == mavlink.MAV_MISSION_ACCEPTED
        assert vehicle.set_mode(ap.GUIDED)[0]
        assert vehicle.arming.set_interlock_switch(rsc.SWITCH_LOW)[0] and vehicle.arm()[0]
        assert vehicle.arming.set_interlock_switch(rsc.SWITCH_HIGH)[0]
        s = vehicle.settings.rsc
        fly(server, s.arming_delay_s + s.runup_time_s + 0.5)
        assert vehicle.takeoff(10.0)[0]
        fly(server, 12.0)
        assert abs(vehicle.pos_ned_m[2] + 10.0) < 0.5
        yield server
    finally:
        real.close()


# ================================================================ strategies
U8, U16 = st.integers(0, 0xFF), st.integers(0, 0xFFFF)
U32 = st.integers(0, 0xFFFFFFFF)
I32 = st.integers(-(2**31), 2**31 - 1)
#: Float32 values, with NaN, infinities, the extremes and values near the interesting bounds.
F32 = st.one_of(
    st.floats(width=32),
    st.sampled_from([math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 0.0, -1.0, 1.0, 2.0, 21196.0, 1e9]),
)
TARGET_SYSTEM = st.sampled_from([SYSID] * 5 + [0, 2, 255])
TARGET_COMPONENT = st.sampled_from([1] * 5 + [0, 190, 255])
MISSION_TYPE = st.one_of(st.sampled_from([0, 0, 1, 2, 255]), U8)
COMMANDS = st.one_of(st.sampled_from(sorted(mavlink.enums["MAV_CMD"])), U16)
PARAM_NAMES = st.one_of(
    st.sampled_from(
        [
            "WPNAV_SPEED",
            "SIM_SPEEDUP",
            "GUID_TIMEOUT",
            "H_RSC_RUNUP_TIME",
            "SIM_WIND_SPD",
            "MAV_GCS_SYSID",
            "LQI_Q_U",
            "POS_KP_XY",
        ]
    ),
    st.binary(max_size=16),
)
LOCAL_FRAMES = st.one_of(
    st.sampled_from(
        [
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
            mavlink.MAV_FRAME_BODY_NED,
            mavlink.MAV_FRAME_BODY_OFFSET_NED,
        ]
    ),
    U8,
)
GLOBAL_FRAMES = st.one_of(
    st.sampled_from(
        [
            mavlink.MAV_FRAME_GLOBAL,
            mavlink.MAV_FRAME_GLOBAL_INT,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        ]
    ),
    U8,
)


def f32s(n: int):
    return st.tuples(*[F32] * n)


MESSAGES = st.one_of(
    st.builds(
        lambda ts, tc, cmd, conf, p: mavlink.MAVLink_command_long_message(ts, tc, cmd, conf, *p),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        COMMANDS,
        U8,
        f32s(7),
    ),
    st.builds(
        lambda ts, tc, frame, cmd, p, x, y, z: mavlink.MAVLink_command_int_message(
            ts, tc, frame, cmd, 0, 0, *p, x, y, z
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        U8,
        COMMANDS,
        f32s(4),
        I32,
        I32,
        F32,
    ),
    st.builds(
        lambda ts, tc, frame, mask, p: mavlink.MAVLink_set_position_target_local_ned_message(
            0, ts, tc, frame, mask, *p
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        LOCAL_FRAMES,
        U16,
        f32s(11),
    ),
    st.builds(
        lambda ts, tc, frame, mask, lat, lon, p: mavlink.MAVLink_set_position_target_global_int_message(
            0, ts, tc, frame, mask, lat, lon, *p
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        GLOBAL_FRAMES,
        U16,
        I32,
        I32,
        f32s(9),
    ),
    st.builds(
        lambda ts, tc, count, mt: mavlink.MAVLink_mission_count_message(ts, tc, count, mt),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        st.one_of(st.integers(1, 4), U16),
        MISSION_TYPE,
    ),
    st.builds(
        lambda ts, tc, seq, frame, cmd, cur, auto, p, x, y, z, mt: mavlink.MAVLink_mission_item_int_message(
            ts, tc, seq, frame, cmd, cur, auto, *p, x, y, z, mt
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        st.one_of(st.integers(0, 4), U16),
        U8,
        COMMANDS,
        U8,
        U8,
        f32s(4),
        I32,
        I32,
        F32,
        MISSION_TYPE,
    ),
    st.builds(
        lambda ts, tc, seq, frame, cmd, cur, auto, p, mt: mavlink.MAVLink_mission_item_message(
            ts, tc, seq, frame, cmd, cur, auto, *p, mt
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        st.one_of(st.integers(0, 4), U16),
        U8,
        COMMANDS,
        U8,
        U8,
        f32s(7),
        MISSION_TYPE,
    ),
    st.builds(mavlink.MAVLink_mission_request_list_message, TARGET_SYSTEM, TARGET_COMPONENT, MISSION_TYPE),
    st.builds(mavlink.MAVLink_mission_request_int_message, TARGET_SYSTEM, TARGET_COMPONENT, U16, MISSION_TYPE),
    st.builds(mavlink.MAVLink_mission_set_current_message, TARGET_SYSTEM, TARGET_COMPONENT, U16),
    st.builds(mavlink.MAVLink_mission_ack_message, TARGET_SYSTEM, TARGET_COMPONENT, U8, MISSION_TYPE),
    st.builds(
        lambda ts, tc, name, value, ptype: mavlink.MAVLink_param_set_message(
            ts, tc, name if isinstance(name, bytes) else name.encode(), value, ptype
        ),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        PARAM_NAMES,
        F32,
        U8,
    ),
    st.builds(
        mavlink.MAVLink_param_request_read_message,
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        PARAM_NAMES.map(lambda n: n if isinstance(n, bytes) else n.encode()),
        st.integers(-32768, 32767),
    ),
    st.builds(mavlink.MAVLink_set_mode_message, TARGET_SYSTEM, U8, U32),
    st.builds(mavlink.MAVLink_request_data_stream_message, TARGET_SYSTEM, TARGET_COMPONENT, U8, U16, U8),
    st.builds(
        lambda ts, tc, ch: mavlink.MAVLink_rc_channels_override_message(ts, tc, *ch),
        TARGET_SYSTEM,
        TARGET_COMPONENT,
        st.tuples(*[U16] * 8),
    ),
    st.builds(mavlink.MAVLink_timesync_message, st.integers(-(2**63), 2**63 - 1), st.integers(-(2**63), 2**63 - 1)),
    st.builds(mavlink.MAVLink_heartbeat_message, U8, U8, U8, U32, U8, st.just(3)),
    st.builds(mavlink.MAVLink_statustext_message, U8, st.binary(max_size=50), U16, U8),
)
SENDERS = st.tuples(st.one_of(st.sampled_from([250, 255]), st.integers(1, 255)), st.integers(0, 255))


@st.composite
def frames(draw) -> bytes:
    """One packed, valid MAVLink 2 (or, one time in four, MAVLink 1) frame."""
    msg = draw(MESSAGES)
    sysid, compid = draw(SENDERS)
    mav = mavlink.MAVLink(None, sysid, compid)
    mav.seq = draw(U8)
    v1 = msg.id <= 255 and draw(st.integers(0, 3)) == 0  # a MAVLink 1 frame: only the v1 fields are sent
    return msg.pack(mav, force_mavlink1=v1)


@st.composite
def mutated(draw) -> bytes:
    """A valid frame with one byte changed (its CRC then fails, or its header lies)."""
    data = bytearray(draw(frames()))
    i = draw(st.integers(0, len(data) - 1))
    data[i] ^= draw(st.integers(1, 255))
    return bytes(data)


@st.composite
def truncated(draw) -> bytes:
    data = draw(frames())
    return data[: draw(st.integers(1, len(data) - 1))]


@st.composite
def concatenated(draw) -> bytes:
    """Several frames (some broken) in one datagram, as a router may send them."""
    parts = draw(st.lists(st.one_of(frames(), mutated(), truncated()), min_size=2, max_size=4))
    return b"".join(parts)


DATAGRAMS = st.one_of(frames(), frames(), mutated(), truncated(), concatenated(), st.binary(max_size=300))


# ================================================================ the properties
def check_stored_lists(server, before: dict, sent_from: int) -> bool:
    """Stored lists unchanged unless an upload was acknowledged; True if one was (then restored)."""
    acked = {
        m.mission_type
        for m in decode(server.sock.sent[sent_from:])
        if m.get_type() == "MISSION_ACK" and m.type == mavlink.MAV_MISSION_ACCEPTED
    }
    changed = False
    for mission_type in MISSION_TYPES:
        generation, items = before[mission_type]
        if server.store.generation(mission_type) == generation:
            assert server.store.items(mission_type) == items, f"list {mission_type} changed in place"
            continue
        assert mission_type in acked, (
            f"list {mission_type} replaced without an accepted upload "
            f"(MISSION_ACK ACCEPTED); now {server.store.items(mission_type)}"
        )
        changed = True
    return changed


def check_parameters(server) -> None:
    for spec in server.params.specs:
        value = server.params.value(spec)
        assert math.isfinite(value) and spec.minimum <= value <= spec.maximum, (spec.name, value)


def check_vehicle(server) -> None:
    vehicle = server.autopilot
    assert np.all(np.isfinite(vehicle.airframe.x)), vehicle.airframe.x
    assert np.all(np.isfinite(vehicle.pos_ned_m)) and np.all(np.isfinite(vehicle.euler_rad))
    assert vehicle.pos_ned_m[2] < 0.5, "below the ground"


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(datagrams=st.lists(DATAGRAMS, min_size=1, max_size=12))
def test_junk_is_counted_and_changes_nothing_stored(flying, datagrams):
    server = flying
    before = {t: (server.store.generation(t), server.store.items(t)) for t in MISSION_TYPES}
    sent_from = len(server.sock.sent)
    with Errors("sim_vehicle") as errors:
        for data in datagrams:
            packets, counted = server.stats.packets_in, verdicts(server.stats)
            feed(server, data)
            assert server.stats.packets_in == packets + 1
            if data:
                assert verdicts(server.stats) > counted, f"datagram {data!r} left no trace in {server.stats}"
        fly(server, 0.5)
    assert not errors.records, [r.getMessage() for r in errors.records]
    if check_stored_lists(server, before, sent_from):
        for mission_type in MISSION_TYPES:  # a legitimate upload happened: start again from the reference
            rows = MISSION if mission_type == mavlink.MAV_MISSION_TYPE_MISSION else []
            assert upload(server, rows, mission_type) == mavlink.MAV_MISSION_ACCEPTED
    assert [(i.frame, i.command, i.x, i.y, i.z) for i in server.store.items()] == [
        (r[0], r[1], r[6], r[7], r[8]) for r in MISSION
    ]
    check_parameters(server)
    check_vehicle(server)
    del server.sock.sent[:]


def test_abandoned_and_out_of_order_uploads_keep_the_mission(flying):
    """A reproducible case of the property: an upload abandoned half-way, items out of order."""
    server = flying
    gcs = mavlink.MAVLink(None, 77, 190)
    generation = server.store.generation()
    feed(server, gcs.mission_count_encode(SYSID, 1, 65535, 0).pack(gcs))
    feed(server, gcs.mission_count_encode(SYSID, 1, 3, 0).pack(gcs))
    for seq in (2, 0, 7):
        feed(
            server,
            gcs.mission_item_int_encode(SYSID, 1, seq, 3, 16, 0, 1, math.nan, 0, 0, 0, 1, 1, math.inf, 0).pack(gcs),
        )
    assert server.store.generation() == generation
    assert len(server.store.items()) == len(MISSION)
    feed(server, gcs.mission_ack_encode(SYSID, 1, mavlink.MAV_MISSION_OPERATION_CANCELLED, 0).pack(gcs))
    assert server.store.upload_in_progress(0) is None and server.store.generation() == generation
