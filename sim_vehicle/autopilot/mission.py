"""Mission sequencing: the mission, rally lists and the items turned into stages (ArduPilot's AP_Mission).

ArduPilot's convention: item 0 of the mission list is home and is not flown; AUTO starts at
item 1. NAV_WAYPOINT (acceptance radius param2, hold param1), NAV_TAKEOFF, NAV_LAND,
NAV_RETURN_TO_LAUNCH, NAV_LOITER_UNLIM/TIME and DO_CHANGE_SPEED are flown; other DO commands
are skipped with a log line. MISSION_ITEM_REACHED and MISSION_CURRENT are reported as events of
:meth:`Autopilot.step <sim_vehicle.autopilot.Autopilot.step>`. Relative altitudes are above home;
LOCAL_NED items are metres from the EKF origin. :class:`Mission` holds the lists and the
sequence; the stages of an item are flown by the :class:`~sim_vehicle.autopilot.navigation.Navigation`
it is given.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from heli_common.mavlink_ids import mavlink
from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import AUTO
from sim_vehicle.autopilot.mode_rtl import rtl_stages
from sim_vehicle.config import VehicleSettings
from sim_vehicle.frames import Frames
from sim_vehicle.mission_store import FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_LOCAL_NED, FRAME_MISSION, MissionItem

log = logging.getLogger(__name__)

# MAV_CMD numbers of the mission items the vehicle flies (pymavlink's generated enums)
CMD_NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
CMD_NAV_LOITER_UNLIM = mavlink.MAV_CMD_NAV_LOITER_UNLIM
CMD_NAV_LOITER_TIME = mavlink.MAV_CMD_NAV_LOITER_TIME
CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
CMD_DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
CMD_NAV_RALLY_POINT = mavlink.MAV_CMD_NAV_RALLY_POINT
NAV_COMMANDS = frozenset(
    {
        CMD_NAV_WAYPOINT,
        CMD_NAV_LOITER_UNLIM,
        CMD_NAV_LOITER_TIME,
        CMD_NAV_RETURN_TO_LAUNCH,
        CMD_NAV_LAND,
        CMD_NAV_TAKEOFF,
    }
)


class Host(Protocol):
    """What the sequencer reads of the vehicle (:class:`~sim_vehicle.autopilot.Autopilot`)."""

    @property
    def mode(self) -> int:
        """ArduCopter mode number now."""

    @property
    def armed(self) -> bool:
        """True while armed."""

    @property
    def landed(self) -> bool:
        """True while on the ground."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame."""

    @property
    def height_above_home_m(self) -> float:
        """Height above home, m."""


class Navigator(Protocol):
    """The stage runner as the sequencer uses it (:class:`~sim_vehicle.autopilot.navigation.Navigation`)."""

    @property
    def current_stage(self) -> Stage | None:
        """The stage flown now."""

    def set_stages(self, stages: list[Stage]) -> None:
        """Fly these stages from now on."""

    def brake_point(self) -> np.ndarray:
        """Where braking now stops the vehicle, (3,) m NED."""

    def hold_target(self) -> np.ndarray:
        """Where to hold, (3,) m NED."""

    def takeoff_stage(self, alt_m: float) -> Stage:
        """A vertical climb to ``alt_m`` above home."""

    def use_speed(self, speed_m_s: float) -> None:
        """Horizontal leg speed from now on (DO_CHANGE_SPEED), m/s."""


