"""MAVLink and ArduCopter numbers, all taken from pymavlink (never written by hand).

``mavlink`` is pymavlink's generated ArduPilot dialect: use ``mavlink.MAV_CMD_NAV_TAKEOFF``,
``mavlink.MAV_FRAME_GLOBAL``, ``mavlink.MAVLINK_MSG_ID_HOME_POSITION`` ... directly. This module
adds only the tables pymavlink does not offer in the form we need.
"""

from __future__ import annotations

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = [
    "mavlink",
    "COPTER_MODES",
    "COPTER_MODE_NAMES",
    "copter_mode_name",
    "enum_names",
    "MAV_RESULT_NAMES",
    "TYPEMASK_IGNORE_POSITION",
    "TYPEMASK_IGNORE_VELOCITY",
    "TYPEMASK_IGNORE_ACCELERATION",
]

#: ArduCopter flight modes (HEARTBEAT.custom_mode), name -> number.
COPTER_MODES: dict[str, int] = {name: number for number, name in mavutil.mode_mapping_acm.items()}
#: ArduCopter flight modes, number -> name.
COPTER_MODE_NAMES: dict[int, str] = dict(mavutil.mode_mapping_acm)


def copter_mode_name(mode: int, unknown: str = "MODE_{}") -> str:
    """ArduCopter name of mode ``mode`` (``unknown.format(mode)`` if there is none)."""
    return COPTER_MODE_NAMES.get(mode, unknown.format(mode))


def enum_names(enum: str, prefix: str | None = None) -> dict[int, str]:
    """Value -> name of a MAVLink enum of the dialect, without ``prefix`` (default ``enum + "_"``)
    and without the generated ``*_ENUM_END`` entry."""
    prefix = enum + "_" if prefix is None else prefix
    return {
        value: entry.name.removeprefix(prefix)
        for value, entry in mavlink.enums[enum].items()
        if not entry.name.endswith("_ENUM_END")
    }


#: MAV_RESULT value -> name without the prefix (``0: "ACCEPTED"`` ...).
MAV_RESULT_NAMES: dict[int, str] = enum_names("MAV_RESULT")

# SET_POSITION_TARGET_* type_mask (POSITION_TARGET_TYPEMASK): the bits of each vector together
TYPEMASK_IGNORE_POSITION = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE
)
TYPEMASK_IGNORE_VELOCITY = (
    mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
TYPEMASK_IGNORE_ACCELERATION = (
    mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
