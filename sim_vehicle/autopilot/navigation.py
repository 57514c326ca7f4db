"""Navigation: the stages the vehicle flies (legs, holds, landing, direct setpoints) and their setpoints.

Every control tick the current stage is started (its leg built from where the reference is),
finished when done (a leg when its profile has arrived within the acceptance radius, a hold
after its time, a direct GUIDED stage after GUID_TIMEOUT without a setpoint) and turned into the
:class:`~heli_model.control.Setpoint` the flight controller tracks. Holds keep the heading in
:attr:`Navigation.yaw_hold_rad`; a vehicle told to stop brakes at ``brake_accel_m_s2``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from heli_model.control import Setpoint
from sim_vehicle.autopilot.legs import GuidedCommand, Leg, Stage
from sim_vehicle.autopilot.mode_guided import integrate_target
from sim_vehicle.autopilot.mode_land import land_setpoint
from sim_vehicle.config import VehicleSettings
from sim_vehicle.frames import Frames

log = logging.getLogger(__name__)


class Body(Protocol):
    """Where the vehicle is (:class:`~sim_vehicle.autopilot.airframe.Airframe`)."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame."""

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        """Ground velocity, (3,) m/s NED."""

    @property
    def height_m(self) -> float:
        """Height above the ground, m."""


