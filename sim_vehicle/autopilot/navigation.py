"""Navigation: the stages the vehicle flies (legs, holds, landing, direct setpoints) and their setpoints.

Every control tick the current stage is started (its leg built from where the reference is),
finished when done (a leg when its profile has arrived within the acceptance radius, a hold
after its time, a direct GUIDED stage after GUID_TIMEOUT without a setpoint) and turned into the
:class:`~heli_model.control.Setpoint` the flight controller tracks. Holds keep the heading in
``_yaw_hold_rad``; a vehicle told to stop brakes at ``brake_accel_m_s2``.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from sim_vehicle.autopilot.legs import Leg, Stage
from sim_vehicle.autopilot.mode import AUTO
from sim_vehicle.autopilot.mode_guided import integrate_target
from sim_vehicle.autopilot.mode_land import land_setpoint
from heli_model.control import Setpoint

log = logging.getLogger(__name__)


class NavigationMixin:
    """The Autopilot's stage runner (state: ``_stages``, ``_ref_pos``, ``_yaw_hold_rad``, ``_speed_override_m_s``)."""

    def change_speed(self, speed_m_s: float | None) -> tuple[bool, str]:
        """MAV_CMD_DO_CHANGE_SPEED: horizontal leg speed from now on (None = back to WPNAV_SPEED)."""
        if speed_m_s is None:
            self._speed_override_m_s = None
            return True, ""
        limit = self.settings.flight.max_speed_m_s
        if not math.isfinite(speed_m_s) or not 0.1 <= speed_m_s <= limit:
            return False, f"speed {speed_m_s!r} outside 0.1..{limit:g} m/s"
        self._speed_override_m_s = float(speed_m_s)
        log.info("speed set to %.1f m/s", speed_m_s)
        return True, ""

    @property
    def speed_m_s(self) -> float:
        """Current horizontal leg speed (DO_CHANGE_SPEED or WPNAV_SPEED), m/s."""
        return self._speed_override_m_s if self._speed_override_m_s is not None else self.settings.flight.wp_speed_m_s

    @property
    def landing(self) -> bool:
        """True while descending to land (LAND, the end of RTL, a NAV_LAND item)."""
        return bool(self._stages) and self._stages[0].kind == "land"

    def _speed_xy(self, stage: Stage) -> float:
        if stage.speed_xy_m_s is not None:
            return stage.speed_xy_m_s
        if self._speed_override_m_s is not None:
            return self._speed_override_m_s
        return self.settings.flight.wp_speed_m_s

    def _leg_start(self) -> np.ndarray:
        pos = self.pos_ned_m
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - pos)) < 2.0:
            return self._ref_pos.copy()
        return pos

    def _advance_stages(self, t: float) -> None:
        while self._stages:
            stage = self._stages[0]
            if stage.started_s is None:
                stage.started_s = t
                if stage.kind == "leg":
                    f = self.settings.flight
                    speed_xy = self._speed_xy(stage)
                    up = f.takeoff_speed_m_s if stage.vertical_only else f.wp_speed_up_m_s
                    stage.leg = Leg(self._leg_start(), stage.target, speed_xy, up, f.wp_speed_down_m_s,
                                    f.wp_accel_m_s2, t)
                elif stage.kind == "hold" and stage.target is None:
                    stage.target = self._hold_target()
                elif stage.kind == "land":
                    stage.target = self._leg_start()
            if not self._stage_done(stage, t):
                return
            self._stages.pop(0)
            if stage.kind in ("leg", "hold") and stage.target is not None:
                self._ref_pos = stage.target.copy()
            if not self._stages and self._item_active and self.mode == AUTO:
                self._complete_item()
                return

    def _stage_done(self, stage: Stage, t: float) -> bool:
        if stage.kind == "leg":
            if not stage.leg.finished(t):
                return False
            radius = stage.radius_m if stage.radius_m > 0 else self.settings.flight.wp_radius_m
            if float(np.linalg.norm(self.pos_ned_m - stage.target)) > radius:
                return False
            return True
        if stage.kind == "hold":
            if stage.duration_s is None:
                return False
            return t - stage.started_s >= stage.duration_s
        if stage.kind == "direct":
            if self._guided is None or t - self._guided.received_s > self.settings.flight.guided_timeout_s:
                log.warning("GUIDED: no setpoint for %.1f s (GUID_TIMEOUT): braking to a hover",
                            self.settings.flight.guided_timeout_s)
                self._events.append(("text", 4, "GUIDED setpoint timeout: braking"))
                self._guided = None
                self._stages.insert(1, Stage("hold", target=self._brake_point()))
                return True
            return False
        return False  # land ends at touchdown

    def _setpoint(self, t: float) -> Setpoint:
        stage = self._stages[0] if self._stages else None
        if stage is None:
            target = self._hold_target()
            self._stages = [Stage("hold", target=target, started_s=t)]
            stage = self._stages[0]
        if stage.kind == "leg":
            pos, vel, acc = stage.leg.sample(t)
            self._ref_pos = pos
            return Setpoint(pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc, yaw_rad=self._yaw_hold_rad)
        if stage.kind == "hold":
            self._ref_pos = stage.target
            return Setpoint(pos_ned_m=stage.target, vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self._yaw_hold_rad)
        if stage.kind == "land":
            return land_setpoint(self, stage)
        if stage.kind == "direct" and self._guided is not None:
            sp = integrate_target(self._guided.setpoint, t - self._guided.received_s)
            if sp.yaw_rad is None and sp.yaw_rate_rad_s is None:
                sp = dataclasses.replace(sp, yaw_rad=self._yaw_hold_rad)
            if sp.pos_ned_m is not None:
                self._ref_pos = np.asarray(sp.pos_ned_m, dtype=float)
            else:
                self._ref_pos = None
            return sp
        return Setpoint(pos_ned_m=self._hold_target(), vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self._yaw_hold_rad)

    def _hold_target(self) -> np.ndarray:
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - self.pos_ned_m)) < 2.0:
            return np.asarray(self._ref_pos, dtype=float).copy()
        return self._brake_point()

    def _brake_point(self) -> np.ndarray:
        """Where the vehicle stops when braking at ``brake_accel_m_s2`` from its current velocity."""
        pos = self.pos_ned_m
        vel = self.vel_ned_m_s
        speed = float(np.linalg.norm(vel))
        stop = pos + vel * speed / (2.0 * self.settings.flight.brake_accel_m_s2)
        stop[2] = min(stop[2], 0.0)
        return stop

    def _fill_nan(self, target: np.ndarray) -> np.ndarray:
        base = self._hold_target()
        return np.where(np.isfinite(target), target, base)

    def _yaw_target(self, sp: Setpoint) -> float:
        if sp.yaw_rad is not None:
            return float(sp.yaw_rad)
        return self._yaw_hold_rad

    def _takeoff_stage(self, alt_m: float) -> Stage:
        """Climb straight up to ``alt_m`` above home."""
        pos = self.pos_ned_m
        down = self.frames.down_at_height_above_home(float(alt_m))
        return Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=0.5, vertical_only=True)

