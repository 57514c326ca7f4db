"""COMMAND_LONG, COMMAND_INT and SET_MODE: one handler table from MAV_CMD to handler, every command acknowledged.

Both command messages go through :data:`COMMAND_HANDLERS` (as ArduPilot's
``GCS_MAVLINK::handle_command_int_packet`` serves both), with the seven parameters in one list:
COMMAND_INT's ``x``, ``y`` and ``z`` are parameters 5 to 7 and its ``frame`` is kept (COMMAND_LONG
has none). A handler returns ``(MAV_RESULT, reason)``; the COMMAND_ACK goes back to the sender,
followed by any reply the handler queued (requested messages follow the ACK, as in ArduPilot).
A FAILED command with a reason also shows it as STATUSTEXT, unless the reason is a
:class:`~sim_vehicle.autopilot.QuietRefusal`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.ardupilot_ids import FORCE_DISARM_MAGIC
from heli_model.control import Setpoint
from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.autopilot import Autopilot, QuietRefusal
from sim_vehicle.mavlink.endpoint import Address, Endpoint
from sim_vehicle.mavlink.stream_sender import StreamSender
from sim_vehicle.mission_store import (
    FRAME_GLOBAL,
    FRAME_GLOBAL_INT,
    FRAME_GLOBAL_RELATIVE_ALT,
    FRAME_GLOBAL_RELATIVE_ALT_INT,
    GLOBAL_FRAMES,
)
from sim_vehicle.streams import MESSAGE_IDS, NAMES_BY_ID
from sim_vehicle.telemetry import Telemetry

log = logging.getLogger(__name__)

REQUESTABLE: dict[str, int] = {**MESSAGE_IDS, "AUTOPILOT_VERSION": mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION}
"""Messages MAV_CMD_REQUEST_MESSAGE answers (once, on the requesting link)."""

Outcome = tuple[int, str]
"""A handler's verdict: MAV_RESULT and the reason (a :class:`QuietRefusal` is not shown as STATUSTEXT)."""


@dataclasses.dataclass(frozen=True)
class CommandCall:
    """One received command: its message, sender, MAV_CMD, param1..param7 and frame (None for COMMAND_LONG)."""

    msg: Any
    address: Address
    command: int
    p: list[float]
    frame: int | None


class CommandProtocol:
    """Runs commands through :data:`COMMAND_HANDLERS` and acknowledges each.

    Parameters
    ----------
    endpoint : Endpoint
        Where the ACKs, replies and STATUSTEXTs go.
    autopilot : Autopilot
        The vehicle the commands act on.
    telemetry : Telemetry
        Builds the messages some commands reply with.
    sender : StreamSender
        The links' streams (SET/GET_MESSAGE_INTERVAL, REQUEST_MESSAGE).
    """

    def __init__(self, endpoint: Endpoint, autopilot: Autopilot, telemetry: Telemetry, sender: StreamSender) -> None:
        self.endpoint = endpoint
        self.autopilot = autopilot
        self.telemetry = telemetry
        self.sender = sender
        self.after_ack: list[tuple[Any, Address | None]] = []
        """Replies a handler queues to follow its COMMAND_ACK (address None: every link)."""
        self.refused_requests: set[int] = set()

    def on_command_long(self, msg: Any, address: Address) -> None:
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        self.run(CommandCall(msg, address, msg.command, params, None))

    def on_command_int(self, msg: Any, address: Address) -> None:
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z]
        self.run(CommandCall(msg, address, msg.command, params, msg.frame))

    def run(self, call: CommandCall) -> None:
        """Look the command up, run it, acknowledge it, then send the replies it queued."""
        self.endpoint.stats.commands += 1
        self.after_ack = []
        handler = COMMAND_HANDLERS.get(call.command)
        if handler is None:
            log.info("command %s (%d) from %s:%d: UNSUPPORTED", _name(call.command, "?"), call.command, *call.address)
            self.ack(call.msg, call.address, call.command, mavlink.MAV_RESULT_UNSUPPORTED)
            return
        try:
            result, reason = handler(self, call)
        except Exception:
            log.exception("command %d failed", call.command)
            result, reason = mavlink.MAV_RESULT_FAILED, "internal error"
        if result != mavlink.MAV_RESULT_ACCEPTED:
            log.warning(
                "command %s refused (%s): %s",
                _name(call.command, call.command),
                mavlink.enums["MAV_RESULT"][result].name,
                reason,
            )
        self.ack(call.msg, call.address, call.command, result)
        replies, self.after_ack = self.after_ack, []
        for reply, to in replies:
            self.endpoint.send(reply, to)
        if (
            result != mavlink.MAV_RESULT_ACCEPTED
            and reason
            and result == mavlink.MAV_RESULT_FAILED
            and not isinstance(reason, QuietRefusal)
        ):
            self.endpoint.statustext(
                mavlink.MAV_SEVERITY_CRITICAL
                if reason.startswith(("Arm:", "PreArm:"))
                else mavlink.MAV_SEVERITY_WARNING,
                reason,
            )

    def ack(self, msg: Any, address: Address, command: int, result: int) -> None:
        """COMMAND_ACK of ``command`` to the sender of ``msg``."""
        self.endpoint.send(
            self.endpoint.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()),
            address,
        )

    def on_set_mode(self, msg: Any, address: Address) -> None:
        """SET_MODE (the message): acknowledged with the message id as the command, as ArduPilot does."""
        if msg.target_system != self.endpoint.sysid:
            return
        if not msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED or msg.custom_mode not in ap.MODE_NAMES:
            log.warning("SET_MODE refused: base_mode %d custom_mode %d", msg.base_mode, msg.custom_mode)
            result = mavlink.MAV_RESULT_DENIED
        else:
            ok, reason = self.autopilot.set_mode(msg.custom_mode)
            if not ok:
                log.warning("SET_MODE %s refused: %s", ap.mode_name(msg.custom_mode), reason)
            result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED
        self.ack(msg, address, mavlink.MAVLINK_MSG_ID_SET_MODE, result)