class Mission:
    """The mission and rally lists and the sequencer (ArduPilot's ``AP_Mission``).

    Parameters
    ----------
    host : Host
        Mode, arming, ground contact and position of the vehicle.
    navigation : Navigator
        Flies the stages of the current item.
    frames : Frames
        Ground frame, EKF origin and home (the items' positions).
    settings : callable () -> VehicleSettings
        The settings in use (``flight``: the speed limit, RTL_ALT).
    emit : callable (event tuple) -> None
        Reports an event of :meth:`Autopilot.step <sim_vehicle.autopilot.Autopilot.step>`.

    Attributes
    ----------
    items : tuple of MissionItem
        The mission list (item 0 is home).
    current : int
        Sequence number of the current mission item.
    finished : bool
        True once the last item is done (until a new list, MISSION_SET_CURRENT or a start).
    rally_ned_m : list of ndarray, shape (3,)
        Rally points, m NED in the ground frame.
    """

    def __init__(
        self,
        host: Host,
        navigation: Navigator,
        frames: Frames,
        settings: Callable[[], VehicleSettings],
        emit: Callable[[tuple], None],
    ) -> None:
        self._host = host
        self._nav = navigation
        self._frames = frames
        self._settings = settings
        self._emit = emit
        self.items: tuple[MissionItem, ...] = ()
        self.current = 0
        self.finished = False
        self.rally_ned_m: list[np.ndarray] = []
        self._item_active = False

    @property
    def has_mission(self) -> bool:
        """True if the mission list holds a flyable item after the home item 0."""
        return any(it.command in NAV_COMMANDS for it in self.items[1:])

    @property
    def _flying_auto(self) -> bool:
        return self._host.mode == AUTO and self._host.armed

    # ------------------------------------------------------------------ the lists
    def set_items(self, items: Sequence[MissionItem]) -> None:
        """A new mission list (after a completed upload or a clear); AUTO flies it from the current item."""
        self.items = tuple(items)
        self.finished = False
        if not self.has_mission:
            self.current = 0
            if self._flying_auto and not self._host.landed:
                self._nav.set_stages([Stage("hold", target=self._nav.brake_point())])
            return
        if not 1 <= self.current < len(self.items):
            self.current = 1
        if self._flying_auto:
            self.start(self.current)

    def set_rally(self, items: Sequence[MissionItem]) -> None:
        """New rally points: RTL returns to the nearest of home and these (ArduPilot's rally)."""
        points = []
        for it in items:
            if it.command == CMD_NAV_RALLY_POINT and not (it.x == 0 and it.y == 0):
                target = self.item_target_ned_m(it)
                points.append(target)
        self.rally_ned_m = points
        log.info("%d rally points", len(points))

    def set_current(self, seq: int) -> tuple[bool, str]:
        """MISSION_SET_CURRENT: continue the mission at ``seq``."""
        if not 0 <= seq < len(self.items):
            return False, f"item {seq} outside the mission (0..{len(self.items) - 1})"
        self.current = max(1, seq) if len(self.items) > 1 else seq
        self.finished = False
        self._emit(("mission_current", self.current))
        if self._flying_auto:
            self.start(self.current)
        return True, ""

    def start_refusal(self, first: int) -> str | None:
        """Why MAV_CMD_MISSION_START from item ``first`` is refused by the list (None: it is not)."""
        if not self.has_mission:
            return "no mission"
        if not 0 <= first < len(self.items):
            return f"item {first} outside the mission (0..{len(self.items) - 1})"
        return None

    # ------------------------------------------------------------------ sequencing
    def resume_seq(self) -> int:
        """Where AUTO (re)starts: the current item, or item 1 after a completed mission."""
        if self.finished or not 1 <= self.current < len(self.items):
            return 1
        return self.current

    def start(self, seq: int) -> None:
        """Fly the mission from item ``seq`` (its stages are made at the next :meth:`advance`)."""
        self.finished = False
        self._item_active = False
        self._nav.set_stages([])
        self.current = seq
        self._emit(("mission_current", seq))
        log.info("AUTO: mission from item %d", seq)

    def drop_active_item(self) -> None:
        """The current item's stages are no longer flown (mode change, disarm): AUTO makes them again."""
        self._item_active = False

    def advance(self, t_s: float) -> None:
        """Every AUTO control tick: while no item is flown, the next item's stages (DO commands done at once)."""
        guard = 0
        while not self._item_active and not self.finished and guard < len(self.items) + 1:
            guard += 1
            if not 1 <= self.current < len(self.items):
                self._finish()
                return
            stages = self._item_stages(self.items[self.current])
            if stages is None:  # a DO command or an unsupported one: done at once
                self._advance_item(reached=False)
                continue
            self._nav.set_stages(stages)
            self._item_active = True

    def item_flown(self) -> None:
        """The stages of the current item are flown (the last one finished, or a touchdown): in AUTO it is done."""
        if self._host.mode == AUTO and self._item_active:
            self._item_active = False
            self._advance_item(reached=True)

    def _advance_item(self, reached: bool) -> None:
        seq = self.current
        if reached:
            self._emit(("mission_item_reached", seq))
            log.info("AUTO: reached item %d", seq)
        if seq + 1 < len(self.items):
            self.current = seq + 1
            self._emit(("mission_current", self.current))
        else:
            self._finish()

    def _finish(self) -> None:
        if not self.finished:
            self.finished = True
            log.info("AUTO: mission complete")
            self._emit(("text", 6, "Mission complete"))
        if self._host.armed and not self._host.landed and self._nav.current_stage is None:
            self._nav.set_stages([Stage("hold", target=self._nav.hold_target())])

    # ------------------------------------------------------------------ items to stages
    def item_target_ned_m(self, item: MissionItem) -> np.ndarray:
        """Target of a mission item, (3,) m NED in the ground frame; a missing position keeps the current one."""
        frames = self._frames
        pos = self._host.pos_ned_m
        has_position = not (item.x == 0 and item.y == 0)
        if item.frame == FRAME_LOCAL_NED:  # metres from the EKF origin, as in ArduPilot
            return frames.from_local((item.x * 1e-4, item.y * 1e-4, item.z))
        if item.frame == FRAME_MISSION or not has_position:
            north, east = pos[0], pos[1]
        else:
            alt_amsl = item.z if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else frames.home_alt_m + item.z
            north, east, _ = frames.ground.to_ned(item.lat_deg, item.lon_deg, alt_amsl)
        if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
            down = -(item.z - frames.ground.alt0_m)
        else:  # relative altitudes are above home
            down = frames.down_at_height_above_home(item.z)
        return np.array([north, east, down])

    def _item_stages(self, item: MissionItem) -> list[Stage] | None:
        """The stages of a NAV item; None for a DO command (DO_CHANGE_SPEED done here) or an unsupported one."""
        cmd = item.command
        if cmd == CMD_DO_CHANGE_SPEED:
            speed = item.param2
            if math.isfinite(speed) and speed > 0:
                speed = min(speed, self._settings().flight.max_speed_m_s)
                self._nav.use_speed(speed)
                log.info("AUTO: speed %.1f m/s (DO_CHANGE_SPEED)", speed)
            return None
        if cmd not in NAV_COMMANDS:
            log.info("AUTO: item %d command %d not simulated; skipped", item.seq, cmd)
            return None
        if cmd == CMD_NAV_TAKEOFF:
            alt_m = item.z if item.frame not in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else item.z - self._frames.home_alt_m
            if self._host.height_above_home_m >= alt_m - 0.5:
                return [Stage("hold", duration_s=0.0)]
            return [self._nav.takeoff_stage(alt_m)]
        if cmd == CMD_NAV_RETURN_TO_LAUNCH:
            return rtl_stages(self._host.pos_ned_m, self._frames, self._settings().flight, self.rally_ned_m)
        target = self.item_target_ned_m(item)
        if cmd == CMD_NAV_LAND:
            return self._land_stages(item, target)
        return self._waypoint_stages(item, target)

    def _land_stages(self, item: MissionItem, target: np.ndarray) -> list[Stage]:
        """NAV_LAND: fly level to its position (when it has one, more than 0.5 m away), then land."""
        stages = []
        pos = self._host.pos_ned_m
        if not (item.x == 0 and item.y == 0) and math.hypot(target[0] - pos[0], target[1] - pos[1]) > 0.5:
            stages.append(Stage("leg", target=np.array([target[0], target[1], min(pos[2], -1.0)])))
        stages.append(Stage("land"))
        return stages

    def _waypoint_stages(self, item: MissionItem, target: np.ndarray) -> list[Stage]:
        """NAV_WAYPOINT (radius param2, hold param1), NAV_LOITER_TIME and NAV_LOITER_UNLIM: a leg and a hold."""
        cmd = item.command
        if target[2] > -1.0 and not self._host.landed:
            target[2] = -1.0  # never fly a leg into the ground; land items do that
        radius = item.param2 if cmd == CMD_NAV_WAYPOINT and math.isfinite(item.param2) and item.param2 > 0 else 0.0
        stages = [Stage("leg", target=target, radius_m=radius)]
        if cmd == CMD_NAV_WAYPOINT and math.isfinite(item.param1) and item.param1 > 0:
            stages.append(Stage("hold", target=target, duration_s=float(item.param1)))
        elif cmd == CMD_NAV_LOITER_TIME:
            stages.append(Stage("hold", target=target, duration_s=max(0.0, float(item.param1))))
        elif cmd == CMD_NAV_LOITER_UNLIM:
            stages.append(Stage("hold", target=target, duration_s=None))
        return stages
