"""Arming, disarming, pre-arm checks and the rotor: ArduCopter heli's motor interlock and run-up.

The rotor speed controller and motor interlock are :mod:`sim_vehicle.rsc`: arming is refused
while the interlock switch (RC8, DO_AUX_FUNCTION 32) is engaged, the interlock takes effect
ARMING_DELAY_SEC after arming, NAV_TAKEOFF is refused until it has, and a vehicle told to climb
waits on the ground until the rotor has run up (H_RSC_RUNUP_TIME). While disarmed a failing
pre-arm check is reported every PREARM_REPORT_PERIOD_S.
"""

from __future__ import annotations

import logging

import numpy as np

from heli_common.mavlink_ids import mavlink

from heli_model import dynamics
from sim_vehicle import rsc
from sim_vehicle.autopilot.mode import mode_name

log = logging.getLogger(__name__)

PREARM_REPORT_PERIOD_S = 30.0
"""While disarmed, a failing pre-arm check is reported this often (ArduPilot's PREARM_DISPLAY_PERIOD)."""
MAV_SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL


class ArmingMixin:
    """The Autopilot's arming state (``armed``) and rotor (``rotor_control``)."""

    def arm(self) -> tuple[bool, str]:
        """Pre-arm checks, then arm. In AUTO the mission starts."""
        if self.armed:
            return True, "already armed"
        if not self.landed:
            return False, "not landed"
        refusal = self.flight_mode.arming_refusal(self)
        if refusal is not None:
            return False, refusal
        if not np.all(np.isfinite(self.x)):
            return False, "state estimate not healthy"
        if self.settings.flight.prearm_fail:
            return False, "PreArm: simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return False, "Arm: Motor Interlock Enabled"
        self.armed = True
        self.rotor_control.armed(self.time_s)
        self._landed_since_s = self.time_s
        self._yaw_hold_rad = float(self.x[dynamics.IDX_PSI])
        self.vehicle_state = self.vehicle.reset_controller(self.vehicle_state)
        self._stages = []
        self._events.append(("armed", ""))
        log.info("armed in %s", mode_name(self.mode))
        self.flight_mode.on_armed(self)
        return True, ""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        """Disarm; refused in flight unless ``force``."""
        if not self.armed:
            return True, "already disarmed"
        if not self.landed and not force:
            return False, "flying: land first (or force-disarm)"
        self.armed = False
        self._stages = []
        self._guided = None
        self._item_active = False
        self._settle_on_ground()
        self._events.append(("disarmed", reason))
        log.info("disarmed (%s)", reason)
        return True, ""


    @property
    def rotor(self) -> rsc.RotorState:
        """Interlock switch, effective interlock and rotor run-up now."""
        return self.rotor_control.state

    def set_interlock_switch(self, position: int) -> tuple[bool, str]:
        """MAV_CMD_DO_AUX_FUNCTION 32: interlock switch LOW (0), MIDDLE (1) or HIGH (2).

        Accepted at any time on the ground, as ArduPilot does (during ARMING_DELAY_SEC after
        arming it is stored and takes effect afterwards); refused in flight when it would stop
        the rotor.
        """
        engaged_before = self.rotor.switch_engaged
        ok, reason = self.rotor_control.set_switch(position, flying=self.armed and not self.landed)
        if ok and self.rotor.switch_engaged != engaged_before:
            log.info("motor interlock switch %s", "engaged" if self.rotor.switch_engaged else "released")
        return ok, reason

    def rc_override(self, chan8_us: int) -> None:
        """RC_CHANNELS_OVERRIDE of RC8 in us (0 releases it back to the RC input)."""
        self.rotor_control.rc_override(chan8_us, self.time_s)

    @property
    def rc8_us(self) -> int:
        """RC8 input now (the override while fresh, else the SITL's stick at 1500 us)."""
        return self.rotor_control.rc8_us(self.time_s)

    def _update_rotor(self, dt_s: float) -> None:
        was_complete = self.rotor.runup_complete
        for severity, text in self.rotor_control.tick(self.time_s, dt_s, self.armed, self.armed and not self.landed):
            log.info("%s", text)
            self._events.append(("text", severity, text))
        if self.rotor.runup_complete != was_complete:
            log.info("rotor run-up %s", "complete" if self.rotor.runup_complete else "lost (below H_RSC_CRITICAL)")

    def prearm_failure(self) -> str | None:
        """The failing pre-arm check (as ArduPilot words it after "PreArm: "), or None."""
        if self.settings.flight.prearm_fail:
            return "simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return "Motor Interlock Enabled"
        return None

    def _report_prearm(self, t: float) -> None:
        if t - self._prearm_reported_s < PREARM_REPORT_PERIOD_S:
            return
        self._prearm_reported_s = t
        failure = self.prearm_failure()
        if failure is not None:
            self._events.append(("text", MAV_SEVERITY_CRITICAL, f"PreArm: {failure}"))

