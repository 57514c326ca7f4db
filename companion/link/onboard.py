"""The companion as a component of its vehicle's MAVLink system: (vehicle sysid, 191).

A ground station sees an onboard computer (HEARTBEAT of type ONBOARD_CONTROLLER, component
``MAV_COMP_ID_ONBOARD_COMPUTER``) and may command it: a COMMAND_LONG / COMMAND_INT addressed to
that component reaches ``OnboardComponent.handle``, which asks the owner's ``on_command`` for a
MAV_RESULT and answers with a COMMAND_ACK addressed back to the sender. STATUSTEXT goes out
from the same address. This is separate from MAVSDK's own address (which talks to the
autopilot); the gate (``companion.link.transport``) sends these frames and hands it the frames
addressed to it. Pure: messages in, frames out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["OnboardCommand", "OnboardComponent", "COMPONENT_ID"]

COMPONENT_ID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
COMMAND_TYPES = ("COMMAND_LONG", "COMMAND_INT")


@dataclasses.dataclass(frozen=True)
class OnboardCommand:
    """A command addressed to the companion: ``command`` (MAV_CMD), its seven params, the sender."""

    command: int
    params: tuple[float, ...]
    sender_system: int
    sender_component: int


class OnboardComponent:
    """Heartbeats, status texts and command answers of the companion component.

    Parameters
    ----------
    system_id : int or None
        The vehicle's system id (the companion belongs to that system); None until the link
        knows it (``set_system``): meanwhile nothing is addressed to us and no HEARTBEAT goes out.
    on_command : callable
        ``on_command(OnboardCommand) -> int``: the MAV_RESULT to answer. Called on the gate's
        thread; hand the work to the event loop and answer quickly (``MAV_RESULT_ACCEPTED``,
        ``..._TEMPORARILY_REJECTED``, ``..._UNSUPPORTED`` ...).
    """

    def __init__(self, system_id: int | None, on_command: Callable[[OnboardCommand], int]) -> None:
        self.on_command = on_command
        self.active = False  # MAV_STATE_ACTIVE while a flight runs
        self.system_id: int | None = None
        self.set_system(system_id)

    def set_system(self, system_id: int | None) -> None:
        """Belong to vehicle ``system_id`` (the link calls it once it has heard the autopilot)."""
        self.system_id = system_id
        self._mav = mavlink.MAVLink(None, srcSystem=system_id or 0, srcComponent=COMPONENT_ID)

    def addressed_to_us(self, msg) -> bool:
        """Is ``msg`` a command for this component (not a broadcast)?"""
        return (
            msg.get_type() in COMMAND_TYPES
            and msg.target_system == self.system_id
            and msg.target_component == COMPONENT_ID
        )

    def handle(self, msg) -> bytes:
        """Answer a command addressed to us (``addressed_to_us``): the COMMAND_ACK frame."""
        if msg.get_type() == "COMMAND_LONG":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        else:
            params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        command = OnboardCommand(msg.command, params, msg.get_srcSystem(), msg.get_srcComponent())
        try:
            result = int(self.on_command(command))
        except Exception:  # never leave a ground station waiting
            result = mavlink.MAV_RESULT_FAILED
        ack = self._mav.command_ack_encode(msg.command, result, 0, 0, command.sender_system, command.sender_component)
        return bytes(ack.pack(self._mav))

    def heartbeat(self) -> bytes | None:
        """Our HEARTBEAT: an onboard controller, standby or active (None before ``set_system``)."""
        if self.system_id is None:
            return None
        state = mavlink.MAV_STATE_ACTIVE if self.active else mavlink.MAV_STATE_STANDBY
        hb = self._mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, state)
        return bytes(hb.pack(self._mav))

    def statustext(self, severity: int, text: str) -> bytes:
        """A STATUSTEXT from us (cut to the 50 characters of one message)."""
        msg = self._mav.statustext_encode(severity, text.encode("utf-8", "replace")[:50])
        return bytes(msg.pack(self._mav))
