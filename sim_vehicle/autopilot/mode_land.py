"""LAND: descend where the vehicle is, at LAND_SPEED_HIGH then LAND_SPEED below LAND_ALT_LOW; disarm on touchdown."""

from __future__ import annotations

from typing import TYPE_CHECKING

from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import LAND, Mode
from heli_model.control import Setpoint

if TYPE_CHECKING:
    from sim_vehicle.autopilot.core import Autopilot


class ModeLand(Mode):
    """LAND (9): a ``land`` stage until touchdown (:mod:`sim_vehicle.autopilot.ground_contact`)."""

    number = LAND

    def arming_refusal(self, ap: Autopilot) -> str | None:
        return f"cannot arm in {self.name}"

    def enter(self, ap: Autopilot) -> None:
        ap._stages = [Stage("land")]

    def enter_landed(self, ap: Autopilot) -> None:
        ap.disarm(reason="LAND on the ground")
        ap._stages = []


def land_setpoint(ap: Autopilot, stage: Stage) -> Setpoint:
    """Descent of a ``land`` stage (LAND, the end of RTL, a NAV_LAND item): over its target, vertical speed only."""
    f = ap.settings.flight
    height = -float(ap.x[16])
    speed = f.land_speed_high_m_s if height > f.land_slow_alt_m else f.land_speed_m_s
    target = stage.target
    return Setpoint(pos_ned_m=(target[0], target[1], float("nan")), vel_ned_m_s=(0.0, 0.0, speed),
                    yaw_rad=ap._yaw_hold_rad)
