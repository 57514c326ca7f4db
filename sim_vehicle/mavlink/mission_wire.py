"""Mission items on the wire: MISSION_ITEM_INT and the legacy float MISSION_ITEM to and from the stored record.

The store keeps the fields of MISSION_ITEM_INT (:data:`sim_vehicle.mission_store.MissionItem`):
latitude and longitude in 1e-7 degrees for the global frames, local positions in 1e-4 m
(as ArduPilot converts MISSION_ITEM), so a download returns exactly what was uploaded.
"""

from __future__ import annotations

import math
from typing import Any

from sim_vehicle.mission_store import FRAME_LOCAL_NED, GLOBAL_FRAMES, MissionItem

INVALID_DEG_E7 = 2_000_000_000
"""Stands for a latitude or longitude that is not one: the store refuses it (INVALID_PARAM5_X)."""


def from_mission_item_int(msg: Any, mission_type: int) -> MissionItem:
    """The record of a received MISSION_ITEM_INT."""
    return MissionItem(
        seq=msg.seq,
        frame=msg.frame,
        command=msg.command,
        current=msg.current,
        autocontinue=msg.autocontinue,
        param1=msg.param1,
        param2=msg.param2,
        param3=msg.param3,
        param4=msg.param4,
        x=int(msg.x),
        y=int(msg.y),
        z=float(msg.z),
        mission_type=mission_type,
    )


def from_mission_item(msg: Any, mission_type: int) -> MissionItem:
    """The record of a received legacy MISSION_ITEM (x, y in degrees or metres, as floats)."""
    frame = msg.frame
    if frame in GLOBAL_FRAMES:
        if not (math.isfinite(msg.x) and math.isfinite(msg.y)) or abs(msg.x) > 90.0 or abs(msg.y) > 180.0:
            x, y = INVALID_DEG_E7, INVALID_DEG_E7
        else:
            x, y = int(round(msg.x * 1e7)), int(round(msg.y * 1e7))
    elif frame == FRAME_LOCAL_NED and math.isfinite(msg.x) and math.isfinite(msg.y):
        x, y = int(round(msg.x * 1e4)), int(round(msg.y * 1e4))
    else:
        x, y = (int(msg.x), int(msg.y)) if math.isfinite(msg.x) and math.isfinite(msg.y) else (0, 0)
    return MissionItem(
        seq=msg.seq,
        frame=frame,
        command=msg.command,
        current=msg.current,
        autocontinue=msg.autocontinue,
        param1=msg.param1,
        param2=msg.param2,
        param3=msg.param3,
        param4=msg.param4,
        x=x,
        y=y,
        z=float(msg.z),
        mission_type=mission_type,
    )


def encode_item(mav: Any, it: MissionItem, sysid: int, compid: int, mission_type: int, legacy: bool) -> Any:
    """The stored item as MISSION_ITEM_INT, or as MISSION_ITEM for a legacy request, to ``sysid``/``compid``."""
    if not legacy:
        return mav.mission_item_int_encode(
            sysid,
            compid,
            it.seq,
            it.frame,
            it.command,
            it.current,
            it.autocontinue,
            it.param1,
            it.param2,
            it.param3,
            it.param4,
            it.x,
            it.y,
            it.z,
            mission_type,
        )
    if it.frame in GLOBAL_FRAMES:
        x, y = it.x * 1e-7, it.y * 1e-7
    elif it.frame == FRAME_LOCAL_NED:
        x, y = it.x * 1e-4, it.y * 1e-4
    else:
        x, y = float(it.x), float(it.y)
    return mav.mission_item_encode(
        sysid,
        compid,
        it.seq,
        it.frame,
        it.command,
        it.current,
        it.autocontinue,
        it.param1,
        it.param2,
        it.param3,
        it.param4,
        x,
        y,
        it.z,
        mission_type,
    )