def _name(command: int, unknown: Any) -> Any:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name if entry else unknown


def _outcome(ok_reason: tuple[bool, str]) -> Outcome:
    ok, reason = ok_reason
    return (mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED), reason


def _finite_int(value: float) -> bool:
    return math.isfinite(value) and value == int(value)


# ====================================================================== flight commands
def _arm(room: CommandProtocol, call: CommandCall) -> Outcome:
    p = call.p
    if p[0] == 1.0:
        return _outcome(room.autopilot.arm())
    if p[0] == 0.0:
        return _outcome(room.autopilot.disarm(force=p[1] == FORCE_DISARM_MAGIC))
    return mavlink.MAV_RESULT_DENIED, f"param1 must be 1 (arm) or 0 (disarm), got {p[0]!r}"


def _takeoff(room: CommandProtocol, call: CommandCall) -> Outcome:
    alt = call.p[6]
    if call.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
        alt = alt - room.autopilot.home_lla[2]
    if not math.isfinite(alt) or not 0.5 <= alt <= ap.MAX_TAKEOFF_ALT_M:
        return (
            mavlink.MAV_RESULT_DENIED,
            f"takeoff altitude (param7) {call.p[6]!r} outside 0.5..{ap.MAX_TAKEOFF_ALT_M:g} m",
        )
    return _outcome(room.autopilot.takeoff(alt))


def _land(room: CommandProtocol, call: CommandCall) -> Outcome:
    return _outcome(room.autopilot.set_mode(ap.LAND))


def _rtl(room: CommandProtocol, call: CommandCall) -> Outcome:
    return _outcome(room.autopilot.set_mode(ap.RTL))


def _do_set_mode(room: CommandProtocol, call: CommandCall) -> Outcome:
    base, custom = call.p[0], call.p[1]
    if not (math.isfinite(base) and math.isfinite(custom)):
        return mavlink.MAV_RESULT_DENIED, f"mode parameters must be finite, got {base!r}, {custom!r}"
    if not int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return mavlink.MAV_RESULT_DENIED, "param1 must have MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"
    if custom != int(custom) or int(custom) not in ap.MODE_NAMES:
        return mavlink.MAV_RESULT_DENIED, f"unknown ArduCopter mode {custom!r}"
    return _outcome(room.autopilot.set_mode(int(custom)))


def _mission_start(room: CommandProtocol, call: CommandCall) -> Outcome:
    first = 0.0 if math.isnan(call.p[0]) else call.p[0]
    count = len(room.autopilot.mission.items)
    if not _finite_int(first) or first < 0 or (count and first >= count):
        return (
            mavlink.MAV_RESULT_DENIED,
            f"first item (param1) {call.p[0]!r} is not an item of the mission (0..{count - 1})",
        )
    return _outcome(room.autopilot.mission_start(int(first)))


def _set_mission_current(room: CommandProtocol, call: CommandCall) -> Outcome:
    seq = call.p[0]
    if not _finite_int(seq) or not 0 <= seq < len(room.autopilot.mission.items):
        return mavlink.MAV_RESULT_DENIED, f"mission item {seq!r} does not exist"
    result = _outcome(room.autopilot.mission.set_current(int(seq)))
    room.endpoint.send(room.telemetry.msg_mission_current())
    return result


