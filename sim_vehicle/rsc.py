"""Rotor speed controller (RSC) and motor interlock of the helicopter, as ArduCopter heli has them.

ArduPilot's behaviour, checked against the reference firmware (``../shared/ardupilot``):

* **Interlock switch.** Aux function 32 (MOTOR_INTERLOCK), from the RC8 input or from
  MAV_CMD_DO_AUX_FUNCTION (218). An RC switch reads LOW below 1200 us, HIGH above 1800 us and
  MIDDLE in between; MIDDLE and HIGH mean *engaged*. The SITL's RC8 input is 1500 us, so the
  switch is engaged at start and arming is refused ("Arm: Motor Interlock Enabled") until it is
  set low. An RC override (RC_CHANNELS_OVERRIDE) lasts RC_OVERRIDE_TIME (3 s) after the last
  one; then RC8 falls back to its input (1500 us: engaged again).
* **Arming delay.** For ARMING_DELAY_SEC (2 s, a constant of ArduCopter) after arming the
  *effective* interlock stays off whatever the switch says (``Copter::motors_output``): the
  switch is accepted, but the rotor does not start and NAV_TAKEOFF is refused until then.
* **Run-up.** With the interlock on, the RSC output ramps to H_RSC_SETPOINT in H_RSC_RAMP_TIME
  (1 s; SERVO_OUTPUT_RAW servo 8) and the rotor speed estimate rises to full speed in
  H_RSC_RUNUP_TIME (``AP_MotorsHeli_RSC::update_rotor_runup``); the run-up is complete when both
  are full and stays complete until the speed falls below H_RSC_CRITICAL. A takeoff accepted
  earlier waits on the ground until then (the reference firmware: takeoff accepted 2.0 s after
  arming, climbing from 12.5 s). With the interlock off (or disarmed) both run down at the same
  rates.

Pure: no I/O, no clock; :func:`update` maps (state, inputs, dt) to the next state and
:class:`RotorControl` keeps one vehicle's rotor, switch and RC8 input between calls.
"""

from __future__ import annotations

import dataclasses
import math

from heli_common.ardupilot_ids import AUX_FUNCTION_MOTOR_INTERLOCK, SWITCH_HIGH, SWITCH_LOW, SWITCH_MIDDLE

SWITCH_NAMES = {SWITCH_LOW: "LOW", SWITCH_MIDDLE: "MIDDLE", SWITCH_HIGH: "HIGH"}
SWITCH_LOW_MAX_US = 1200
"""An RC input below this is LOW (``AUX_SWITCH_PWM_TRIGGER_LOW``)."""
SWITCH_HIGH_MIN_US = 1800
"""An RC input above this is HIGH (``AUX_SWITCH_PWM_TRIGGER_HIGH``)."""
ROTOR_CONTROL_MODES = {1: "RC passthrough", 2: "setpoint", 3: "throttle curve", 4: "governor"}
"""H_RSC_MODE values; the simulation runs every mode with the same run-up model."""
ROTOR_RPM_NOMINAL = 1500.0
"""Rotor speed at full run-up, rpm (ArduPilot's H_RSC_GOV_RPM default), for the RPM message."""


