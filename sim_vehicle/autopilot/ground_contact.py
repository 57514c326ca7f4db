"""Ground contact: lift-off, touchdown, sitting on the ground and ArduCopter heli's auto-disarm.

Flat ground at the start altitude (``down = 0`` of the ground frame, :mod:`sim_vehicle.frames`):
the vehicle cannot go below it (the pure update stops it, :mod:`heli_model.vehicle_update`),
sits still on it while disarmed or idle, and a landing disarms on touchdown. A vehicle told to
climb waits on the ground until the rotor has run up (H_RSC_RUNUP_TIME).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from heli_model import dynamics
from sim_vehicle.autopilot.mode import AUTO

log = logging.getLogger(__name__)

LIFTOFF_HEIGHT_M = 0.2
"""Height above ground at which a climbing vehicle counts as airborne."""
TOUCHDOWN_HEIGHT_M = 0.03
"""Height below which a descending vehicle counts as landed."""


class GroundContactMixin:
    """The Autopilot's land detector (state: ``landed``, ``_landed_since_s``)."""

    def _ground_contact(self) -> None:
        """After a physics step (the ground already stopped the vehicle): lift-off or touchdown."""
        height = -float(self.x[16])
        if self.landed and height > LIFTOFF_HEIGHT_M:
            self.landed = False
            log.info("airborne")
        elif not self.landed and height < TOUCHDOWN_HEIGHT_M and self._descending_to_ground():
            self._touchdown()

    def _descending_to_ground(self) -> bool:
        if not self._stages:
            return False
        stage = self._stages[0]
        if stage.kind == "land":
            return True
        if stage.kind == "direct" and self._guided is not None:
            sp = self._guided.setpoint
            if sp.pos_ned_m is not None and not math.isnan(sp.pos_ned_m[2]):
                return sp.pos_ned_m[2] >= -TOUCHDOWN_HEIGHT_M
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] > 0.0
        return stage.target is not None and stage.target[2] >= -TOUCHDOWN_HEIGHT_M

    def _touchdown(self) -> None:
        self.landed = True
        self._landed_since_s = self.time_s
        self._settle_on_ground()
        log.info("touchdown at N %.1f E %.1f", self.x[14], self.x[15])
        if self._stages and self._stages[0].kind == "land":
            stage = self._stages.pop(0)
            stage.arrived_s = self.time_s
            if self.mode == AUTO and self._item_active:
                self._complete_item()
            self.disarm(reason="landed")

    def _settle_on_ground(self) -> None:
        n, e, psi = float(self.x[14]), float(self.x[15]), float(self.x[dynamics.IDX_PSI])
        x = dynamics.hover_state(self.model, (n, e, 0.0), psi)  # a forced disarm in flight drops it
        self.landed = True
        self.vehicle_state = self.vehicle.reset_controller(self.vehicle_state._replace(x=x, delta=np.zeros(4)))

    def _idle_on_ground(self, t: float) -> None:
        """Sit on the ground; disarm as ArduCopter heli's auto-disarm does.

        Never while the rotor turns above H_RSC_CRITICAL; after half of DISARM_DELAY when the
        interlock is off; otherwise after DISARM_DELAY (not in AUTO).
        """
        self.vehicle_state = self.vehicle.reset_controller(self.vehicle_state._replace(delta=np.zeros(4)))
        delay = self.settings.flight.disarm_delay_s
        if self.rotor.above_critical(self.settings.rsc):
            self._landed_since_s = t
            return
        interlock_off = not self.rotor.interlock
        if interlock_off:
            delay *= 0.5
        if delay > 0 and t - self._landed_since_s >= delay and (interlock_off or self.mode != AUTO):
            self.disarm(reason=f"landed and idle for {delay:g} s")

    def _lifting_off(self) -> bool:
        """True when a landed vehicle is told to climb and its rotor has run up."""
        return self._climbing_stage() and self.rotor.runup_complete

    def _climbing_stage(self) -> bool:
        """True when the current stage asks a landed vehicle to lift off."""
        if not self._stages:
            return False
        stage = self._stages[0]
        if stage.kind in ("leg", "hold"):
            return stage.target is not None and stage.target[2] < -LIFTOFF_HEIGHT_M
        if stage.kind == "direct" and self._guided is not None:
            sp = self._guided.setpoint
            if sp.pos_ned_m is not None and sp.pos_ned_m[2] < -LIFTOFF_HEIGHT_M:
                return True
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] < -0.05
        return False

    @property
    def taking_off(self) -> bool:
        """True from lift-off until a takeoff has reached its altitude (MAV_LANDED_STATE_TAKEOFF).

        A vehicle waiting on the ground for its rotor to run up is still ON_GROUND, as in ArduPilot.
        """
        if not self.armed or not self._stages:
            return False
        stage = self._stages[0]
        takeoff = stage.kind == "leg" and stage.vertical_only
        return takeoff and (not self.landed or self._lifting_off())
