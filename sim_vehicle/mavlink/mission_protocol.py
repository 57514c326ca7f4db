"""The MAVLink mission protocol for the mission, fence and rally lists, one protocol object per list.

As ArduPilot's ``MissionItemProtocol`` with its ``_Waypoints``, ``_Fence`` and ``_Rally``
subclasses: the base class runs the upload (MISSION_COUNT, then MISSION_REQUEST_INT for each
item in order, re-requested after :data:`REQUEST_RETRY_S` of silence, MISSION_ACK at the end),
the download (MISSION_REQUEST_LIST, MISSION_REQUEST_INT), clearing and cancelling; a subclass
only says what its list is and where a new list goes. The lists themselves and their atomic
replacement are kept by :class:`sim_vehicle.mission_store.MissionStore`. A legacy sender
(MISSION_ITEM, MISSION_REQUEST) is answered in the legacy messages.
"""

from __future__ import annotations

import abc
import dataclasses
import logging
from typing import Any

from sim_vehicle.autopilot import Autopilot
from sim_vehicle.mavlink.endpoint import Address, Endpoint
from sim_vehicle.mavlink.mission_wire import encode_item
from sim_vehicle.mission_store import (
    MISSION_TYPE_FENCE,
    MISSION_TYPE_MISSION,
    MISSION_TYPE_NAMES,
    MISSION_TYPE_RALLY,
    MissionItem,
    MissionResult,
    MissionStore,
    Upload,
)
from sim_vehicle.telemetry import Telemetry

log = logging.getLogger(__name__)

REQUEST_RETRY_S = 1.0
"""An item not received this long (wall-clock seconds) after its request is requested again."""
LOST_ACK_WINDOW_S = 5.0
"""The last item of a completed upload sent again this soon means our MISSION_ACK was lost: ACK again."""


@dataclasses.dataclass
class _UploadPeer:
    """The sender of the upload in progress and what we last asked it for."""

    address: Address
    sysid: int
    compid: int
    legacy: bool
    last_request_wall_s: float = 0.0
    requested_seq: int = 0


def mission_type_of(msg: Any) -> int:
    """The list a mission message is about (messages without the field are about the mission)."""
    return int(getattr(msg, "mission_type", MISSION_TYPE_MISSION))


def send_ack(endpoint: Endpoint, msg: Any, address: Address, result: int, mission_type: int) -> None:
    """MISSION_ACK with ``result`` to the sender of ``msg``."""
    endpoint.send(
        endpoint.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), int(result), mission_type), address
    )


def refuse_count(endpoint: Endpoint, msg: Any, address: Address, result: MissionResult, mission_type: int) -> None:
    log.warning("MISSION_COUNT %d (type %d) refused: %s", msg.count, mission_type, result.name)
    send_ack(endpoint, msg, address, result, mission_type)


def refuse_item(endpoint: Endpoint, msg: Any, address: Address, item: MissionItem) -> None:
    log.warning(
        "mission item %d (type %d) from %s:%d outside any upload: refused", item.seq, item.mission_type, *address
    )
    send_ack(endpoint, msg, address, MissionResult.DENIED, item.mission_type)


def refuse_request(endpoint: Endpoint, msg: Any, address: Address, count: int, mission_type: int) -> None:
    log.warning("MISSION_REQUEST for item %d of %d (type %d): refused", msg.seq, count, mission_type)
    send_ack(endpoint, msg, address, MissionResult.INVALID_SEQUENCE, mission_type)


