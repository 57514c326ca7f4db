"""Telemetry streams per link: HEARTBEAT at 1 Hz, the streams each link asked for, home and origin.

Nothing but HEARTBEAT is sent unasked. A link gets a message only as it requested it with
SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM or the ``MAVn_*`` parameters (the rates are kept per
link by :class:`sim_vehicle.streams.StreamTable`; the messages are built by
:class:`sim_vehicle.telemetry.Telemetry`), as ArduPilot's streams are per link.
"""

from __future__ import annotations

import logging
from typing import Any

from sim_vehicle.clock import SimClock
from sim_vehicle.config import replace_path
from sim_vehicle.mavlink.endpoint import Address, Endpoint
from sim_vehicle.params import ParameterTable
from sim_vehicle.streams import LinkStreams, StreamTable
from sim_vehicle.telemetry import Telemetry

log = logging.getLogger(__name__)

MAX_STREAM_WALL_HZ = 50.0
"""A stream is never sent faster than this in wall-clock time, whatever the speed-up."""


class StreamSender:
    """Sends HEARTBEAT, home and origin to every link and each link's due streams to that link.

    Parameters
    ----------
    endpoint : Endpoint
        Where messages go.
    telemetry : Telemetry
        Builds the messages.
    streams : StreamTable
        Each link's requested rates.
    clock : SimClock
        Simulated time (stream periods are in simulated seconds).
    params : ParameterTable
        Takes the ``MAVn_*`` rates that REQUEST_DATA_STREAM sets on a numbered link.
    """

    def __init__(
        self, endpoint: Endpoint, telemetry: Telemetry, streams: StreamTable, clock: SimClock, params: ParameterTable
    ) -> None:
        self.endpoint = endpoint
        self.telemetry = telemetry
        self.streams = streams
        self.clock = clock
        self.params = params

    def link(self, address: Address) -> LinkStreams:
        """The streams of the link at ``address`` (created on first use)."""
        return self.streams.link(address, self.clock.time_s)

    def send_heartbeat(self) -> None:
        self.endpoint.send(self.telemetry.msg_heartbeat())

    def send_home_and_origin(self) -> None:
        """GPS_GLOBAL_ORIGIN then HOME_POSITION to every link (ArduPilot does so whenever home is set)."""
        self.endpoint.send(self.telemetry.msg_gps_global_origin())
        self.endpoint.send(self.telemetry.msg_home_position())

    def send_due(self) -> None:
        """Each link's due messages, to that link only."""
        now = self.clock.time_s
        min_period = self.clock.speedup / MAX_STREAM_WALL_HZ
        for address in self.endpoint.destinations():
            link = self.streams.link(address, now)
            for name in link.due(now, min_period):
                msg = self._build(name, link)
                if msg is not None:
                    self.endpoint.send(msg, address)

    def _build(self, name: str, link: LinkStreams) -> Any | None:
        try:
            return self.telemetry.build(name, link)
        except Exception as exc:  # e.g. a value out of the field's range: skip it, keep flying
            n = self.endpoint.throttle.count(f"stream:{name}")
            if n <= 3 or n % 1000 == 0:
                log.error("cannot send %s: %s: %s", name, type(exc).__name__, exc)
            return None

    def on_request_data_stream(self, msg: Any, address: Address) -> None:
        """REQUEST_DATA_STREAM for the requesting link; a numbered link's MAVn_ parameter follows."""
        changed = self.streams.request_data_stream(
            address, msg.req_stream_id, msg.req_message_rate, msg.start_stop, self.clock.time_s
        )
        n = self.streams.number(address)
        if n is None or n > 3 or not changed:
            return
        settings = self.params.settings
        for group, hz in changed:
            settings = replace_path(settings, f"link.mav{n}.{group.lower()}", min(int(hz), 1000))
        self.params.settings = settings
