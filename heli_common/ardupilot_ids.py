"""ArduPilot numbers that pymavlink does not define, written once for the vehicle and the companion.

They are ArduPilot's, not MAVLink's: the dialect has ``MAV_CMD_DO_AUX_FUNCTION`` but not the
``RC_Channel::AUX_FUNC`` list it takes, nor the force-disarm value ``AP_Arming`` checks.
"""

from __future__ import annotations

from heli_common.mavlink_ids import mavlink

__all__ = ["AUX_FUNCTION_MOTOR_INTERLOCK", "FORCE_DISARM_MAGIC", "SWITCH_LOW", "SWITCH_MIDDLE", "SWITCH_HIGH"]

#: ``RC_Channel::AUX_FUNC::MOTOR_INTERLOCK``: the RCx_OPTION / DO_AUX_FUNCTION number.
AUX_FUNCTION_MOTOR_INTERLOCK = 32
#: MAV_CMD_COMPONENT_ARM_DISARM param2 that disarms even in flight (``AP_Arming``).
FORCE_DISARM_MAGIC = 21196
#: Aux switch positions (``RC_Channel::AuxSwitchPos``; DO_AUX_FUNCTION param2).
SWITCH_LOW = mavlink.MAV_CMD_DO_AUX_FUNCTION_SWITCH_LEVEL_LOW
SWITCH_MIDDLE = mavlink.MAV_CMD_DO_AUX_FUNCTION_SWITCH_LEVEL_MIDDLE
SWITCH_HIGH = mavlink.MAV_CMD_DO_AUX_FUNCTION_SWITCH_LEVEL_HIGH
