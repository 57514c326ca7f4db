"""STABILIZE and ALT_HOLD: with no RC pilot in the simulation, they brake to a hover and hold it like LOITER."""

from __future__ import annotations

from sim_vehicle.autopilot.mode import ALT_HOLD, STABILIZE, Mode


class ModeStabilize(Mode):
    """STABILIZE (0): no pilot sticks, so the vehicle holds its position; CONDITION_YAW is refused."""

    number = STABILIZE


class ModeAltHold(Mode):
    """ALT_HOLD (2): as STABILIZE, holding position as well as altitude."""

    number = ALT_HOLD
