"""GUIDED: takeoff, position targets flown as legs, and direct setpoints tracked with a timeout.

A position-only target (SET_POSITION_TARGET_*) is flown as a straight leg at WPNAV_SPEED and
held. A setpoint with velocity or acceleration is passed to the controller directly, moved on
by its own velocity and acceleration between two setpoints (:func:`integrate_target`); without a
new one for GUID_TIMEOUT (simulated s) the vehicle brakes to a hover. NAV_TAKEOFF climbs
straight up once the motor interlock is in effect and the rotor has run up.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from heli_model.control import Setpoint
from sim_vehicle.autopilot.legs import GuidedCommand, Stage
from sim_vehicle.autopilot.mode import GUIDED, Mode, QuietRefusal, mode_name
from sim_vehicle.autopilot.mode_context import ModeContext

log = logging.getLogger(__name__)

MAX_TAKEOFF_ALT_M = 1000.0


class ModeGuided(Mode):
    """GUIDED (4): takeoff, targets and setpoints from the companion or a GCS."""

    number = GUIDED
    accepts_condition_yaw = True

    def takeoff(self, ap: ModeContext, alt_m: float) -> tuple[bool, str]:
        """Takeoff to ``alt_m`` above home (see :meth:`Autopilot.takeoff`)."""
        ok, reason = self.takeoff_refusal(ap, alt_m)
        if not ok:
            return False, QuietRefusal(reason)
        ap.navigation.set_stages([ap.navigation.takeoff_stage(alt_m), Stage("hold")])
        log.info("takeoff to %.1f m%s", alt_m, "" if ap.arming.rotor.runup_complete else " once the rotor has run up")
        return True, ""

    def takeoff_refusal(self, ap: ModeContext, alt_m: float) -> tuple[bool, str]:
        """``(True, "")`` if a takeoff to ``alt_m`` is accepted now, else ``(False, why)``."""
        if not math.isfinite(alt_m) or not 0.5 <= alt_m <= MAX_TAKEOFF_ALT_M:
            return False, f"takeoff altitude {alt_m!r} m outside 0.5..{MAX_TAKEOFF_ALT_M:g}"
        if not ap.armed:
            return False, "not armed"
        if ap.mode != GUIDED:
            return False, f"takeoff needs GUIDED, mode is {mode_name(ap.mode)}"
        if not ap.landed:
            return False, "already flying"
        if alt_m <= ap.height_above_home_m:
            return False, f"takeoff altitude {alt_m:g} m is not above the vehicle"
        rotor = ap.arming.rotor
        if not rotor.interlock:
            return False, (
                "motor interlock not in effect yet (ARMING_DELAY_SEC after arming)"
                if rotor.switch_engaged
                else "motor interlock not engaged (RC8 or DO_AUX_FUNCTION 32)"
            )
        return True, ""

    def set_target(self, ap: ModeContext, setpoint: Setpoint) -> tuple[bool, str]:
        """A GUIDED target (see :meth:`Autopilot.set_guided_setpoint`)."""
        if ap.mode != GUIDED:
            return False, f"not in GUIDED (mode {mode_name(ap.mode)})"
        if not ap.armed:
            return False, "not armed"
        checked = check_setpoint(setpoint, ap.settings.flight.max_speed_m_s)
        if isinstance(checked, str):
            return False, checked
        if ap.landed and not ap.ground.climbing_stage():
            return False, "landed: take off first (MAV_CMD_NAV_TAKEOFF)"
        if checked.vel_ned_m_s is None and checked.acc_ned_m_s2 is None:
            return self._position_target(ap, checked)
        nav = ap.navigation
        nav.guided = GuidedCommand(checked, ap.time_s)
        if nav.current_stage is None or nav.current_stage.kind != "direct":
            nav.set_stages([Stage("direct")])
        return True, ""

    @staticmethod
    def _position_target(ap: ModeContext, checked: Setpoint) -> tuple[bool, str]:
        """A target without velocity or acceleration: a leg to it and a hold (or a turn on the spot)."""
        nav = ap.navigation
        if checked.pos_ned_m is None:  # yaw only: turn on the spot
            nav.yaw_hold_rad = nav.yaw_target(checked)
            target = nav.hold_target()
            nav.set_stages([Stage("hold", target=target)])
            return True, ""
        target = nav.fill_nan(np.asarray(checked.pos_ned_m, dtype=float))
        if checked.yaw_rad is not None or checked.yaw_rate_rad_s is not None:
            nav.yaw_hold_rad = nav.yaw_target(checked)
        current = nav.current_stage
        same = (
            current is not None
            and current.kind in ("leg", "hold")
            and current.target is not None
            and float(np.linalg.norm(current.target - target)) < 0.05
        )
        if not same:
            nav.set_stages([Stage("leg", target=target), Stage("hold", target=target)])
        nav.guided = None
        return True, ""


#: Longest time a GUIDED target is integrated forward (simulated s); beyond it the target stays.
TARGET_INTEGRATION_MAX_S = 0.5


def integrate_target(sp: Setpoint, age_s: float) -> Setpoint:
    """The target ``age_s`` after it was received, moved by its velocity and acceleration.

    As ArduCopter's GUIDED does with position-velocity-acceleration targets: between two
    setpoints (a companion at 50 Hz of wall clock feeds a sped-up simulation more slowly) the
    position target advances along ``vel * dt + acc * dt^2 / 2``, the velocity target along
    ``acc * dt`` and a heading given with a rate along ``yaw_rate * dt``, for at most
    ``TARGET_INTEGRATION_MAX_S``. Axes that are not commanded (None
    or NaN) are left as they are.
    """
    dt = min(max(age_s, 0.0), TARGET_INTEGRATION_MAX_S)
    if dt == 0.0 or sp.vel_ned_m_s is None:
        return sp
    vel = np.nan_to_num(np.asarray(sp.vel_ned_m_s, dtype=float))
    acc = np.zeros(3) if sp.acc_ned_m_s2 is None else np.nan_to_num(np.asarray(sp.acc_ned_m_s2, dtype=float))
    changes = {"vel_ned_m_s": np.asarray(sp.vel_ned_m_s, dtype=float) + acc * dt}
    if sp.yaw_rad is not None and sp.yaw_rate_rad_s is not None:
        changes["yaw_rad"] = float(sp.yaw_rad) + float(sp.yaw_rate_rad_s) * dt
    if sp.pos_ned_m is not None:
        changes["pos_ned_m"] = np.asarray(sp.pos_ned_m, dtype=float) + vel * dt + 0.5 * acc * dt * dt
    return dataclasses.replace(sp, **changes)


def check_setpoint(sp: Setpoint, max_speed_m_s: float) -> Setpoint | str:
    """Validate a GUIDED setpoint: finite (NaN = axis not commanded), plausible magnitudes."""
    out = {}
    for name in ("pos_ned_m", "vel_ned_m_s", "acc_ned_m_s2"):
        value = getattr(sp, name)
        if value is None:
            out[name] = None
            continue
        arr = np.asarray(value, dtype=float)
        if arr.shape != (3,) or np.any(np.isinf(arr)):
            return f"{name}: expected 3 finite numbers, got {value!r}"
        if np.all(np.isnan(arr)):
            out[name] = None
            continue
        out[name] = arr
    if out["pos_ned_m"] is not None and np.nanmax(np.abs(out["pos_ned_m"])) > 100_000.0:
        return "pos_ned_m: more than 100 km from home"
    if out["vel_ned_m_s"] is not None and np.nanmax(np.abs(out["vel_ned_m_s"])) > 2.0 * max_speed_m_s:
        return f"vel_ned_m_s: faster than {2.0 * max_speed_m_s:g} m/s"
    if out["acc_ned_m_s2"] is not None and np.nanmax(np.abs(out["acc_ned_m_s2"])) > 20.0:
        return "acc_ned_m_s2: more than 20 m/s^2"
    for name in ("yaw_rad", "yaw_rate_rad_s"):
        value = getattr(sp, name)
        if value is not None and not math.isfinite(float(value)):
            return f"{name}: expected a finite number, got {value!r}"
    return Setpoint(
        pos_ned_m=out["pos_ned_m"],
        vel_ned_m_s=out["vel_ned_m_s"],
        acc_ned_m_s2=out["acc_ned_m_s2"],
        yaw_rad=sp.yaw_rad,
        yaw_rate_rad_s=sp.yaw_rate_rad_s,
    )
