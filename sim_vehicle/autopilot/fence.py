"""The geofence: polygon and circle fences in the local frame, breach test and breach action.

ArduPilot's polygon and circle fences (FENCE_TYPE) and altitude ceiling (FENCE_ALT_MAX, above
home); a breach triggers FENCE_ACTION (1 RTL, falling back to LAND; 2 LAND; 4 BRAKE).
:class:`Fence` is the area, :func:`fence_breach` the pure test and :class:`Geofence` the
vehicle's fence (ArduPilot's ``AC_Fence``): the list it holds and the check of every control tick.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from heli_common.geometry import point_in_polygon
from heli_common.mavlink_ids import mavlink
from sim_vehicle.autopilot.mode import BRAKE, LAND, RTL
from sim_vehicle.config import VehicleSettings
from sim_vehicle.frames import Frames
from sim_vehicle.mission_store import MissionItem

log = logging.getLogger(__name__)

CMD_FENCE_POLYGON_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
CMD_FENCE_POLYGON_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CMD_FENCE_CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
CMD_FENCE_CIRCLE_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
FENCE_ACTION_MODES = {1: RTL, 2: LAND, 4: BRAKE}
"""FENCE_ACTION value -> the mode a breach switches to."""


@dataclasses.dataclass(frozen=True)
class Fence:
    """A geofence in the local frame (ArduPilot's polygon and circle fences).

    Attributes
    ----------
    inclusion_polygons, exclusion_polygons : list of ndarray, shape (K, 2)
        North-east vertices, m.
    inclusion_circles, exclusion_circles : list of (ndarray (2,), float)
        Centre north-east (m) and radius (m).
    """

    inclusion_polygons: tuple = ()
    exclusion_polygons: tuple = ()
    inclusion_circles: tuple = ()
    exclusion_circles: tuple = ()

    @property
    def empty(self) -> bool:
        """True when no polygon or circle is defined."""
        return not (
            self.inclusion_polygons or self.exclusion_polygons or self.inclusion_circles or self.exclusion_circles
        )


def fence_breach(fence: Fence, pos_ned_m: np.ndarray, alt_max_m: float) -> str | None:
    """Why ``pos_ned_m`` violates the fence (or the ceiling), or None if it does not."""
    if -pos_ned_m[2] > alt_max_m:
        return f"above FENCE_ALT_MAX {alt_max_m:g} m"
    ne = pos_ned_m[:2]
    for poly in fence.inclusion_polygons:
        if not point_in_polygon(ne, poly):
            return "outside an inclusion polygon"
    for poly in fence.exclusion_polygons:
        if point_in_polygon(ne, poly):
            return "inside an exclusion polygon"
    for centre, radius in fence.inclusion_circles:
        if math.hypot(ne[0] - centre[0], ne[1] - centre[1]) > radius:
            return "outside an inclusion circle"
    for centre, radius in fence.exclusion_circles:
        if math.hypot(ne[0] - centre[0], ne[1] - centre[1]) < radius:
            return "inside an exclusion circle"
    return None


def fence_from_items(items: Sequence[MissionItem], target_ned_m: Callable[[MissionItem], np.ndarray]) -> Fence:
    """The fence of a fence list: polygon vertices grouped by their vertex count (param1), circles.

    ``target_ned_m`` maps an item to its position, (3,) m NED.
    """
    polygons: dict[int, list] = {CMD_FENCE_POLYGON_INCLUSION: [], CMD_FENCE_POLYGON_EXCLUSION: []}
    circles: dict[int, list] = {CMD_FENCE_CIRCLE_INCLUSION: [], CMD_FENCE_CIRCLE_EXCLUSION: []}
    current: list = []
    current_cmd = None
    for it in items:
        if it.command in polygons:
            count = int(it.param1) if math.isfinite(it.param1) and 3 <= it.param1 <= 1000 else 1000
            if current_cmd != it.command or not current or len(current) >= count:
                current = []
                current_cmd = it.command
                polygons[it.command].append(current)
            current.append(target_ned_m(it)[:2])
        elif it.command in circles and math.isfinite(it.param1) and it.param1 > 0:
            circles[it.command].append((target_ned_m(it)[:2], float(it.param1)))
            current_cmd = None
    return Fence(
        tuple(np.array(p) for p in polygons[CMD_FENCE_POLYGON_INCLUSION] if len(p) >= 3),
        tuple(np.array(p) for p in polygons[CMD_FENCE_POLYGON_EXCLUSION] if len(p) >= 3),
        tuple(circles[CMD_FENCE_CIRCLE_INCLUSION]),
        tuple(circles[CMD_FENCE_CIRCLE_EXCLUSION]),
    )


class Host(Protocol):
    """What the fence reads of the vehicle and asks of it (:class:`~sim_vehicle.autopilot.Autopilot`)."""

    @property
    def mode(self) -> int:
        """ArduCopter mode number now."""

    @property
    def landed(self) -> bool:
        """True while on the ground."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame."""

    def set_mode(self, mode: int) -> tuple[bool, str]:
        """Switch flight mode (the breach action)."""


class Geofence:
    """The vehicle's geofence: the area of the fence list and the breach check (ArduPilot's ``AC_Fence``).

    Parameters
    ----------
    host : Host
        Mode, ground contact and position; switches mode on a breach.
    frames : Frames
        Home (FENCE_ALT_MAX is above home).
    item_target_ned_m : callable (MissionItem) -> ndarray (3,)
        Position of a fence item, m NED in the ground frame.
    settings : callable () -> VehicleSettings
        The settings in use (FENCE_ENABLE, FENCE_ALT_MAX, FENCE_ACTION).
    emit : callable (event tuple) -> None
        Reports an event of :meth:`Autopilot.step <sim_vehicle.autopilot.Autopilot.step>`.

    Attributes
    ----------
    area : Fence
        The polygons and circles of the fence list.
    breached : str or None
        Why the fence is breached now (None inside).
    """

    def __init__(
        self,
        host: Host,
        frames: Frames,
        item_target_ned_m: Callable[[MissionItem], np.ndarray],
        settings: Callable[[], VehicleSettings],
        emit: Callable[[tuple], None],
    ) -> None:
        self._host = host
        self._frames = frames
        self._item_target_ned_m = item_target_ned_m
        self._settings = settings
        self._emit = emit
        self.area = Fence()
        self.breached: str | None = None

    def set_items(self, items: Sequence[MissionItem]) -> None:
        """New fence list (polygon vertices grouped by their vertex count, circles)."""
        self.area = fence_from_items(items, self._item_target_ned_m)
        self.breached = None
        log.info(
            "fence: %d inclusion / %d exclusion polygons, %d / %d circles",
            len(self.area.inclusion_polygons),
            len(self.area.exclusion_polygons),
            len(self.area.inclusion_circles),
            len(self.area.exclusion_circles),
        )

    def check(self) -> None:
        """Every control tick while armed: a new breach switches to the FENCE_ACTION mode (not from RTL or LAND)."""
        f = self._settings().flight
        if not f.fence_enable or self._host.landed:
            return
        pos = self._host.pos_ned_m.copy()
        pos[2] = -self._frames.height_above_home(pos)  # FENCE_ALT_MAX is above home
        reason = fence_breach(self.area, pos, f.fence_alt_max_m)
        if reason is None:
            if self.breached is not None:
                log.info("fence: back inside")
            self.breached = None
            return
        if self.breached is not None:
            return  # already acting on this breach
        self.breached = reason
        log.warning("fence breached (%s): action %d", reason, f.fence_action)
        self._emit(("text", 2, f"Fence breach: {reason}"[:50]))
        action = FENCE_ACTION_MODES.get(f.fence_action)
        if action is not None and self._host.mode not in (RTL, LAND):
            ok, _ = self._host.set_mode(action)
            if not ok and action == RTL:
                self._host.set_mode(LAND)
