"""GUIDED setpoints from SET_POSITION_TARGET_LOCAL_NED and SET_POSITION_TARGET_GLOBAL_INT.

As ArduCopter's ``GCS_MAVLINK_Copter::handle_set_position_target_*``: the ``type_mask`` says
which of position, velocity, acceleration, yaw and yaw rate the sender sets; local targets are
in metres from the EKF origin (LOCAL_NED), from the vehicle (LOCAL_OFFSET_NED) or in body axes
(BODY_NED, BODY_OFFSET_NED); global ones in 1e-7 degrees with the altitude AMSL or above home.
A target is a :class:`heli_model.control.Setpoint` in the vehicle's NED frame.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from heli_common.mavlink_ids import (
    TYPEMASK_IGNORE_ACCELERATION,
    TYPEMASK_IGNORE_POSITION,
    TYPEMASK_IGNORE_VELOCITY,
    mavlink,
)
from heli_model.control import Setpoint
from sim_vehicle.autopilot import Autopilot
from sim_vehicle.mavlink.endpoint import Address, LogThrottle
from sim_vehicle.mission_store import FRAME_GLOBAL, FRAME_GLOBAL_INT, GLOBAL_FRAMES

log = logging.getLogger(__name__)

LOCAL_FRAMES = frozenset(
    {
        mavlink.MAV_FRAME_LOCAL_NED,
        mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
        mavlink.MAV_FRAME_BODY_NED,
        mavlink.MAV_FRAME_BODY_OFFSET_NED,
    }
)
BODY_FRAMES = frozenset({mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED})


class GuidedSetpoints:
    """Turns position-target messages into GUIDED setpoints of the autopilot.

    Parameters
    ----------
    autopilot : Autopilot
        Takes the setpoints (and refuses them outside GUIDED).
    throttle : LogThrottle
        Rate-limits the log of refused setpoints.
    """

    def __init__(self, autopilot: Autopilot, throttle: LogThrottle) -> None:
        self.autopilot = autopilot
        self.throttle = throttle

    def on_set_position_target_local_ned(self, msg: Any, address: Address) -> None:
        frame = msg.coordinate_frame
        if frame not in LOCAL_FRAMES:
            log.warning("SET_POSITION_TARGET_LOCAL_NED: frame %d not supported; ignored", frame)
            return
        pos = (msg.x, msg.y, msg.z)
        vel = (msg.vx, msg.vy, msg.vz)
        acc = (msg.afx, msg.afy, msg.afz)
        a = self.autopilot
        yaw = float(a.euler_rad[2])
        c, s = math.cos(yaw), math.sin(yaw)

        def rotate(v: tuple) -> tuple:
            return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])

        here = a.pos_ned_m
        if frame in BODY_FRAMES:
            vel, acc = rotate(vel), rotate(acc)  # velocities and accelerations in body axes
        if frame == mavlink.MAV_FRAME_BODY_OFFSET_NED:
            off = rotate(pos)
            pos = (off[0] + here[0], off[1] + here[1], off[2] + here[2])
        elif frame == mavlink.MAV_FRAME_LOCAL_OFFSET_NED:
            pos = (pos[0] + here[0], pos[1] + here[1], pos[2] + here[2])
        elif frame == mavlink.MAV_FRAME_LOCAL_NED:  # metres from the EKF origin, as in ArduPilot
            pos = tuple(a.frames.from_local(pos))
        self._set_target(msg, pos, vel, acc)

    def on_set_position_target_global_int(self, msg: Any, address: Address) -> None:
        frame = msg.coordinate_frame
        if frame not in GLOBAL_FRAMES:
            log.warning("SET_POSITION_TARGET_GLOBAL_INT: frame %d not supported; ignored", frame)
            return
        pos: tuple = (math.nan, math.nan, math.nan)
        if not msg.type_mask & TYPEMASK_IGNORE_POSITION:
            lat, lon = msg.lat_int * 1e-7, msg.lon_int * 1e-7
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or not math.isfinite(msg.alt):
                log.warning(
                    "SET_POSITION_TARGET_GLOBAL_INT: position %r, %r, %r invalid; ignored",
                    msg.lat_int,
                    msg.lon_int,
                    msg.alt,
                )
                return
            home_alt = self.autopilot.home_lla[2]
            alt_amsl = msg.alt if frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else home_alt + msg.alt
            pos = self.autopilot.frame.to_ned(lat, lon, alt_amsl)
        self._set_target(msg, pos, (msg.vx, msg.vy, msg.vz), (msg.afx, msg.afy, msg.afz))

    def _set_target(self, msg: Any, pos: tuple, vel: tuple, acc: tuple) -> None:
        mask = msg.type_mask
        force = bool(mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET)
        setpoint = Setpoint(
            pos_ned_m=None if mask & TYPEMASK_IGNORE_POSITION else pos,
            vel_ned_m_s=None if mask & TYPEMASK_IGNORE_VELOCITY else vel,
            acc_ned_m_s2=None if (mask & TYPEMASK_IGNORE_ACCELERATION or force) else acc,
            yaw_rad=None if mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE else float(msg.yaw),
            yaw_rate_rad_s=None if mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE else float(msg.yaw_rate),
        )
        if (
            setpoint.pos_ned_m is None
            and setpoint.vel_ned_m_s is None
            and setpoint.acc_ned_m_s2 is None
            and setpoint.yaw_rad is None
            and setpoint.yaw_rate_rad_s is None
        ):
            log.warning("%s: type_mask %#x ignores everything; ignored", msg.get_type(), mask)
            return
        ok, reason = self.autopilot.set_guided_setpoint(setpoint)
        if not ok:
            n = self.throttle.count(f"guided:{reason}")
            if n <= 3 or n % 100 == 0:
                log.warning("%s refused: %s", msg.get_type(), reason)
