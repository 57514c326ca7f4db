"""LOITER: brake to a hover and hold position; CONDITION_YAW turns the vehicle on the spot."""

from __future__ import annotations

from sim_vehicle.autopilot.mode import LOITER, Mode


class ModeLoiter(Mode):
    """LOITER (5): hold the position reached after braking."""

    number = LOITER
    accepts_condition_yaw = True
