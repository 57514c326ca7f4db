"""The vehicle link: MAVSDK 4.x connection, telemetry, missions, commands and the 50 Hz
GUIDED setpoint stream (DESIGN.md section 5).

Modules: ``vehicle`` (VehicleLink: the connection and its lifecycle, holding one part per job
as a member: ``watchers`` (telemetry subscriptions), ``waits``, ``vehicle_commands``
(COMMAND_LONG, parameters), ``message_tap`` (raw messages in), ``direct_messages`` (setpoints
and STATUSTEXT out) and ``mission_transfer``; ``session``: MAVSDK's handles the parts share;
``ports``: the Protocols the parts call), ``telemetry`` (the snapshot), ``streams`` (the
telemetry asked for), ``frames`` (home vs the vehicle's EKF origin), ``setpoints`` (the 50 Hz
stream), ``gate`` and ``transport`` (MAVLink signing in front of MAVSDK).

MAVSDK is imported lazily (inside ``VehicleLink.connect``), so importing this package is cheap.
"""

from companion.link.direct_messages import setpoint_fields
from companion.link.setpoint_frame import setpoint_type_mask
from companion.link.setpoints import (
    JitterStats,
    Setpoint,
    SetpointStreamer,
    hold_position,
    jitter_stats,
    planning_worker_init,
    raise_stream_priority,
    restore_normal_priority,
)
from companion.link.telemetry import Telemetry
from companion.link.vehicle import DEFAULT_URL, VehicleLink, check_url
from companion.link.vehicle_commands import COPTER_MODES

__all__ = [
    "COPTER_MODES",
    "DEFAULT_URL",
    "JitterStats",
    "Setpoint",
    "SetpointStreamer",
    "Telemetry",
    "VehicleLink",
    "check_url",
    "hold_position",
    "jitter_stats",
    "planning_worker_init",
    "raise_stream_priority",
    "restore_normal_priority",
    "setpoint_fields",
    "setpoint_type_mask",
]