@dataclasses.dataclass(frozen=True)
class RscSettings:
    """Rotor speed controller and interlock (ArduPilot parameter in brackets).

    Attributes
    ----------
    mode : int
        Rotor control mode 1..4 [H_RSC_MODE]; every mode runs up the same way here.
    runup_time_s : float
        Time from rest to full rotor speed, simulated s [H_RSC_RUNUP_TIME].
    ramp_time_s : float
        Time of the RSC output ramp from rest to the setpoint, simulated s [H_RSC_RAMP_TIME].
    critical_pct : float
        Below this rotor speed (percent) the run-up counts as incomplete again [H_RSC_CRITICAL].
    setpoint_pct : float
        RSC output at full speed, percent; SERVO_OUTPUT_RAW servo 8 shows it [H_RSC_SETPOINT].
    arming_delay_s : float
        The effective interlock stays off this long after arming, simulated s (ArduCopter's
        compile-time constant ARMING_DELAY_SEC; not a MAVLink parameter there either).
    rc_override_timeout_s : float
        An RC8 override is dropped this long after the last RC_CHANNELS_OVERRIDE, simulated s
        [RC_OVERRIDE_TIME].
    rc8_input_us : int
        RC8 when not overridden: the SITL's stick input, 1500 us (MIDDLE: interlock engaged).
    """

    mode: int = 2
    runup_time_s: float = 10.0
    ramp_time_s: float = 1.0
    critical_pct: float = 50.0
    setpoint_pct: float = 66.0
    arming_delay_s: float = 2.0
    rc_override_timeout_s: float = 3.0
    rc8_input_us: int = 1500

    def __post_init__(self) -> None:
        if self.mode not in ROTOR_CONTROL_MODES:
            raise ValueError(f"mode: expected one of {sorted(ROTOR_CONTROL_MODES)}, got {self.mode!r}")
        for name, lo, hi in (
            ("runup_time_s", 0.5, 60.0),
            ("ramp_time_s", 0.0, 60.0),
            ("critical_pct", 0.0, 100.0),
            ("setpoint_pct", 0.0, 100.0),
            ("arming_delay_s", 0.0, 60.0),
            ("rc_override_timeout_s", 0.1, 120.0),
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"{name}: expected {lo:g}..{hi:g}, got {value!r}")
        if not 800 <= self.rc8_input_us <= 2200:
            raise ValueError(f"rc8_input_us: expected 800..2200, got {self.rc8_input_us!r}")


@dataclasses.dataclass(frozen=True)
class RotorState:
    """The rotor and its interlock.

    Attributes
    ----------
    switch_engaged : bool
        The interlock switch (RC8 / DO_AUX_FUNCTION 32) asks for the rotor to run.
    interlock : bool
        Effective motor interlock: armed, past the arming delay and the switch engaged.
    speed : float
        Rotor speed estimate, fraction of full speed in [0, 1].
    runup_complete : bool
        The rotor has reached full speed (and not fallen below the critical speed since).
    ramp : float
        RSC output ramp, fraction of H_RSC_SETPOINT in [0, 1].
    """

    switch_engaged: bool = True
    interlock: bool = False
    speed: float = 0.0
    runup_complete: bool = False
    ramp: float = 0.0

    def above_critical(self, settings: RscSettings) -> bool:
        """True while the rotor turns faster than H_RSC_CRITICAL (no auto-disarm then)."""
        return self.speed > settings.critical_pct / 100.0


def switch_position(pwm_us: float) -> int:
    """Aux switch position of an RC input: LOW < 1200 us < MIDDLE < 1800 us < HIGH."""
    if pwm_us < SWITCH_LOW_MAX_US:
        return SWITCH_LOW
    if pwm_us > SWITCH_HIGH_MIN_US:
        return SWITCH_HIGH
    return SWITCH_MIDDLE


def engages(position: int) -> bool:
    """True if the interlock switch in ``position`` engages the interlock (MIDDLE or HIGH)."""
    return position in (SWITCH_MIDDLE, SWITCH_HIGH)


def rc8_pwm_us(override_us: int | None, override_age_s: float, settings: RscSettings) -> int:
    """RC8 now: the override while it is fresh, else the RC input (``rc8_input_us``)."""
    if override_us is not None and override_age_s <= settings.rc_override_timeout_s:
        return int(override_us)
    return settings.rc8_input_us


def update(state: RotorState, *, armed: bool, armed_for_s: float, dt_s: float, settings: RscSettings) -> RotorState:
    """The rotor ``dt_s`` later.

    Parameters
    ----------
    state : RotorState
        Now.
    armed : bool
        Motors armed.
    armed_for_s : float
        Simulated time since arming, s (ignored when disarmed).
    dt_s : float
        Time step, simulated s (>= 0).
    settings : RscSettings
        Run-up time, critical speed, arming delay.

    Returns
    -------
    RotorState
        With the effective interlock, the new speed estimate and the run-up flag.
    """
    interlock = armed and armed_for_s >= settings.arming_delay_s and state.switch_engaged
    target = 1.0 if interlock else 0.0
    dt_s = max(dt_s, 0.0)
    speed = _approach(state.speed, target, dt_s / settings.runup_time_s)
    ramp = _approach(state.ramp, target, dt_s / settings.ramp_time_s if settings.ramp_time_s > 0 else 1.0)
    complete = state.runup_complete
    if not complete and interlock and speed >= 1.0 and ramp >= 1.0:
        complete = True
    if complete and speed <= settings.critical_pct / 100.0:
        complete = False
    return RotorState(state.switch_engaged, interlock, speed, complete, ramp)


