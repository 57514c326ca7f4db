"""Arming, disarming, pre-arm checks and the rotor: ArduCopter heli's motor interlock and run-up.

The rotor speed controller and motor interlock are :mod:`sim_vehicle.rsc`: arming is refused
while the interlock switch (RC8, DO_AUX_FUNCTION 32) is engaged, the interlock takes effect
ARMING_DELAY_SEC after arming, NAV_TAKEOFF is refused until it has, and a vehicle told to climb
waits on the ground until the rotor has run up (H_RSC_RUNUP_TIME). While disarmed a failing
pre-arm check is reported every PREARM_REPORT_PERIOD_S. What arming does to the rest of the
vehicle (the mode's mission start, the controller reset) is the
:meth:`Autopilot.arm <sim_vehicle.autopilot.Autopilot.arm>` that calls :meth:`Arming.arm`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from heli_common.mavlink_ids import mavlink
from sim_vehicle import rsc
from sim_vehicle.config import VehicleSettings

log = logging.getLogger(__name__)

PREARM_REPORT_PERIOD_S = 30.0
"""While disarmed, a failing pre-arm check is reported this often (ArduPilot's PREARM_DISPLAY_PERIOD)."""
MAV_SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL


class Host(Protocol):
    """What arming reads of the vehicle (:class:`~sim_vehicle.autopilot.Autopilot`)."""

    @property
    def time_s(self) -> float:
        """Simulated time, s."""

    @property
    def landed(self) -> bool:
        """True while on the ground."""


class Arming:
    """Arming state, pre-arm checks and the rotor (ArduPilot's ``AP_Arming`` and heli RSC).

    Parameters
    ----------
    host : Host
        The clock and whether the vehicle is on the ground.
    settings : callable () -> VehicleSettings
        The settings in use (``flight.prearm_fail``); the rotor's are given to :meth:`apply_settings`.
    emit : callable (event tuple) -> None
        Reports an event of :meth:`Autopilot.step <sim_vehicle.autopilot.Autopilot.step>`.

    Attributes
    ----------
    armed : bool
        True while armed (the one owner of this state).
    rotor_control : sim_vehicle.rsc.RotorControl
        The rotor speed controller and motor interlock.
    """

    def __init__(self, host: Host, settings: Callable[[], VehicleSettings], emit: Callable[[tuple], None]) -> None:
        self._host = host
        self._settings = settings
        self._emit = emit
        self.armed = False
        self.rotor_control = rsc.RotorControl(settings().rsc)
        self._prearm_reported_s = 0.0

    def apply_settings(self, settings: VehicleSettings) -> None:
        """The rotor's settings after a PARAM_SET."""
        self.rotor_control.settings = settings.rsc

    @property
    def rotor(self) -> rsc.RotorState:
        """Interlock switch, effective interlock and rotor run-up now."""
        return self.rotor_control.state

    # ------------------------------------------------------------------ arming
    def arming_check(self, state_healthy: bool) -> str | None:
        """Why the vehicle may not arm (state estimate, SIM_PREARM_FAIL, interlock switch), or None."""
        if not state_healthy:
            return "state estimate not healthy"
        if self._settings().flight.prearm_fail:
            return "PreArm: simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return "Arm: Motor Interlock Enabled"
        return None

    def arm(self, t: float) -> None:
        """Armed from ``t`` (the checks passed): the motor interlock's ARMING_DELAY_SEC starts."""
        self.armed = True
        self.rotor_control.armed(t)

    def disarm(self) -> None:
        """Disarmed."""
        self.armed = False

    def prearm_failure(self) -> str | None:
        """The failing pre-arm check (as ArduPilot words it after "PreArm: "), or None."""
        if self._settings().flight.prearm_fail:
            return "simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return "Motor Interlock Enabled"
        return None

    def report_prearm(self, t: float) -> None:
        """While disarmed: a failing pre-arm check as a STATUSTEXT every PREARM_REPORT_PERIOD_S."""
        if t - self._prearm_reported_s < PREARM_REPORT_PERIOD_S:
            return
        self._prearm_reported_s = t
        failure = self.prearm_failure()
        if failure is not None:
            self._emit(("text", MAV_SEVERITY_CRITICAL, f"PreArm: {failure}"))

    # ------------------------------------------------------------------ rotor and interlock
    def set_interlock_switch(self, position: int) -> tuple[bool, str]:
        """MAV_CMD_DO_AUX_FUNCTION 32: interlock switch LOW (0), MIDDLE (1) or HIGH (2).

        Accepted at any time on the ground, as ArduPilot does (during ARMING_DELAY_SEC after
        arming it is stored and takes effect afterwards); refused in flight when it would stop
        the rotor.
        """
        engaged_before = self.rotor.switch_engaged
        ok, reason = self.rotor_control.set_switch(position, flying=self.armed and not self._host.landed)
        if ok and self.rotor.switch_engaged != engaged_before:
            log.info("motor interlock switch %s", "engaged" if self.rotor.switch_engaged else "released")
        return ok, reason

    def rc_override(self, chan8_us: int) -> None:
        """RC_CHANNELS_OVERRIDE of RC8 in us (0 releases it back to the RC input)."""
        self.rotor_control.rc_override(chan8_us, self._host.time_s)

    @property
    def rc8_us(self) -> int:
        """RC8 input now (the override while fresh, else the SITL's stick at 1500 us)."""
        return self.rotor_control.rc8_us(self._host.time_s)

    def update_rotor(self, dt_s: float) -> None:
        """One control period of the rotor speed controller and interlock."""
        was_complete = self.rotor.runup_complete
        flying = self.armed and not self._host.landed
        for severity, text in self.rotor_control.tick(self._host.time_s, dt_s, self.armed, flying):
            log.info("%s", text)
            self._emit(("text", severity, text))
        if self.rotor.runup_complete != was_complete:
            log.info("rotor run-up %s", "complete" if self.rotor.runup_complete else "lost (below H_RSC_CRITICAL)")
