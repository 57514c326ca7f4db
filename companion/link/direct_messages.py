"""Messages out without waiting: ``send_message``, the GUIDED setpoint, and STATUSTEXT to the
ground stations (``VehicleLink.direct``).

The 50 Hz SET_POSITION_TARGET_LOCAL_NED (position + velocity + acceleration + yaw, type_mask
from what is given) is encoded here and written by the gate (``GateThread.send_message``); the
rare sends (``send_message``, STATUSTEXT: broadcast, routed by the autopilot to its other links)
use ``MavlinkDirect.send_message`` of MAVSDK's synchronous plugin (a ~20 us ctypes call). None of
them blocks the event loop. Messages in are ``companion.link.message_tap``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable

from companion.errors import LinkError
from companion.link.frames import LinkFrames
from companion.link.session import LinkSession
from companion.link.setpoint_frame import SETPOINT_MESSAGE, SetpointFrame, setpoint_values
from heli_common.mavlink_ids import enum_names

log = logging.getLogger(__name__)

#: MAV_SEVERITY names by value (MAVLink common.xml: pymavlink's ``mavutil.mavlink.MAV_SEVERITY_*``).
MAV_SEVERITY_NAMES = tuple(enum_names("MAV_SEVERITY").values())
#: STATUSTEXT.text is char[50].
STATUSTEXT_MAX_CHARS = 50


def setpoint_fields(
    time_boot_ms: int,
    target_system: int,
    target_component: int,
    pos_ned_m=None,
    vel_ned_m_s=None,
    acc_ned_m_s2=None,
    yaw_rad=None,
    yaw_rate_rad_s=None,
) -> dict:
    """``setpoint_values`` by field name (MAVSDK's MavlinkDirect takes a JSON object)."""
    return dict(
        zip(
            SETPOINT_MESSAGE.ordered_fieldnames,
            setpoint_values(
                time_boot_ms,
                target_system,
                target_component,
                pos_ned_m,
                vel_ned_m_s,
                acc_ned_m_s2,
                yaw_rad,
                yaw_rate_rad_s,
            ),
        )
    )


class DirectMessages:
    """The link's sends (``VehicleLink.direct``).

    Parameters
    ----------
    session : LinkSession
        The connection: its gate, MavlinkDirect plugin and target.
    frames : callable() -> LinkFrames
        The link's current frames (setpoint positions are about the planning home).
    """

    def __init__(self, session: LinkSession, frames: Callable[[], LinkFrames]) -> None:
        self._session = session
        self._frames = frames

    def send_message(self, name: str, fields: dict) -> None:
        """Send one MAVLink message ``name`` with ``fields`` now (non-blocking)."""
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        session = self._session
        session.require_connected()
        session.direct.send_message(
            MavlinkMessage(name, 0, 0, session.target_system, session.target_component, json.dumps(fields))
        )

    def send_setpoint(
        self, pos_ned_m=None, vel_ned_m_s=None, acc_ned_m_s2=None, yaw_rad=None, yaw_rate_rad_s=None
    ) -> None:
        """Send one SET_POSITION_TARGET_LOCAL_NED now (non-blocking; call from the loop thread).

        ``None`` fields are masked out in ``type_mask``. Raises ``LinkError`` for non-finite
        values (nothing is sent then). ``pos_ned_m`` is about the planning home and is sent
        in the vehicle's local frame (``frames.to_origin``). It goes out through the gate
        directly (``GateThread.send_message``: encoded and signed here, from MAVSDK's address),
        through MAVSDK only before the gate knows that address.
        """
        session = self._session
        session.require_connected()
        if pos_ned_m is not None:
            pos_ned_m = self._frames().to_origin_floats(pos_ned_m)
        values = setpoint_values(
            int((time.monotonic() - session.t0) * 1000.0),
            session.target_system,
            session.target_component,
            pos_ned_m,
            vel_ned_m_s,
            acc_ned_m_s2,
            yaw_rad,
            yaw_rate_rad_s,
        )
        if session.gate is not None and session.gate.send_message(SetpointFrame(values)):
            return
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        fields = dict(zip(SETPOINT_MESSAGE.ordered_fieldnames, values))
        session.direct.send_message(
            MavlinkMessage(
                SETPOINT_MESSAGE.msgname, 0, 0, session.target_system, session.target_component, json.dumps(fields)
            )
        )

    def send_statustext(self, text: str, severity: int | str = "NOTICE") -> None:
        """Send one STATUSTEXT to the ground stations (non-blocking; call from the loop thread).

        STATUSTEXT has no target: the autopilot forwards it to its other links (ArduPilot's
        MAVLink routing; ``sim-vehicle`` does the same), so QGroundControl and MAVProxy show it.

        Parameters
        ----------
        text : str
            Cut to ``STATUSTEXT_MAX_CHARS`` (50) characters; non-ASCII characters become ``?``.
        severity : int or str
            A MAV_SEVERITY value (pymavlink's ``mavutil.mavlink.MAV_SEVERITY_NOTICE`` ...) or its
            name with or without the prefix (``"NOTICE"``, ``"MAV_SEVERITY_WARNING"``).

        Raises
        ------
        LinkError
            Not connected, or an unknown severity (nothing is sent then).
        """
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        self._session.require_connected()
        name = severity.upper().removeprefix("MAV_SEVERITY_") if isinstance(severity, str) else None
        level = MAV_SEVERITY_NAMES.index(name) if name in MAV_SEVERITY_NAMES else severity
        if not (isinstance(level, int) and not isinstance(level, bool) and 0 <= level < len(MAV_SEVERITY_NAMES)):
            raise LinkError(
                f"severity: expected a MAV_SEVERITY value 0..7 or one of "
                f"{', '.join(MAV_SEVERITY_NAMES)}, got {severity!r}"
            )
        body = str(text).encode("ascii", "replace").decode("ascii")[:STATUSTEXT_MAX_CHARS]
        fields = {"severity": level, "text": body, "id": 0, "chunk_seq": 0}
        self._session.direct.send_message(MavlinkMessage("STATUSTEXT", 0, 0, 0, 0, json.dumps(fields)))
        log.debug("STATUSTEXT %d %r sent", level, body)
