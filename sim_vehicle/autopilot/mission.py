"""Mission sequencing: the mission, rally lists and the items turned into stages (ArduPilot's AP_Mission).

ArduPilot's convention: item 0 of the mission list is home and is not flown; AUTO starts at
item 1. NAV_WAYPOINT (acceptance radius param2, hold param1), NAV_TAKEOFF, NAV_LAND,
NAV_RETURN_TO_LAUNCH, NAV_LOITER_UNLIM/TIME and DO_CHANGE_SPEED are flown; other DO commands
are skipped with a log line. MISSION_ITEM_REACHED and MISSION_CURRENT are reported as events of
:meth:`Autopilot.step`. Relative altitudes are above home; LOCAL_NED items are metres from the
EKF origin.
"""

from __future__ import annotations

import logging
import math
from typing import Sequence

import numpy as np

from heli_common.mavlink_ids import mavlink

from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import AUTO
from sim_vehicle.autopilot.mode_rtl import rtl_stages
from sim_vehicle.mission_store import (
    FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_LOCAL_NED, FRAME_MISSION, MissionItem,
)

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
NAV_COMMANDS = frozenset({CMD_NAV_WAYPOINT, CMD_NAV_LOITER_UNLIM, CMD_NAV_LOITER_TIME, CMD_NAV_RETURN_TO_LAUNCH,
                          CMD_NAV_LAND, CMD_NAV_TAKEOFF})


class MissionMixin:
    """The Autopilot's mission lists and sequencer (state: ``mission_items``, ``mission_current``,
    ``mission_finished``, ``rally_ned_m``, ``_item_active``)."""

    @property
    def has_mission(self) -> bool:
        """True if the mission list holds a flyable item after the home item 0."""
        return any(it.command in NAV_COMMANDS for it in self.mission_items[1:])

    def mission_start(self, first: int = 0) -> tuple[bool, str]:
        """MAV_CMD_MISSION_START: AUTO from item ``first`` (0 = from item 1)."""
        if not self.has_mission:
            return False, "no mission"
        if not 0 <= first < len(self.mission_items):
            return False, f"item {first} outside the mission (0..{len(self.mission_items) - 1})"
        if not self.armed:
            return False, "not armed"
        self.mission_current = max(1, first)
        if self.mode != AUTO:
            self.mode = AUTO
            self._events.append(("mode", AUTO))
            log.info("mode -> AUTO (mission start)")
        self._start_mission(self.mission_current)
        return True, ""

    def set_mission(self, items: Sequence[MissionItem]) -> None:
        """A new mission list (after a completed upload or a clear)."""
        self.mission_items = tuple(items)
        self.mission_finished = False
        if not self.has_mission:
            self.mission_current = 0
            if self.mode == AUTO and self.armed and not self.landed:
                self._stages = [Stage("hold", target=self._brake_point())]
            return
        if not 1 <= self.mission_current < len(self.mission_items):
            self.mission_current = 1
        if self.mode == AUTO and self.armed:
            self._start_mission(self.mission_current)


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
        if not 0 <= seq < len(self.mission_items):
            return False, f"item {seq} outside the mission (0..{len(self.mission_items) - 1})"
        self.mission_current = max(1, seq) if len(self.mission_items) > 1 else seq
        self.mission_finished = False
        self._events.append(("mission_current", self.mission_current))
        if self.mode == AUTO and self.armed:
            self._start_mission(self.mission_current)
        return True, ""


    def _resume_seq(self) -> int:
        """Where AUTO (re)starts: the current item, or item 1 after a completed mission."""
        if self.mission_finished or not 1 <= self.mission_current < len(self.mission_items):
            return 1
        return self.mission_current

    def _start_mission(self, seq: int) -> None:
        self.mission_finished = False
        self._item_active = False
        self._stages = []
        self.mission_current = seq
        self._events.append(("mission_current", seq))
        log.info("AUTO: mission from item %d", seq)

    def _advance_mission(self, t: float) -> None:
        guard = 0
        while not self._item_active and not self.mission_finished and guard < len(self.mission_items) + 1:
            guard += 1
            if not 1 <= self.mission_current < len(self.mission_items):
                self._finish_mission()
                return
            item = self.mission_items[self.mission_current]
            stages = self._item_stages(item)
            if stages is None:  # a DO command or an unsupported one: done at once
                self._advance_item(reached=False)
                continue
            self._stages = stages
            self._item_active = True

    def _complete_item(self) -> None:
        self._item_active = False
        self._advance_item(reached=True)

    def _advance_item(self, reached: bool) -> None:
        seq = self.mission_current
        if reached:
            self._events.append(("mission_item_reached", seq))
            log.info("AUTO: reached item %d", seq)
        if seq + 1 < len(self.mission_items):
            self.mission_current = seq + 1
            self._events.append(("mission_current", self.mission_current))
        else:
            self._finish_mission()

    def _finish_mission(self) -> None:
        if not self.mission_finished:
            self.mission_finished = True
            log.info("AUTO: mission complete")
            self._events.append(("text", 6, "Mission complete"))
        if self.armed and not self.landed and not self._stages:
            self._stages = [Stage("hold", target=self._hold_target())]

    def item_target_ned_m(self, item: MissionItem) -> np.ndarray:
        """Target of a mission item in NED, m; a missing position keeps the current one."""
        pos = self.pos_ned_m
        has_position = not (item.x == 0 and item.y == 0)
        if item.frame == FRAME_LOCAL_NED:  # metres from the EKF origin, as in ArduPilot
            return self.frames.from_local((item.x * 1e-4, item.y * 1e-4, item.z))
        if item.frame == FRAME_MISSION or not has_position:
            north, east = pos[0], pos[1]
        else:
            alt_amsl = item.z if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else self.frames.home_alt_m + item.z
            north, east, _ = self.frame.to_ned(item.lat_deg, item.lon_deg, alt_amsl)
        if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
            down = -(item.z - self.frame.alt0_m)
        else:  # relative altitudes are above home
            down = self.frames.down_at_height_above_home(item.z)
        return np.array([north, east, down])

    def _item_stages(self, item: MissionItem) -> list[Stage] | None:
        cmd = item.command
        if cmd == CMD_DO_CHANGE_SPEED:
            speed = item.param2
            if math.isfinite(speed) and speed > 0:
                self._speed_override_m_s = min(speed, self.settings.flight.max_speed_m_s)
                log.info("AUTO: speed %.1f m/s (DO_CHANGE_SPEED)", self._speed_override_m_s)
            return None
        if cmd not in NAV_COMMANDS:
            log.info("AUTO: item %d command %d not simulated; skipped", item.seq, cmd)
            return None
        if cmd == CMD_NAV_TAKEOFF:
            alt_m = item.z if item.frame not in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else item.z - self.frames.home_alt_m
            if self.height_above_home_m >= alt_m - 0.5:
                return [Stage("hold", duration_s=0.0)]
            return [self._takeoff_stage(alt_m)]
        if cmd == CMD_NAV_RETURN_TO_LAUNCH:
            return rtl_stages(self)
        target = self.item_target_ned_m(item)
        if cmd == CMD_NAV_LAND:
            stages = []
            pos = self.pos_ned_m
            if not (item.x == 0 and item.y == 0) and math.hypot(target[0] - pos[0], target[1] - pos[1]) > 0.5:
                stages.append(Stage("leg", target=np.array([target[0], target[1], min(pos[2], -1.0)])))
            stages.append(Stage("land"))
            return stages
        if target[2] > -1.0 and not self.landed:
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