def _change_speed(room: CommandProtocol, call: CommandCall) -> Outcome:
    speed = call.p[1]
    if speed == -1.0:
        return _outcome(room.autopilot.navigation.change_speed(None))
    ok, reason = room.autopilot.navigation.change_speed(speed)
    return (mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_DENIED), reason


def _condition_yaw(room: CommandProtocol, call: CommandCall) -> Outcome:
    angle_deg, direction, relative = call.p[0], call.p[2], call.p[3]
    if not all(math.isfinite(v) for v in (angle_deg, direction, relative)) or not 0.0 <= angle_deg <= 360.0:
        return mavlink.MAV_RESULT_DENIED, f"angle (param1) {angle_deg!r} outside 0..360 degrees"
    yaw = math.radians(angle_deg)
    if relative:
        yaw = float(room.autopilot.euler_rad[2]) + (-yaw if direction < 0 else yaw)
    return _outcome(room.autopilot.set_yaw(yaw))


def _reposition(room: CommandProtocol, call: CommandCall) -> Outcome:
    """MAV_CMD_DO_REPOSITION (MAVSDK goto_location): a GUIDED position target."""
    p, frame = call.p, call.frame
    if frame is None:  # COMMAND_LONG: degrees, altitude AMSL
        lat, lon, frame = p[4], p[5], FRAME_GLOBAL
    else:
        lat, lon = p[4] * 1e-7, p[5] * 1e-7
    alt = p[6]
    if not all(math.isfinite(v) for v in (lat, lon, alt)) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return mavlink.MAV_RESULT_DENIED, f"position {p[4]!r}, {p[5]!r}, {p[6]!r} invalid"
    if frame not in GLOBAL_FRAMES:
        return mavlink.MAV_RESULT_DENIED, f"frame {frame} not supported (use a global frame)"
    a = room.autopilot
    if a.mode != ap.GUIDED:
        change_mode = math.isfinite(p[1]) and bool(int(p[1]) & mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)
        if not change_mode:
            return mavlink.MAV_RESULT_FAILED, "DO_REPOSITION needs GUIDED (or the change-mode flag)"
        ok, reason = a.set_mode(ap.GUIDED)
        if not ok:
            return mavlink.MAV_RESULT_FAILED, reason
    alt_amsl = alt if frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else a.home_lla[2] + alt
    yaw = None if not math.isfinite(p[3]) else math.radians(p[3])
    target = a.frame.to_ned(lat, lon, alt_amsl)
    return _outcome(a.set_guided_setpoint(Setpoint(pos_ned_m=target, yaw_rad=yaw)))


def _set_home(room: CommandProtocol, call: CommandCall) -> Outcome:
    """MAV_CMD_DO_SET_HOME: param1 1 (or lat = lon = 0) = here, else params 5-7.

    COMMAND_LONG: degrees and metres AMSL. COMMAND_INT: degE7, altitude in ``frame``
    (GLOBAL: AMSL, GLOBAL_RELATIVE_ALT: above the current home). Then GPS_GLOBAL_ORIGIN and
    HOME_POSITION go to every link, as ArduPilot sends them.
    """
    a, p, frame = room.autopilot, call.p, call.frame
    if not all(math.isfinite(v) for v in (p[0], p[4], p[5], p[6])):
        return mavlink.MAV_RESULT_DENIED, "DO_SET_HOME parameters must be finite"
    if frame is None:
        lat, lon, alt = p[4], p[5], p[6]
    else:
        lat, lon, alt = p[4] * 1e-7, p[5] * 1e-7, p[6]
        if frame in (FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT):
            alt = a.frames.home_alt_m + alt
        elif frame not in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
            return mavlink.MAV_RESULT_DENIED, f"DO_SET_HOME: frame {frame} not supported (use a global frame)"
    if p[0] == 1.0 or (p[4] == 0 and p[5] == 0):
        lat, lon, alt = a.position_lla()
    result = _outcome(a.set_home(lat, lon, alt))
    if result[0] == mavlink.MAV_RESULT_ACCEPTED:
        room.after_ack.append((room.telemetry.msg_gps_global_origin(), None))
        room.after_ack.append((room.telemetry.msg_home_position(), None))
    return result


