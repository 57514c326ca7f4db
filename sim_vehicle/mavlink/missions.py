"""Mission messages routed to the protocol of their list, as ArduPilot's ``GCS_MAVLINK::handle_mission_*``.

MISSION_COUNT, MISSION_ITEM(_INT), MISSION_REQUEST_LIST, MISSION_REQUEST(_INT) and MISSION_ACK go
to the :class:`~sim_vehicle.mavlink.mission_protocol.MissionItemProtocol` of their
``mission_type``; a type the vehicle does not keep is refused (:class:`UnsupportedList`).
MISSION_CLEAR_ALL clears one list or all three; MISSION_SET_CURRENT picks the mission item to fly.
"""

from __future__ import annotations

import logging
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle.autopilot import Autopilot
from sim_vehicle.mavlink.endpoint import Address, Endpoint
from sim_vehicle.mavlink.mission_protocol import (
    MissionItemProtocol,
    MissionItemProtocolFence,
    MissionItemProtocolRally,
    MissionItemProtocolWaypoints,
    mission_type_of,
    refuse_count,
    refuse_item,
    refuse_request,
    send_ack,
)
from sim_vehicle.mavlink.mission_wire import from_mission_item, from_mission_item_int
from sim_vehicle.mission_store import MISSION_TYPE_ALL, MissionItem, MissionResult, MissionStore
from sim_vehicle.telemetry import Telemetry

log = logging.getLogger(__name__)


class UnsupportedList:
    """A list type the vehicle does not keep (MAV_MISSION_TYPE other than mission, fence, rally): refused."""

    def __init__(self, endpoint: Endpoint) -> None:
        self.endpoint = endpoint

    def on_count(self, msg: Any, address: Address) -> None:
        refuse_count(self.endpoint, msg, address, MissionResult.UNSUPPORTED, mission_type_of(msg))

    def on_item(self, msg: Any, address: Address, item: MissionItem, legacy: bool) -> None:
        refuse_item(self.endpoint, msg, address, item)

    def on_request_list(self, msg: Any, address: Address) -> None:
        send_ack(self.endpoint, msg, address, MissionResult.UNSUPPORTED, mission_type_of(msg))

    def on_request(self, msg: Any, address: Address, legacy: bool) -> None:
        refuse_request(self.endpoint, msg, address, 0, mission_type_of(msg))

    def on_ack(self, msg: Any, address: Address) -> None:
        """Nothing to cancel: there is never an upload of such a list."""


class MissionProtocols:
    """The mission messages routed to the protocol of their list (:class:`UnsupportedList` for another type).

    Parameters are those of :class:`MissionItemProtocol`.
    """

    def __init__(self, endpoint: Endpoint, store: MissionStore, autopilot: Autopilot, telemetry: Telemetry) -> None:
        self.endpoint = endpoint
        self.store = store
        self.autopilot = autopilot
        self.telemetry = telemetry
        self.lists: dict[int, MissionItemProtocol] = {
            cls.mission_type: cls(endpoint, store, autopilot, telemetry)
            for cls in (MissionItemProtocolWaypoints, MissionItemProtocolFence, MissionItemProtocolRally)
        }
        self._unsupported = UnsupportedList(endpoint)

    def protocol(self, mission_type: int) -> MissionItemProtocol | UnsupportedList:
        """The protocol of list ``mission_type``."""
        return self.lists.get(mission_type, self._unsupported)

    def on_mission_count(self, msg: Any, address: Address) -> None:
        self.protocol(mission_type_of(msg)).on_count(msg, address)

    def on_mission_item_int(self, msg: Any, address: Address) -> None:
        item = from_mission_item_int(msg, mission_type_of(msg))
        self.protocol(item.mission_type).on_item(msg, address, item, legacy=False)

    def on_mission_item(self, msg: Any, address: Address) -> None:
        item = from_mission_item(msg, mission_type_of(msg))
        self.protocol(item.mission_type).on_item(msg, address, item, legacy=True)

    def on_mission_request_list(self, msg: Any, address: Address) -> None:
        self.protocol(mission_type_of(msg)).on_request_list(msg, address)

    def on_mission_request_int(self, msg: Any, address: Address) -> None:
        self.protocol(mission_type_of(msg)).on_request(msg, address, legacy=False)

    def on_mission_request(self, msg: Any, address: Address) -> None:
        self.protocol(mission_type_of(msg)).on_request(msg, address, legacy=True)

    def on_mission_ack(self, msg: Any, address: Address) -> None:
        self.protocol(mission_type_of(msg)).on_ack(msg, address)

    def on_mission_clear_all(self, msg: Any, address: Address) -> None:
        """MISSION_CLEAR_ALL of one list, or of all three (MAV_MISSION_TYPE_ALL)."""
        mission_type = mission_type_of(msg)
        result = self.store.clear(mission_type)
        cleared = (
            self.lists.values()
            if mission_type == MISSION_TYPE_ALL
            else [self.lists[mission_type]]
            if mission_type in self.lists
            else []
        )
        for protocol in cleared:
            protocol.cleared(result == MissionResult.ACCEPTED)
        send_ack(self.endpoint, msg, address, result, mission_type)

    def on_mission_set_current(self, msg: Any, address: Address) -> None:
        """MISSION_SET_CURRENT: the mission item to fly next; MISSION_CURRENT to every link either way."""
        ok, reason = self.autopilot.mission.set_current(int(msg.seq))
        if not ok:
            log.warning("MISSION_SET_CURRENT %d refused: %s", msg.seq, reason)
            self.endpoint.statustext(mavlink.MAV_SEVERITY_WARNING, f"set current refused: {reason}")
        self.endpoint.send(self.telemetry.msg_mission_current())

    def update(self) -> None:
        """Housekeeping: uploads idle too long are cancelled, silent uploaders asked again."""
        now = self.endpoint.wall_s()
        for upload in self.store.expire_uploads(now):
            self.lists[upload.mission_type].upload_expired(upload)
        for protocol in self.lists.values():
            protocol.retry(now)
