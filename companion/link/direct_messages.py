"""The link's raw traffic: messages in (``messages``), and messages out without waiting
(``send_message``, the GUIDED setpoint, STATUSTEXT to the ground stations).

Messages in come from the gate, which parses every frame anyway (``companion.link.gate``): the
types someone reads are handed to the loop in batches as field dicts, without MAVSDK's JSON
round trip. The 50 Hz SET_POSITION_TARGET_LOCAL_NED (position + velocity + acceleration + yaw,
type_mask from what is given) is encoded here and written by the gate
(``GateThread.send_message``); the rare sends (``send_message``, STATUSTEXT: broadcast, routed
by the autopilot to its other links) use ``MavlinkDirect.send_message`` of MAVSDK's synchronous
plugin (a ~20 us ctypes call). None of them blocks the event loop.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import time
from typing import AsyncIterator

from heli_common.mavlink_ids import enum_names

from companion.errors import LinkError
from companion.link.frames import LinkFrames
from companion.link.setpoint_frame import SETPOINT_MESSAGE, SetpointFrame, setpoint_values
from companion.link.transport import TAP_HANDOVER_PERIOD_S

log = logging.getLogger(__name__)

#: MAV_SEVERITY names by value (MAVLink common.xml: pymavlink's ``mavutil.mavlink.MAV_SEVERITY_*``).
MAV_SEVERITY_NAMES = tuple(enum_names("MAV_SEVERITY").values())
#: STATUSTEXT.text is char[50].
STATUSTEXT_MAX_CHARS = 50


def setpoint_fields(time_boot_ms: int, target_system: int, target_component: int,
                    pos_ned_m=None, vel_ned_m_s=None, acc_ned_m_s2=None, yaw_rad=None,
                    yaw_rate_rad_s=None) -> dict:
    """``setpoint_values`` by field name (MAVSDK's MavlinkDirect takes a JSON object)."""
    return dict(zip(SETPOINT_MESSAGE.ordered_fieldnames,
                    setpoint_values(time_boot_ms, target_system, target_component, pos_ned_m,
                                    vel_ned_m_s, acc_ned_m_s2, yaw_rad, yaw_rate_rad_s)))


class DirectMessages:
    """The MavlinkDirect traffic of a ``VehicleLink`` (a part of it: it uses the link's MAVSDK
    handles and frames, set by ``connect`` and ``set_planning_home``)."""

    target_system: int
    target_component: int
    frames: LinkFrames
    _mavsdk: object
    _system: object
    _direct_sync: object
    _t0: float
    _readers: dict
    _tap_batches: collections.deque       # batches of (type, fields) the gate read, for the loop
    _taps_streamer: object                # the setpoint stream that takes them (``batch_reads``)
    gate: object

    def _require_connected(self) -> None:
        if self._system is None or self._mavsdk is None:
            raise LinkError("the link is not connected (call connect() first)")

    def _from_vehicle(self, fields: dict) -> bool:
        return fields.get("_sysid") == self.target_system

    async def messages(self, name: str) -> AsyncIterator[dict]:
        """Raw MAVLink messages named ``name`` (e.g. ``"SERVO_OUTPUT_RAW"``) as field dicts.

        Each dict has the message fields plus ``"_sysid"``, ``"_compid"`` and ``"_t_s"``
        (monotonic arrival time). They come straight from the gate (``companion.link.gate``:
        the frames it admits, parsed once on its thread, ``tapped_fields``), not through MAVSDK;
        every reader of a type gets the same dict: read it, do not change it.
        """
        self._require_connected()
        queue: asyncio.Queue[dict] = asyncio.Queue()
        readers = self._readers.setdefault(name, set())
        readers.add(queue)
        self.gate.inbound.tapped.add(name)
        try:
            while True:
                yield await queue.get()
        finally:
            readers.discard(queue)
            if not readers and self.gate is not None:
                self.gate.inbound.tapped.discard(name)

    def batch_reads(self, streamer=None) -> None:
        """While the setpoint ``streamer`` runs (None: from now on, no longer), the gate reads
        the vehicle's datagrams in batches every ``TAP_HANDOVER_PERIOD_S``
        (``GateThread.batch_reads``) and the messages it read are taken at the stream's next
        tick (``SetpointStreamer.tick_hooks``) instead of waking the loop: the companion's about
        40 telemetry datagrams a second then cost the gate 10 wake-ups and the loop none."""
        if self.gate is None:
            return
        if self._taps_streamer is not None:
            self._taps_streamer.tick_hooks.remove(self._take_taps)
        self._taps_streamer = streamer
        if streamer is not None:
            streamer.tick_hooks.append(self._take_taps)
        self.gate.batch_reads(TAP_HANDOVER_PERIOD_S if streamer is not None else 0.0)
        self._take_taps()

    def _take_taps(self) -> None:
        """On the loop: the messages the gate read, to their readers (``messages``)."""
        batches = self._tap_batches
        while batches:
            for name, fields in batches.popleft():
                for queue in self._readers.get(name, ()):
                    queue.put_nowait(fields)

    def _tap_from_gate_thread(self, loop: asyncio.AbstractEventLoop):
        """The gate's ``on_tap``: keep each batch for the loop, and wake the loop for it unless
        the setpoint stream's next tick takes it (``batch_reads``)."""
        def on_tap(batch: list) -> None:
            self._tap_batches.append(batch)
            streamer = self._taps_streamer
            if streamer is None or not streamer.running:     # a stream that stopped takes none
                try:
                    loop.call_soon_threadsafe(self._take_taps)
                except RuntimeError:           # the loop is closed: the link is closing
                    pass
        return on_tap

    def send_message(self, name: str, fields: dict) -> None:
        """Send one MAVLink message ``name`` with ``fields`` now (non-blocking)."""
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        self._require_connected()
        self._direct_sync.send_message(MavlinkMessage(name, 0, 0, self.target_system,
                                                      self.target_component, json.dumps(fields)))

    def send_setpoint(self, pos_ned_m=None, vel_ned_m_s=None, acc_ned_m_s2=None, yaw_rad=None,
                      yaw_rate_rad_s=None) -> None:
        """Send one SET_POSITION_TARGET_LOCAL_NED now (non-blocking; call from the loop thread).

        ``None`` fields are masked out in ``type_mask``. Raises ``LinkError`` for non-finite
        values (nothing is sent then). ``pos_ned_m`` is about the planning home and is sent
        in the vehicle's local frame (``frames.to_origin``). It goes out through the gate
        directly (``GateThread.send_message``: encoded and signed here, from MAVSDK's address),
        through MAVSDK only before the gate knows that address.
        """
        self._require_connected()
        if pos_ned_m is not None:
            pos_ned_m = self.frames.to_origin_floats(pos_ned_m)
        values = setpoint_values(int((time.monotonic() - self._t0) * 1000.0), self.target_system,
                                 self.target_component, pos_ned_m, vel_ned_m_s, acc_ned_m_s2, yaw_rad,
                                 yaw_rate_rad_s)
        if self.gate is not None and self.gate.send_message(SetpointFrame(values)):
            return
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        fields = dict(zip(SETPOINT_MESSAGE.ordered_fieldnames, values))
        self._direct_sync.send_message(MavlinkMessage(SETPOINT_MESSAGE.msgname, 0, 0, self.target_system,
                                                      self.target_component, json.dumps(fields)))

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

        self._require_connected()
        name = severity.upper().removeprefix("MAV_SEVERITY_") if isinstance(severity, str) else None
        level = MAV_SEVERITY_NAMES.index(name) if name in MAV_SEVERITY_NAMES else severity
        if not (isinstance(level, int) and not isinstance(level, bool) and 0 <= level < len(MAV_SEVERITY_NAMES)):
            raise LinkError(f"severity: expected a MAV_SEVERITY value 0..7 or one of "
                            f"{', '.join(MAV_SEVERITY_NAMES)}, got {severity!r}")
        body = str(text).encode("ascii", "replace").decode("ascii")[:STATUSTEXT_MAX_CHARS]
        fields = {"severity": level, "text": body, "id": 0, "chunk_seq": 0}
        self._direct_sync.send_message(MavlinkMessage("STATUSTEXT", 0, 0, 0, 0, json.dumps(fields)))
        log.debug("STATUSTEXT %d %r sent", level, body)
