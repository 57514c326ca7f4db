"""BRAKE: stop at ``brake_accel_m_s2`` and hold where the vehicle stopped (also a fence action)."""

from __future__ import annotations

from sim_vehicle.autopilot.mode import BRAKE, Mode


class ModeBrake(Mode):
    """BRAKE (17): brake to a hover and hold."""

    number = BRAKE
    accepts_condition_yaw = True