def _aux_function(room: CommandProtocol, call: CommandCall) -> Outcome:
    """MAV_CMD_DO_AUX_FUNCTION: only 32 (MOTOR_INTERLOCK) is simulated; position 0/1/2."""
    function, position = call.p[0], call.p[1]
    if not (math.isfinite(function) and math.isfinite(position)) or position not in (0.0, 1.0, 2.0):
        return mavlink.MAV_RESULT_DENIED, f"switch position (param2) {position!r}: expected 0, 1 or 2"
    if function != rsc.AUX_FUNCTION_MOTOR_INTERLOCK:
        return mavlink.MAV_RESULT_FAILED, QuietRefusal(f"aux function {function:g} not simulated")
    return _outcome(room.autopilot.arming.set_interlock_switch(int(position)))


# ====================================================================== message requests
def _set_message_interval(room: CommandProtocol, call: CommandCall) -> Outcome:
    """SET_MESSAGE_INTERVAL for the requesting link (:meth:`StreamTable.set_message_interval`)."""
    p = call.p
    result, text = room.sender.streams.set_message_interval(call.address, p[0], p[1], room.sender.clock.time_s)
    if text:
        room.endpoint.statustext(mavlink.MAV_SEVERITY_INFO, text)  # ArduPilot's own words, sent by it too
    if result != mavlink.MAV_RESULT_ACCEPTED:
        return result, QuietRefusal(text or f"message {p[0]!r} interval {p[1]!r} us refused")
    return result, ""


def _get_message_interval(room: CommandProtocol, call: CommandCall) -> Outcome:
    msg_id = call.p[0]
    if not math.isfinite(msg_id):
        return mavlink.MAV_RESULT_DENIED, "message id must be finite"
    name = NAMES_BY_ID.get(int(msg_id))
    interval = 0 if name is None else room.sender.link(call.address).interval_us(name)
    # ArduPilot sends MESSAGE_INTERVAL before the COMMAND_ACK
    room.endpoint.send(room.endpoint.mav.message_interval_encode(int(msg_id), interval), call.address)
    return mavlink.MAV_RESULT_ACCEPTED, ""


def _request_message(room: CommandProtocol, call: CommandCall) -> Outcome:
    """REQUEST_MESSAGE: the message once, after the ACK, on the requesting link; unknown: FAILED."""
    msg_id = call.p[0]
    if not math.isfinite(msg_id):
        return mavlink.MAV_RESULT_DENIED, "message id (param1) must be finite"
    name = next((n for n, i in REQUESTABLE.items() if i == int(msg_id)), None)
    if name is None:
        if int(msg_id) not in room.refused_requests:
            room.refused_requests.add(int(msg_id))
            log.info("REQUEST_MESSAGE %d: not available", int(msg_id))
        return mavlink.MAV_RESULT_FAILED, QuietRefusal(f"message {int(msg_id)} not available")
    reply = room.telemetry.build(name, room.sender.link(call.address))
    if reply is not None:
        room.after_ack.append((reply, call.address))
    return mavlink.MAV_RESULT_ACCEPTED, ""


def _autopilot_capabilities(room: CommandProtocol, call: CommandCall) -> Outcome:
    room.after_ack.append((room.telemetry.msg_autopilot_version(), call.address))
    return mavlink.MAV_RESULT_ACCEPTED, ""


def _get_home(room: CommandProtocol, call: CommandCall) -> Outcome:
    room.after_ack.append((room.telemetry.msg_home_position(), call.address))
    return mavlink.MAV_RESULT_ACCEPTED, ""


COMMAND_HANDLERS: dict[int, Callable[[CommandProtocol, CommandCall], Outcome]] = {
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM: _arm,
    mavlink.MAV_CMD_NAV_TAKEOFF: _takeoff,
    mavlink.MAV_CMD_NAV_LAND: _land,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: _rtl,
    mavlink.MAV_CMD_DO_SET_MODE: _do_set_mode,
    mavlink.MAV_CMD_MISSION_START: _mission_start,
    mavlink.MAV_CMD_DO_SET_MISSION_CURRENT: _set_mission_current,
    mavlink.MAV_CMD_DO_CHANGE_SPEED: _change_speed,
    mavlink.MAV_CMD_DO_REPOSITION: _reposition,
    mavlink.MAV_CMD_CONDITION_YAW: _condition_yaw,
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: _set_message_interval,
    mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: _get_message_interval,
    mavlink.MAV_CMD_REQUEST_MESSAGE: _request_message,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _autopilot_capabilities,
    mavlink.MAV_CMD_GET_HOME_POSITION: _get_home,
    mavlink.MAV_CMD_DO_SET_HOME: _set_home,
    mavlink.MAV_CMD_DO_AUX_FUNCTION: _aux_function,
}
"""The one table of the commands the vehicle serves; any other MAV_CMD is answered UNSUPPORTED."""
