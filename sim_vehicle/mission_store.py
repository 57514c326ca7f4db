"""Mission, fence and rally lists of the SITL vehicle, each replaced atomically.

Implements the storage side of the MAVLink mission protocol
(https://mavlink.io/en/services/mission.html): an upload starts with ``MISSION_COUNT``, the
vehicle requests items ``0 .. count-1`` in order, and the new list replaces the stored one
*only* when the last item has arrived. An upload that fails (wrong sequence, bad item), is
cancelled, replaced by another upload or times out leaves the previous list intact, so a
vehicle never flies half a mission.

Items are kept as the fields of ``MISSION_ITEM_INT`` (latitude and longitude as integers in
1e-7 degrees), so a download returns exactly what was uploaded. Pure bookkeeping: no I/O.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
import math

from heli_common.mavlink_ids import enum_names, mavlink
from heli_common.mission_item import MissionItemInt

log = logging.getLogger(__name__)

MISSION_TYPE_MISSION = mavlink.MAV_MISSION_TYPE_MISSION
MISSION_TYPE_FENCE = mavlink.MAV_MISSION_TYPE_FENCE
MISSION_TYPE_RALLY = mavlink.MAV_MISSION_TYPE_RALLY
MISSION_TYPE_ALL = mavlink.MAV_MISSION_TYPE_ALL
MISSION_TYPES = (MISSION_TYPE_MISSION, MISSION_TYPE_FENCE, MISSION_TYPE_RALLY)
MISSION_TYPE_NAMES = {MISSION_TYPE_MISSION: "mission", MISSION_TYPE_FENCE: "fence", MISSION_TYPE_RALLY: "rally"}

MAX_ITEMS = 700


#: ``MAV_MISSION_RESULT`` values (names and numbers from pymavlink's generated enum).
MissionResult = enum.IntEnum(
    "MissionResult", {name: value for value, name in enum_names("MAV_MISSION_RESULT", "MAV_MISSION_").items()}
)


# frames the vehicle can fly (MAV_FRAME numbers)
FRAME_GLOBAL = mavlink.MAV_FRAME_GLOBAL
FRAME_LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
FRAME_MISSION = mavlink.MAV_FRAME_MISSION
FRAME_GLOBAL_RELATIVE_ALT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
FRAME_GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT
FRAME_GLOBAL_RELATIVE_ALT_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
FRAME_GLOBAL_TERRAIN_ALT = mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT
FRAME_GLOBAL_TERRAIN_ALT_INT = mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT
SUPPORTED_FRAMES = frozenset(
    {
        FRAME_GLOBAL,
        FRAME_LOCAL_NED,
        FRAME_MISSION,
        FRAME_GLOBAL_RELATIVE_ALT,
        FRAME_GLOBAL_INT,
        FRAME_GLOBAL_RELATIVE_ALT_INT,
        FRAME_GLOBAL_TERRAIN_ALT,
        FRAME_GLOBAL_TERRAIN_ALT_INT,
    }
)
#: the frames whose x, y are latitude and longitude (degE7 in MISSION_ITEM_INT, degrees in MISSION_ITEM)
GLOBAL_FRAMES = frozenset(
    {
        FRAME_GLOBAL,
        FRAME_GLOBAL_INT,
        FRAME_GLOBAL_RELATIVE_ALT,
        FRAME_GLOBAL_RELATIVE_ALT_INT,
        FRAME_GLOBAL_TERRAIN_ALT,
        FRAME_GLOBAL_TERRAIN_ALT_INT,
    }
)


#: one stored item: the project's one ``MISSION_ITEM_INT`` record
MissionItem = MissionItemInt


def validate_item(item: MissionItem) -> MissionResult:
    """Check one item; returns ``ACCEPTED`` or the ``MAV_MISSION_RESULT`` that names the fault."""
    if item.frame not in SUPPORTED_FRAMES:
        return MissionResult.UNSUPPORTED_FRAME
    for index, value in enumerate((item.param1, item.param2, item.param3, item.param4)):
        if math.isinf(value):  # NaN is allowed by the standard ("unused"), infinity is not
            return MissionResult(MissionResult.INVALID_PARAM1 + index)
    if not math.isfinite(item.z):
        return MissionResult.INVALID_PARAM7
    if item.frame in GLOBAL_FRAMES:
        if not (item.x == 0 and item.y == 0):  # (0, 0) = "no position" (e.g. DO commands, RTL)
            if abs(item.x) > 900_000_000:
                return MissionResult.INVALID_PARAM5_X
            if abs(item.y) > 1_800_000_000:
                return MissionResult.INVALID_PARAM6_Y
    return MissionResult.ACCEPTED


@dataclasses.dataclass
class Upload:
    """An upload in progress for one mission type."""

    mission_type: int
    count: int
    started_s: float
    last_activity_s: float
    items: list[MissionItem] = dataclasses.field(default_factory=list)
    retries: int = 0

    @property
    def next_seq(self) -> int:
        """The sequence number the vehicle waits for."""
        return len(self.items)


class MissionStore:
    """The three lists (mission, fence, rally) and at most one upload per list.

    Parameters
    ----------
    upload_timeout_s : float
        An upload with no item for this long (wall-clock seconds passed in by the caller) is
        abandoned; the old list stays.

    Notes
    -----
    ``begin_upload`` / ``receive_item`` / ``expire_uploads`` are the upload protocol;
    ``items(mission_type)`` is the stored list (a tuple, never mutated in place).
    """

    def __init__(self, upload_timeout_s: float = 5.0) -> None:
        self.upload_timeout_s = float(upload_timeout_s)
        self._lists: dict[int, tuple[MissionItem, ...]] = {t: () for t in MISSION_TYPES}
        self._uploads: dict[int, Upload] = {}
        self._generation: dict[int, int] = {t: 0 for t in MISSION_TYPES}

    # ---- stored lists -------------------------------------------------------------------------

    def items(self, mission_type: int = MISSION_TYPE_MISSION) -> tuple[MissionItem, ...]:
        """The stored list of ``mission_type`` (empty tuple if none)."""
        return self._lists.get(mission_type, ())

    def generation(self, mission_type: int = MISSION_TYPE_MISSION) -> int:
        """Counter increased each time the list of ``mission_type`` is replaced or cleared."""
        return self._generation.get(mission_type, 0)

    def clear(self, mission_type: int) -> MissionResult:
        """``MISSION_CLEAR_ALL``: empty one list (or all three with ``MISSION_TYPE_ALL``)."""
        types = MISSION_TYPES if mission_type == MISSION_TYPE_ALL else (mission_type,)
        if any(t not in MISSION_TYPES for t in types):
            return MissionResult.UNSUPPORTED
        for t in types:
            self._uploads.pop(t, None)
            self._lists[t] = ()
            self._generation[t] += 1
            log.info("%s list cleared", MISSION_TYPE_NAMES[t])
        return MissionResult.ACCEPTED

    # ---- upload protocol ----------------------------------------------------------------------

    def upload_in_progress(self, mission_type: int) -> Upload | None:
        """The upload of ``mission_type`` in progress, if any."""
        return self._uploads.get(mission_type)

    def begin_upload(self, mission_type: int, count: int, now_s: float) -> MissionResult:
        """``MISSION_COUNT``: start receiving ``count`` items; a previous upload is abandoned.

        A count of 0 clears the list at once (as ArduPilot does). Returns ``ACCEPTED`` when the
        caller should request item 0 (or has nothing more to do for ``count == 0``).
        """
        if mission_type not in MISSION_TYPES:
            return MissionResult.UNSUPPORTED
        if count < 0:
            return MissionResult.INVALID
        if count > MAX_ITEMS:
            log.warning("%s upload refused: %d items > %d", MISSION_TYPE_NAMES[mission_type], count, MAX_ITEMS)
            return MissionResult.NO_SPACE
        if mission_type in self._uploads:
            log.warning(
                "%s upload restarted before it completed; the partial upload is dropped",
                MISSION_TYPE_NAMES[mission_type],
            )
            del self._uploads[mission_type]
        if count == 0:
            self._lists[mission_type] = ()
            self._generation[mission_type] += 1
            return MissionResult.ACCEPTED
        self._uploads[mission_type] = Upload(mission_type, count, now_s, now_s)
        return MissionResult.ACCEPTED

    def receive_item(self, item: MissionItem, now_s: float) -> tuple[MissionResult, bool]:
        """One item of an upload.

        Returns
        -------
        result : MissionResult
            ``ACCEPTED`` if the item was stored (or was a harmless duplicate of the previous
            one), otherwise the fault; ``INVALID_SEQUENCE`` for an out-of-order or past-the-count
            item (the upload stays open so the sender can resend the requested one);
            any other fault aborts the upload (the old list stays).
        complete : bool
            True when this item completed the upload and the list was replaced.
        """
        upload = self._uploads.get(item.mission_type)
        if upload is None:
            return MissionResult.DENIED, False
        if upload.items and item.seq == upload.next_seq - 1:  # resent because our request was lost
            upload.last_activity_s = now_s
            return MissionResult.ACCEPTED, False
        if item.seq != upload.next_seq:
            log.warning(
                "%s upload: got item %d, expected %d of %d: refused (INVALID_SEQUENCE)",
                MISSION_TYPE_NAMES[item.mission_type],
                item.seq,
                upload.next_seq,
                upload.count,
            )
            return MissionResult.INVALID_SEQUENCE, False
        result = validate_item(item)
        if result != MissionResult.ACCEPTED:
            log.warning(
                "%s upload aborted at item %d (command %d, frame %d): %s; previous list kept",
                MISSION_TYPE_NAMES[item.mission_type],
                item.seq,
                item.command,
                item.frame,
                result.name,
            )
            del self._uploads[item.mission_type]
            return result, False
        upload.items.append(item)
        upload.last_activity_s = now_s
        if len(upload.items) == upload.count:
            self._commit(upload)
            return MissionResult.ACCEPTED, True
        return MissionResult.ACCEPTED, False

    def cancel_upload(self, mission_type: int, reason: str) -> bool:
        """Drop the upload of ``mission_type`` (the stored list stays); True if there was one."""
        upload = self._uploads.pop(mission_type, None)
        if upload is not None:
            log.warning(
                "%s upload cancelled after %d of %d items (%s); previous list kept",
                MISSION_TYPE_NAMES[mission_type],
                len(upload.items),
                upload.count,
                reason,
            )
        return upload is not None

    def expire_uploads(self, now_s: float) -> list[Upload]:
        """Abandon uploads idle for longer than ``upload_timeout_s``; returns them."""
        expired = [u for u in self._uploads.values() if now_s - u.last_activity_s > self.upload_timeout_s]
        for upload in expired:
            self.cancel_upload(upload.mission_type, f"no item for {self.upload_timeout_s:g} s")
        return expired

    def _commit(self, upload: Upload) -> None:
        items = tuple(upload.items)
        self._lists[upload.mission_type] = items
        self._generation[upload.mission_type] += 1
        del self._uploads[upload.mission_type]
        log.info("%s list replaced: %d items", MISSION_TYPE_NAMES[upload.mission_type], len(items))
