"""The setpoint stream's own frame packing gives pymavlink's bytes, signed and unsigned."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import LinkError
from companion.link.setpoint_frame import SETPOINT_MESSAGE, SetpointFrame, setpoint_values
from mavlink_signing import signing_encoder

floats = st.floats(allow_nan=False, allow_infinity=False, width=32)
vector = st.none() | st.tuples(floats, floats, floats)
scalar = st.none() | floats


def encoder(signed: bool, link_id: int, seq: int, timestamp: int) -> mavlink.MAVLink:
    mav = signing_encoder(bytes(range(32)), link_id, 7, 191) if signed else mavlink.MAVLink(None, 7, 191)
    mav.seq = seq
    if signed:
        mav.signing.timestamp = timestamp
    return mav


@settings(max_examples=300, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    vector,
    vector,
    vector,
    scalar,
    scalar,
    st.booleans(),
    st.integers(0, 255),
    st.integers(0, 255),
    st.integers(0, 2**48 - 2),
)
def test_frame_is_pymavlinks(time_boot_ms, pos, vel, acc, yaw, yaw_rate, signed, link_id, seq, timestamp):
    values = setpoint_values(time_boot_ms, 1, 1, pos, vel, acc, yaw, yaw_rate)
    ours, theirs = encoder(signed, link_id, seq, timestamp), encoder(signed, link_id, seq, timestamp)
    expected = SETPOINT_MESSAGE(**dict(zip(SETPOINT_MESSAGE.ordered_fieldnames, values))).pack(theirs)
    assert SetpointFrame(values).pack(ours) == expected
    assert ours.signing.timestamp == theirs.signing.timestamp


def test_all_zero_payload_keeps_one_byte_and_parses():
    values = setpoint_values(0, 0, 0, None, None, None, None, None)
    values = values[:12] + (0, 0, 0, 0)  # type_mask, targets and frame 0 as well
    frame = SetpointFrame(values).pack(mavlink.MAVLink(None, 1, 1))
    assert frame[1] == 1  # payload length after truncation
    msg = mavlink.MAVLink(None).parse_char(frame)
    assert msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and msg.x == 0.0


def test_signed_frame_passes_the_receivers_check():
    key = bytes(range(32))
    frame = SetpointFrame(setpoint_values(1234, 1, 1, [1.0, 2.0, -3.0], None, None, 0.5)).pack(
        signing_encoder(key, 3, 255, 190)
    )
    receiver = mavlink.MAVLink(None)
    receiver.signing.secret_key, receiver.signing.sign_outgoing = key, False
    msg = receiver.parse_char(frame)
    assert msg.get_signed() and (msg.x, msg.z) == (1.0, -3.0) and math.isclose(msg.yaw, 0.5)


def test_values_beyond_float32_are_named():
    with pytest.raises(LinkError, match="vel_ned_m_s"):
        setpoint_values(0, 1, 1, [0, 0, 0], [1e39, 0, 0])
    with pytest.raises(LinkError, match="yaw_rate_rad_s"):
        setpoint_values(0, 1, 1, [0, 0, 0], yaw_rad=0.0, yaw_rate_rad_s=math.nan)
