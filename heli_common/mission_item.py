"""The one mission item record: the fields of MAVLink's ``MISSION_ITEM_INT``.

Used by the companion's mission conversion (``companion.mission.raw.RawItem``) and by the SITL
vehicle's mission store (``sim_vehicle.mission_store.MissionItem``). Pure data: no I/O.
"""

from __future__ import annotations

import dataclasses

from heli_common.mavlink_ids import mavlink


@dataclasses.dataclass(frozen=True)
class MissionItemInt:
    """One mission, fence or rally item with the fields of ``MISSION_ITEM_INT``.

    Attributes
    ----------
    seq : int
        Index in its list.
    frame : int
        ``MAV_FRAME``.
    command : int
        ``MAV_CMD``.
    current, autocontinue : int
        As sent (0/1).
    param1 .. param4 : float
        Command parameters.
    x, y : int
        Latitude and longitude in 1e-7 degrees (global frames) or local x/y * 1e4 (local frames).
    z : float
        Altitude, m (frame-dependent reference).
    mission_type : int
        ``MAV_MISSION_TYPE``: 0 mission, 1 fence, 2 rally.
    """

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION

    @property
    def lat_deg(self) -> float:
        """Latitude, degrees (global frames)."""
        return self.x * 1e-7

    @property
    def lon_deg(self) -> float:
        """Longitude, degrees (global frames)."""
        return self.y * 1e-7