class Navigation:
    """The stage runner (ArduPilot's ``AC_WPNav``): the one owner of the stages flown.

    Parameters
    ----------
    body : Body
        Position and velocity of the vehicle.
    frames : Frames
        Home and the ground frame (takeoff altitudes are above home).
    settings : callable () -> VehicleSettings
        The settings in use (``flight``: WPNAV speeds, radius, brake deceleration, GUID_TIMEOUT).
    emit : callable (event tuple) -> None
        Reports an event of :meth:`Autopilot.step <sim_vehicle.autopilot.Autopilot.step>`.
    yaw_rad : float
        Initial heading held.

    Attributes
    ----------
    guided : GuidedCommand or None
        The direct GUIDED setpoint flown by a ``direct`` stage.
    yaw_hold_rad : float
        Heading held by legs, holds and landings (and direct setpoints without a yaw).
    """

    def __init__(
        self,
        body: Body,
        frames: Frames,
        settings: Callable[[], VehicleSettings],
        emit: Callable[[tuple], None],
        yaw_rad: float,
    ) -> None:
        self._body = body
        self._frames = frames
        self._settings = settings
        self._emit = emit
        self._stages: list[Stage] = []
        self._ref_pos: np.ndarray | None = None
        self._speed_override_m_s: float | None = None
        self.guided: GuidedCommand | None = None
        self.yaw_hold_rad = yaw_rad

    # ------------------------------------------------------------------ the stages
    @property
    def current_stage(self) -> Stage | None:
        """The stage flown now (None when there is none)."""
        return self._stages[0] if self._stages else None

    def set_stages(self, stages: list[Stage]) -> None:
        """Fly these stages from now on (an empty list: nothing)."""
        self._stages = stages

    def pop_stage(self) -> Stage:
        """Remove the current stage (a ``land`` stage at touchdown) and return it."""
        return self._stages.pop(0)

    def clear(self) -> None:
        """Nothing to fly and no GUIDED setpoint (disarmed)."""
        self._stages = []
        self.guided = None

    def hold_after_error(self, landed: bool) -> None:
        """After an internal error: forget the reference and setpoint; brake to a hover (nothing on the ground)."""
        self.guided = None
        self._ref_pos = None
        self._stages = [] if landed else [Stage("hold", target=self.brake_point())]

    @property
    def landing(self) -> bool:
        """True while descending to land (LAND, the end of RTL, a NAV_LAND item)."""
        return bool(self._stages) and self._stages[0].kind == "land"

    # ------------------------------------------------------------------ speed
    def change_speed(self, speed_m_s: float | None) -> tuple[bool, str]:
        """MAV_CMD_DO_CHANGE_SPEED: horizontal leg speed from now on (None = back to WPNAV_SPEED)."""
        if speed_m_s is None:
            self._speed_override_m_s = None
            return True, ""
        limit = self._settings().flight.max_speed_m_s
        if not math.isfinite(speed_m_s) or not 0.1 <= speed_m_s <= limit:
            return False, f"speed {speed_m_s!r} outside 0.1..{limit:g} m/s"
        self._speed_override_m_s = float(speed_m_s)
        log.info("speed set to %.1f m/s", speed_m_s)
        return True, ""

    def use_speed(self, speed_m_s: float) -> None:
        """The horizontal leg speed of a mission's DO_CHANGE_SPEED (already within the limit)."""
        self._speed_override_m_s = speed_m_s

    @property
    def speed_m_s(self) -> float:
        """Current horizontal leg speed (DO_CHANGE_SPEED or WPNAV_SPEED), m/s."""
        if self._speed_override_m_s is not None:
            return self._speed_override_m_s
        return self._settings().flight.wp_speed_m_s

    def _speed_xy(self, stage: Stage) -> float:
        return stage.speed_xy_m_s if stage.speed_xy_m_s is not None else self.speed_m_s

    # ------------------------------------------------------------------ every control tick
    def advance(self, t: float) -> bool:
        """Start the current stage, finish it when done, go on to the next.

        Returns
        -------
        emptied : bool
            True when the last stage has just finished (a mission item may be complete).
        """
        while self._stages:
            stage = self._stages[0]
            if stage.started_s is None:
                self._start(stage, t)
            if not self._stage_done(stage, t):
                return False
            self._stages.pop(0)
            if stage.kind in ("leg", "hold") and stage.target is not None:
                self._ref_pos = stage.target.copy()
            if not self._stages:
                return True
        return False

    def _start(self, stage: Stage, t: float) -> None:
        stage.started_s = t
        if stage.kind == "leg":
            f = self._settings().flight
            up = f.takeoff_speed_m_s if stage.vertical_only else f.wp_speed_up_m_s
            stage.leg = Leg(
                self._leg_start(), stage.target, self._speed_xy(stage), up, f.wp_speed_down_m_s, f.wp_accel_m_s2, t
            )
        elif stage.kind == "hold" and stage.target is None:
            stage.target = self.hold_target()
        elif stage.kind == "land":
            stage.target = self._leg_start()

    def _leg_start(self) -> np.ndarray:
        pos = self._body.pos_ned_m
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - pos)) < 2.0:
            return self._ref_pos.copy()
        return pos

    def _stage_done(self, stage: Stage, t: float) -> bool:
        f = self._settings().flight
        if stage.kind == "leg":
            if not stage.leg.finished(t):
                return False
            radius = stage.radius_m if stage.radius_m > 0 else f.wp_radius_m
            return not float(np.linalg.norm(self._body.pos_ned_m - stage.target)) > radius
        if stage.kind == "hold":
            if stage.duration_s is None:
                return False
            return t - stage.started_s >= stage.duration_s
        if stage.kind == "direct":
            if self.guided is None or t - self.guided.received_s > f.guided_timeout_s:
                log.warning("GUIDED: no setpoint for %.1f s (GUID_TIMEOUT): braking to a hover", f.guided_timeout_s)
                self._emit(("text", 4, "GUIDED setpoint timeout: braking"))
                self.guided = None
                self._stages.insert(1, Stage("hold", target=self.brake_point()))
                return True
            return False
        return False  # land ends at touchdown

    def setpoint(self, t: float) -> Setpoint:
        """What the flight controller tracks now (a hold where the vehicle is when there is no stage)."""
        stage = self._stages[0] if self._stages else None
        if stage is None:
            target = self.hold_target()
            self._stages = [Stage("hold", target=target, started_s=t)]
            stage = self._stages[0]
        if stage.kind == "leg":
            pos, vel, acc = stage.leg.sample(t)
            self._ref_pos = pos
            return Setpoint(pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc, yaw_rad=self.yaw_hold_rad)
        if stage.kind == "hold":
            self._ref_pos = stage.target
            return Setpoint(pos_ned_m=stage.target, vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self.yaw_hold_rad)
        if stage.kind == "land":
            return land_setpoint(stage, self._body.height_m, self._settings().flight, self.yaw_hold_rad)
        if stage.kind == "direct" and self.guided is not None:
            return self._direct_setpoint(self.guided, t)
        return Setpoint(pos_ned_m=self.hold_target(), vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self.yaw_hold_rad)

    def _direct_setpoint(self, guided: GuidedCommand, t: float) -> Setpoint:
        sp = integrate_target(guided.setpoint, t - guided.received_s)
        if sp.yaw_rad is None and sp.yaw_rate_rad_s is None:
            sp = dataclasses.replace(sp, yaw_rad=self.yaw_hold_rad)
        self._ref_pos = None if sp.pos_ned_m is None else np.asarray(sp.pos_ned_m, dtype=float)
        return sp

    # ------------------------------------------------------------------ targets
    def hold_target(self) -> np.ndarray:
        """Where to hold: the reference when the vehicle is near it, else the brake point. (3,) m NED."""
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - self._body.pos_ned_m)) < 2.0:
            return np.asarray(self._ref_pos, dtype=float).copy()
        return self.brake_point()

    def brake_point(self) -> np.ndarray:
        """Where the vehicle stops when braking at ``brake_accel_m_s2`` from its current velocity, (3,) m NED."""
        pos = self._body.pos_ned_m
        vel = self._body.vel_ned_m_s
        speed = float(np.linalg.norm(vel))
        stop = pos + vel * speed / (2.0 * self._settings().flight.brake_accel_m_s2)
        stop[2] = min(stop[2], 0.0)
        return stop

    def fill_nan(self, target: np.ndarray) -> np.ndarray:
        """``target`` (3,) with its NaN (not commanded) axes taken from :meth:`hold_target`."""
        base = self.hold_target()
        return np.where(np.isfinite(target), target, base)

    def yaw_target(self, sp: Setpoint) -> float:
        """The heading a setpoint asks for (the one held when it gives none), rad."""
        if sp.yaw_rad is not None:
            return float(sp.yaw_rad)
        return self.yaw_hold_rad

    def takeoff_stage(self, alt_m: float) -> Stage:
        """Climb straight up to ``alt_m`` above home."""
        pos = self._body.pos_ned_m
        down = self._frames.down_at_height_above_home(float(alt_m))
        return Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=0.5, vertical_only=True)