def _approach(value: float, target: float, step: float) -> float:
    return min(target, value + step) if value < target else max(target, value - step)


def with_switch(state: RotorState, engaged: bool) -> RotorState:
    """The same rotor with the interlock switch set to ``engaged``."""
    return dataclasses.replace(state, switch_engaged=bool(engaged))


class RotorControl:
    """The rotor of one vehicle with its interlock switch and RC8 input.

    Holds the :class:`RotorState`, the RC8 override and the arming time, and advances the rotor
    with :func:`update`. An RC switch acts when it *moves* (as ArduPilot's aux switches do) and
    is announced with ArduPilot's STATUSTEXT "RC8: MotorInterlock LOW|MIDDLE|HIGH";
    DO_AUX_FUNCTION acts at once, silently.

    Parameters
    ----------
    settings : RscSettings
        Run-up, arming delay, RC8 input and override timeout.
    """

    SEVERITY_WARNING = 4
    SEVERITY_INFO = 6

    def __init__(self, settings: RscSettings) -> None:
        self.settings = settings
        self.armed_at_s = 0.0
        self._override_us: int | None = None
        self._override_s = 0.0
        self.rc8_position = switch_position(settings.rc8_input_us)
        self.state = RotorState(switch_engaged=engages(self.rc8_position))

    def rc8_us(self, now_s: float) -> int:
        """RC8 now, us."""
        return rc8_pwm_us(self._override_us, now_s - self._override_s, self.settings)

    def rc_override(self, chan8_us: int, now_s: float) -> None:
        """RC_CHANNELS_OVERRIDE of RC8 (0 releases it back to the RC input)."""
        self._override_us = None if chan8_us == 0 else int(chan8_us)
        self._override_s = now_s

    def set_switch(self, position: int, flying: bool) -> tuple[bool, str]:
        """Interlock switch to LOW (0), MIDDLE (1) or HIGH (2); returns ``(accepted, reason)``.

        Refused only when it would stop the rotor in flight (ArduPilot lets the rotor run down;
        the simulated vehicle cannot autorotate).
        """
        if position not in SWITCH_NAMES:
            return False, f"switch position {position!r}: expected 0 (low), 1 (middle) or 2 (high)"
        engaged = engages(position)
        if not engaged and flying:
            return False, "Motor interlock: cannot disengage in flight (sim)"
        self.state = with_switch(self.state, engaged)
        return True, ""

    def armed(self, now_s: float) -> None:
        """The motors were armed now (the arming delay starts)."""
        self.armed_at_s = now_s

    def tick(self, now_s: float, dt_s: float, armed: bool, flying: bool) -> list[tuple[int, str]]:
        """Read RC8, advance the rotor ``dt_s``; returns ``(severity, text)`` messages to send."""
        texts = []
        position = switch_position(self.rc8_us(now_s))
        if position != self.rc8_position:
            self.rc8_position = position
            ok, reason = self.set_switch(position, flying)
            texts.append(
                (self.SEVERITY_INFO, f"RC8: MotorInterlock {SWITCH_NAMES[position]}")
                if ok
                else (self.SEVERITY_WARNING, reason)
            )
        self.state = update(
            self.state, armed=armed, armed_for_s=now_s - self.armed_at_s, dt_s=dt_s, settings=self.settings
        )
        return texts


def output_pwm_us(state: RotorState, settings: RscSettings) -> int:
    """RSC output (SERVO_OUTPUT_RAW servo 8): 1000 us at rest, H_RSC_SETPOINT once ramped up."""
    return int(round(1000.0 + 10.0 * settings.setpoint_pct * state.ramp))


__all__ = [
    "RscSettings",
    "RotorState",
    "RotorControl",
    "update",
    "with_switch",
    "switch_position",
    "engages",
    "rc8_pwm_us",
    "output_pwm_us",
    "AUX_FUNCTION_MOTOR_INTERLOCK",
    "SWITCH_LOW",
    "SWITCH_MIDDLE",
    "SWITCH_HIGH",
    "SWITCH_NAMES",
    "ROTOR_RPM_NOMINAL",
]
