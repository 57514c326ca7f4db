"""Ground contact: lift-off, touchdown, sitting on the ground and ArduCopter heli's auto-disarm.

Flat ground at the start altitude (``down = 0`` of the ground frame, :mod:`sim_vehicle.frames`):
the vehicle cannot go below it (the pure update stops it, :mod:`heli_model.vehicle_update`),
sits still on it while disarmed or idle, and a landing disarms on touchdown. A vehicle told to
climb waits on the ground until the rotor has run up (H_RSC_RUNUP_TIME).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from sim_vehicle import rsc
from sim_vehicle.autopilot.legs import GuidedCommand, Stage
from sim_vehicle.autopilot.mode import AUTO
from sim_vehicle.config import VehicleSettings

log = logging.getLogger(__name__)

LIFTOFF_HEIGHT_M = 0.2
"""Height above ground at which a climbing vehicle counts as airborne."""
TOUCHDOWN_HEIGHT_M = 0.03
"""Height below which a descending vehicle counts as landed."""


class Body(Protocol):
    """The airframe as the land detector uses it (:class:`~sim_vehicle.autopilot.airframe.Airframe`)."""

    @property
    def height_m(self) -> float:
        """Height above the ground, m."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame."""

    def settle_on_ground(self) -> None:
        """Put the vehicle at rest on the ground below it."""

    def reset_controller(self, zero_inputs: bool = False) -> None:
        """Reset the flight controller (and the rotor inputs held)."""


class Stages(Protocol):
    """The stage runner as the land detector uses it (:class:`~sim_vehicle.autopilot.navigation.Navigation`)."""

    guided: GuidedCommand | None

    @property
    def current_stage(self) -> Stage | None:
        """The stage flown now."""

    def pop_stage(self) -> Stage:
        """Remove the current stage and return it."""


class Rotor(Protocol):
    """Arming and the rotor (:class:`~sim_vehicle.autopilot.arming.Arming`)."""

    @property
    def armed(self) -> bool:
        """True while armed."""

    @property
    def rotor(self) -> rsc.RotorState:
        """Interlock and rotor run-up now."""


class Host(Protocol):
    """What the land detector reads of the vehicle and asks of it (:class:`~sim_vehicle.autopilot.Autopilot`)."""

    @property
    def mode(self) -> int:
        """ArduCopter mode number now."""

    @property
    def time_s(self) -> float:
        """Simulated time, s."""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        """Disarm."""


class GroundContact:
    """The land detector (ArduCopter's ``land_detector.cpp``): the one owner of :attr:`landed`.

    Parameters
    ----------
    body : Body
        Height and position; settles the vehicle on the ground.
    stages : Stages
        The current stage and GUIDED setpoint (do they ask to climb, or to touch down?).
    rotor : Rotor
        Armed, interlock and rotor run-up.
    host : Host
        Mode, clock, and the disarm of a landing or of the auto-disarm.
    settings : callable () -> VehicleSettings
        The settings in use (DISARM_DELAY, H_RSC_CRITICAL).
    on_land_stage_done : callable () -> None
        Called when a touchdown ends a ``land`` stage, before the disarm (a NAV_LAND item is complete).

    Attributes
    ----------
    landed : bool
        True while on the ground.
    """

    def __init__(
        self,
        body: Body,
        stages: Stages,
        rotor: Rotor,
        host: Host,
        settings: Callable[[], VehicleSettings],
        on_land_stage_done: Callable[[], None],
    ) -> None:
        self._body = body
        self._stages = stages
        self._rotor = rotor
        self._host = host
        self._settings = settings
        self._on_land_stage_done = on_land_stage_done
        self.landed = True
        self._landed_since_s = 0.0

    def restart_idle_timer(self, t: float) -> None:
        """The auto-disarm's idle time counts from ``t`` (arming)."""
        self._landed_since_s = t

    def after_physics_step(self) -> None:
        """After a physics step (the ground already stopped the vehicle): lift-off or touchdown."""
        height = self._body.height_m
        if self.landed and height > LIFTOFF_HEIGHT_M:
            self.landed = False
            log.info("airborne")
        elif not self.landed and height < TOUCHDOWN_HEIGHT_M and self._descending_to_ground():
            self._touchdown()

    def _descending_to_ground(self) -> bool:
        stage = self._stages.current_stage
        if stage is None:
            return False
        if stage.kind == "land":
            return True
        guided = self._stages.guided
        if stage.kind == "direct" and guided is not None:
            sp = guided.setpoint
            if sp.pos_ned_m is not None and not math.isnan(sp.pos_ned_m[2]):
                return sp.pos_ned_m[2] >= -TOUCHDOWN_HEIGHT_M
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] > 0.0
        return stage.target is not None and stage.target[2] >= -TOUCHDOWN_HEIGHT_M

    def _touchdown(self) -> None:
        t = self._host.time_s
        self._landed_since_s = t
        self.settle()
        pos = self._body.pos_ned_m
        log.info("touchdown at N %.1f E %.1f", pos[0], pos[1])
        stage = self._stages.current_stage
        if stage is not None and stage.kind == "land":
            self._stages.pop_stage().arrived_s = t
            self._on_land_stage_done()
            self._host.disarm(reason="landed")

    def settle(self) -> None:
        """On the ground from now on, at rest below where the vehicle is (touchdown, disarm)."""
        self._body.settle_on_ground()
        self.landed = True

    def idle(self, t: float) -> None:
        """Sit on the ground; disarm as ArduCopter heli's auto-disarm does.

        Never while the rotor turns above H_RSC_CRITICAL; after half of DISARM_DELAY when the
        interlock is off; otherwise after DISARM_DELAY (not in AUTO).
        """
        self._body.reset_controller(zero_inputs=True)
        settings = self._settings()
        delay = settings.flight.disarm_delay_s
        rotor = self._rotor.rotor
        if rotor.above_critical(settings.rsc):
            self._landed_since_s = t
            return
        interlock_off = not rotor.interlock
        if interlock_off:
            delay *= 0.5
        if delay > 0 and t - self._landed_since_s >= delay and (interlock_off or self._host.mode != AUTO):
            self._host.disarm(reason=f"landed and idle for {delay:g} s")

    def lifting_off(self) -> bool:
        """True when a landed vehicle is told to climb and its rotor has run up."""
        return self.climbing_stage() and self._rotor.rotor.runup_complete

    def climbing_stage(self) -> bool:
        """True when the current stage asks a landed vehicle to lift off."""
        stage = self._stages.current_stage
        if stage is None:
            return False
        if stage.kind in ("leg", "hold"):
            return stage.target is not None and stage.target[2] < -LIFTOFF_HEIGHT_M
        guided = self._stages.guided
        if stage.kind == "direct" and guided is not None:
            sp = guided.setpoint
            if sp.pos_ned_m is not None and sp.pos_ned_m[2] < -LIFTOFF_HEIGHT_M:
                return True
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] < -0.05
        return False

    @property
    def taking_off(self) -> bool:
        """True from lift-off until a takeoff has reached its altitude (MAV_LANDED_STATE_TAKEOFF).

        A vehicle waiting on the ground for its rotor to run up is still ON_GROUND, as in ArduPilot.
        """
        stage = self._stages.current_stage
        if not self._rotor.armed or stage is None:
            return False
        takeoff = stage.kind == "leg" and stage.vertical_only
        return takeoff and (not self.landed or self.lifting_off())
