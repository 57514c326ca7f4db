"""LAND: descend where the vehicle is, at LAND_SPEED_HIGH then LAND_SPEED below LAND_ALT_LOW; disarm on touchdown."""

from __future__ import annotations

from heli_model.control import Setpoint
from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import LAND, Mode
from sim_vehicle.autopilot.mode_context import ModeContext
from sim_vehicle.config import FlightSettings


class ModeLand(Mode):
    """LAND (9): a ``land`` stage until touchdown (:mod:`sim_vehicle.autopilot.ground_contact`)."""

    number = LAND

    def arming_refusal(self, ap: ModeContext) -> str | None:
        return f"cannot arm in {self.name}"

    def enter(self, ap: ModeContext) -> None:
        ap.navigation.set_stages([Stage("land")])

    def enter_landed(self, ap: ModeContext) -> None:
        ap.disarm(reason="LAND on the ground")
        ap.navigation.set_stages([])


def land_setpoint(stage: Stage, height_m: float, flight: FlightSettings, yaw_rad: float) -> Setpoint:
    """Descent of a ``land`` stage (LAND, the end of RTL, a NAV_LAND item): over its target, vertical speed only.

    ``height_m`` is the height above the ground: LAND_SPEED_HIGH above ``flight.land_slow_alt_m``,
    LAND_SPEED below; the heading ``yaw_rad`` is held.
    """
    speed = flight.land_speed_high_m_s if height_m > flight.land_slow_alt_m else flight.land_speed_m_s
    target = stage.target
    return Setpoint(pos_ned_m=(target[0], target[1], float("nan")), vel_ned_m_s=(0.0, 0.0, speed), yaw_rad=yaw_rad)
