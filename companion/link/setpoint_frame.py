"""The 50 Hz SET_POSITION_TARGET_LOCAL_NED frame, packed in one step (pure: numbers in, bytes out).

pymavlink builds a message object from keyword fields, then packs it through its generic
``MAVLink_message._pack`` (header object, byte array, CRC object, signature): with the field
dictionary before it, about 75 us of the event loop per setpoint in flight on the benchmark's
machine (``benchmarks/companion_cpu.py --account``). ``SetpointFrame.pack`` writes the same
bytes directly from the field values in wire order: the payload with pymavlink's own
``struct.Struct`` for the message, MAVLink 2's trailing-zero truncation, the header, the
CRC-16/MCRF4XX with the message's CRC extra (pymavlink's ``x25crc``) and, when the encoder
signs, the signature (SHA-256 over key, frame, link id and timestamp; the encoder's timestamp
moves on by one, as pymavlink's does). ``tests/unit/link/test_setpoint_frame.py`` checks that the
bytes are pymavlink's, signed and unsigned, for arbitrary values.
"""

from __future__ import annotations

import hashlib
import struct

from companion.errors import LinkError
from heli_common.mavlink_ids import (
    TYPEMASK_IGNORE_ACCELERATION,
    TYPEMASK_IGNORE_POSITION,
    TYPEMASK_IGNORE_VELOCITY,
    mavlink,
)

__all__ = ["SETPOINT_MESSAGE", "SetpointFrame", "setpoint_type_mask", "setpoint_values"]

SETPOINT_MESSAGE = mavlink.MAVLink_set_position_target_local_ned_message
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_LINK_TIMESTAMP = struct.Struct("<BQ")
_ZERO3 = (0.0, 0.0, 0.0)
#: The largest finite float32 (the message's floats): a larger value cannot be sent.
FLOAT32_MAX = 3.4028234663852886e38
_GROUP_NAMES = ("pos_ned_m", "vel_ned_m_s", "acc_ned_m_s2", "yaw_rad", "yaw_rate_rad_s")


def setpoint_type_mask(pos, vel, acc, yaw, yaw_rate=None) -> int:
    """SET_POSITION_TARGET type_mask: a field group is ignored when it is None."""
    mask = 0
    for value, bits in (
        (pos, TYPEMASK_IGNORE_POSITION),
        (vel, TYPEMASK_IGNORE_VELOCITY),
        (acc, TYPEMASK_IGNORE_ACCELERATION),
        (yaw, mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE),
        (yaw_rate, mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE),
    ):
        if value is None:
            mask |= bits
    return mask


def _three(value, name: str) -> tuple | list:
    """``value`` as 3 floats (None: three zeros); ``LinkError`` naming ``name`` otherwise."""
    if value is None:
        return _ZERO3
    try:
        values = [float(v) for v in (value.tolist() if hasattr(value, "tolist") else value)]
    except (TypeError, ValueError):
        values = []
    if len(values) != 3 or not (
        abs(values[0]) <= FLOAT32_MAX and abs(values[1]) <= FLOAT32_MAX and abs(values[2]) <= FLOAT32_MAX
    ):  # NaN fails too
        raise LinkError(f"setpoint {name} must be 3 finite numbers, got {value!r}")
    return values


def _scalar(value, name: str) -> float:
    if value is None:
        return 0.0
    value = float(value)
    if not abs(value) <= FLOAT32_MAX:
        raise LinkError(f"setpoint {name} must be finite, got {value!r}")
    return value


def setpoint_values(
    time_boot_ms: int,
    target_system: int,
    target_component: int,
    pos_ned_m=None,
    vel_ned_m_s=None,
    acc_ned_m_s2=None,
    yaw_rad=None,
    yaw_rate_rad_s=None,
) -> tuple:
    """SET_POSITION_TARGET_LOCAL_NED's field values in wire order
    (``SETPOINT_MESSAGE.ordered_fieldnames``), frame LOCAL_NED; a group given as None is 0
    and masked out in ``type_mask``.

    Parameters
    ----------
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : (3,) array_like or None
    yaw_rad, yaw_rate_rad_s : float or None

    Raises
    ------
    LinkError
        A given vector is not 3 finite numbers, or a given yaw is not finite (named).
    """
    pos, vel, acc = (_three(v, n) for v, n in zip((pos_ned_m, vel_ned_m_s, acc_ned_m_s2), _GROUP_NAMES))
    return (
        int(time_boot_ms) & 0xFFFFFFFF,
        *pos,
        *vel,
        *acc,
        _scalar(yaw_rad, "yaw_rad"),
        _scalar(yaw_rate_rad_s, "yaw_rate_rad_s"),
        setpoint_type_mask(pos_ned_m, vel_ned_m_s, acc_ned_m_s2, yaw_rad, yaw_rate_rad_s),
        target_system,
        target_component,
        mavlink.MAV_FRAME_LOCAL_NED,
    )


class SetpointFrame:
    """One setpoint to pack: ``pack(encoder)`` as pymavlink's message ``pack`` would.

    Parameters
    ----------
    values : tuple
        ``setpoint_values(...)``.
    """

    __slots__ = ("values",)

    def __init__(self, values: tuple) -> None:
        self.values = values

    def pack(self, mav: mavlink.MAVLink) -> bytes:
        """The frame from ``mav``'s system, component and sequence, signed when ``mav`` signs."""
        payload = SETPOINT_MESSAGE.unpacker.pack(*self.values)
        payload = payload.rstrip(b"\0") or payload[:1]  # MAVLink 2: trailing zeros cut
        signing = mav.signing
        signed = signing.sign_outgoing
        frame = (
            _HEADER.pack(
                253,
                len(payload),
                mavlink.MAVLINK_IFLAG_SIGNED if signed else 0,
                0,
                mav.seq,
                mav.srcSystem,
                mav.srcComponent,
                SETPOINT_MESSAGE.id & 0xFFFF,
                SETPOINT_MESSAGE.id >> 16,
            )
            + payload
        )
        crc = mavlink.x25crc(frame[1:])
        crc.accumulate(bytes((SETPOINT_MESSAGE.crc_extra,)))
        frame += _CRC.pack(crc.crc)
        if not signed:
            return frame
        frame += _LINK_TIMESTAMP.pack(signing.link_id, signing.timestamp)[:7]
        signing.timestamp += 1
        return frame + hashlib.sha256(signing.secret_key + frame).digest()[:6]