class MissionItemProtocol(abc.ABC):
    """Upload, download, clearing and cancelling of one list.

    Parameters
    ----------
    endpoint : Endpoint
        Where replies go.
    store : MissionStore
        Keeps the list and the upload in progress.
    autopilot : Autopilot
        Takes a new list (:meth:`apply`).
    telemetry : Telemetry
        Builds MISSION_CURRENT.
    """

    mission_type: int
    """The MAV_MISSION_TYPE of the list."""

    def __init__(self, endpoint: Endpoint, store: MissionStore, autopilot: Autopilot, telemetry: Telemetry) -> None:
        self.endpoint = endpoint
        self.store = store
        self.autopilot = autopilot
        self.telemetry = telemetry
        self._peer: _UploadPeer | None = None
        self._completed: tuple[int, float] | None = None
        """(item count, wall time) of the last completed upload."""

    @abc.abstractmethod
    def apply(self) -> None:
        """Hand the stored list to the vehicle (after an upload or a clear)."""

    # ---------------------------------------------------------------- upload
    def on_count(self, msg: Any, address: Address) -> None:
        """MISSION_COUNT: start an upload (0 items: the list is cleared at once) and request item 0."""
        result = self.store.begin_upload(self.mission_type, int(msg.count), self.endpoint.wall_s())
        if result != MissionResult.ACCEPTED:
            refuse_count(self.endpoint, msg, address, result, self.mission_type)
            return
        log.info("%s upload of %d items from %s:%d", MISSION_TYPE_NAMES[self.mission_type], msg.count, *address)
        if msg.count == 0:
            self.apply()
            send_ack(self.endpoint, msg, address, MissionResult.ACCEPTED, self.mission_type)
            return
        self._peer = _UploadPeer(address, msg.get_srcSystem(), msg.get_srcComponent(), legacy=False)
        self._request_item(0)

    def on_item(self, msg: Any, address: Address, item: MissionItem, legacy: bool) -> None:
        """MISSION_ITEM_INT (or legacy MISSION_ITEM): store it; request the next, or ACK the complete list."""
        peer = self._peer
        if peer is not None and legacy and peer.address == address:
            peer.legacy = True  # answer a legacy sender with legacy requests
        if peer is None:
            self._item_outside_upload(msg, address, item)
            return
        now = self.endpoint.wall_s()
        result, complete = self.store.receive_item(item, now)
        if result == MissionResult.INVALID_SEQUENCE:
            send_ack(self.endpoint, msg, address, result, self.mission_type)
            self._request_item(self.store.upload_in_progress(self.mission_type).next_seq)
        elif result != MissionResult.ACCEPTED:
            self._peer = None
            send_ack(self.endpoint, msg, address, result, self.mission_type)
        elif complete:
            self._peer = None
            self._completed = (len(self.store.items(self.mission_type)), now)
            self.apply()
            send_ack(self.endpoint, msg, address, MissionResult.ACCEPTED, self.mission_type)
        else:
            upload = self.store.upload_in_progress(self.mission_type)
            if upload is not None and upload.next_seq != peer.requested_seq:
                self._request_item(upload.next_seq)

    def _item_outside_upload(self, msg: Any, address: Address, item: MissionItem) -> None:
        done = self._completed
        if done is not None and item.seq == done[0] - 1 and self.endpoint.wall_s() - done[1] < LOST_ACK_WINDOW_S:
            send_ack(self.endpoint, msg, address, MissionResult.ACCEPTED, self.mission_type)  # our ACK was lost
            return
        refuse_item(self.endpoint, msg, address, item)

    def _request_item(self, seq: int) -> None:
        peer = self._peer
        mav = self.endpoint.mav
        if peer.legacy:
            out = mav.mission_request_encode(peer.sysid, peer.compid, seq, self.mission_type)
        else:
            out = mav.mission_request_int_encode(peer.sysid, peer.compid, seq, self.mission_type)
        peer.requested_seq = seq
        peer.last_request_wall_s = self.endpoint.wall_s()
        self.endpoint.send(out, peer.address)

    # ---------------------------------------------------------------- download
    def on_request_list(self, msg: Any, address: Address) -> None:
        """MISSION_REQUEST_LIST: MISSION_COUNT of the stored list."""
        self.endpoint.send(
            self.endpoint.mav.mission_count_encode(
                msg.get_srcSystem(), msg.get_srcComponent(), len(self.store.items(self.mission_type)), self.mission_type
            ),
            address,
        )

    def on_request(self, msg: Any, address: Address, legacy: bool) -> None:
        """MISSION_REQUEST_INT (or legacy MISSION_REQUEST): the stored item, exactly as it was uploaded."""
        items = self.store.items(self.mission_type)
        if not 0 <= msg.seq < len(items):
            refuse_request(self.endpoint, msg, address, len(items), self.mission_type)
            return
        self.endpoint.send(
            encode_item(
                self.endpoint.mav,
                items[msg.seq],
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                self.mission_type,
                legacy,
            ),
            address,
        )

    # ---------------------------------------------------------------- clearing, cancelling, time-outs
    def cleared(self, accepted: bool) -> None:
        """After MISSION_CLEAR_ALL of this list: the upload is forgotten; an accepted clear goes to the vehicle."""
        self._peer = None
        if accepted:
            self.apply()

    def on_ack(self, msg: Any, address: Address) -> None:
        """MISSION_ACK other than ACCEPTED from the uploader: the upload is cancelled."""
        peer = self._peer
        if peer is not None and peer.address == address and msg.type != MissionResult.ACCEPTED:
            self.store.cancel_upload(self.mission_type, f"sender sent MISSION_ACK {msg.type}")
            self._peer = None

    def upload_expired(self, upload: Upload) -> None:
        """The store gave up the upload: tell the uploader (OPERATION_CANCELLED)."""
        peer, self._peer = self._peer, None
        if peer is not None:
            self.endpoint.send(
                self.endpoint.mav.mission_ack_encode(
                    peer.sysid, peer.compid, MissionResult.OPERATION_CANCELLED, upload.mission_type
                ),
                peer.address,
            )

    def retry(self, now_s: float) -> None:
        """Request the awaited item again when the uploader has been silent for :data:`REQUEST_RETRY_S`."""
        if self._peer is not None and now_s - self._peer.last_request_wall_s > REQUEST_RETRY_S:
            self._request_item(self._peer.requested_seq)


class MissionItemProtocolWaypoints(MissionItemProtocol):
    """The mission: a new list goes to the autopilot, and MISSION_CURRENT to every link."""

    mission_type = MISSION_TYPE_MISSION

    def apply(self) -> None:
        self.autopilot.mission.set_items(self.store.items(self.mission_type))
        self.endpoint.send(self.telemetry.msg_mission_current())


class MissionItemProtocolFence(MissionItemProtocol):
    """The geofence: inclusion and exclusion polygons and circles."""

    mission_type = MISSION_TYPE_FENCE

    def apply(self) -> None:
        self.autopilot.fence.set_items(self.store.items(self.mission_type))


class MissionItemProtocolRally(MissionItemProtocol):
    """The rally points RTL may go to."""

    mission_type = MISSION_TYPE_RALLY

    def apply(self) -> None:
        self.autopilot.mission.set_rally(self.store.items(self.mission_type))
