"""What a flight mode may read of the vehicle and ask of it: the small interface the ``mode_*`` modules use.

As ArduCopter's modes act on ``copter`` through its public members, the modes here act on a
:class:`ModeContext`: the vehicle's state, and the parts of the navigation, the mission, the
land detector and the arming they need, each by its public methods. The
:class:`~sim_vehicle.autopilot.Autopilot` provides it. No mode module imports the core (no import
cycle, not even for type checking) or touches another object's private members.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from heli_model.control import Setpoint
from sim_vehicle import rsc
from sim_vehicle.autopilot.legs import GuidedCommand, Stage
from sim_vehicle.config import VehicleSettings
from sim_vehicle.frames import Frames


class NavigationForModes(Protocol):
    """The stage runner as the modes use it (:class:`~sim_vehicle.autopilot.navigation.Navigation`)."""

    guided: GuidedCommand | None
    yaw_hold_rad: float

    @property
    def current_stage(self) -> Stage | None:
        """The stage flown now."""

    def set_stages(self, stages: list[Stage]) -> None:
        """Fly these stages from now on."""

    def brake_point(self) -> np.ndarray:
        """Where braking now stops the vehicle, (3,) m NED."""

    def hold_target(self) -> np.ndarray:
        """Where to hold, (3,) m NED."""

    def fill_nan(self, target: np.ndarray) -> np.ndarray:
        """``target`` with its NaN axes from :meth:`hold_target`."""

    def yaw_target(self, sp: Setpoint) -> float:
        """The heading a setpoint asks for, rad."""

    def takeoff_stage(self, alt_m: float) -> Stage:
        """A vertical climb to ``alt_m`` above home."""


class MissionForModes(Protocol):
    """The mission sequencer as the modes use it (:class:`~sim_vehicle.autopilot.mission.Mission`)."""

    @property
    def has_mission(self) -> bool:
        """True if the mission holds a flyable item after the home item 0."""

    @property
    def rally_ned_m(self) -> list[np.ndarray]:
        """Rally points, each (3,) m NED."""

    def resume_seq(self) -> int:
        """Where AUTO (re)starts."""

    def start(self, seq: int) -> None:
        """Fly the mission from item ``seq``."""

    def advance(self, t_s: float) -> None:
        """Go on to the next item that has stages to fly."""


class GroundForModes(Protocol):
    """The land detector as the modes use it (:class:`~sim_vehicle.autopilot.ground_contact.GroundContact`)."""

    def climbing_stage(self) -> bool:
        """True when the current stage asks a landed vehicle to lift off."""


class ArmingForModes(Protocol):
    """Arming and rotor as the modes use them (:class:`~sim_vehicle.autopilot.arming.Arming`)."""

    @property
    def rotor(self) -> rsc.RotorState:
        """Interlock switch, effective interlock and rotor run-up now."""


class ModeContext(Protocol):
    """The vehicle as a flight mode sees it."""

    @property
    def mode(self) -> int:
        """ArduCopter mode number now."""

    @property
    def armed(self) -> bool:
        """True while armed."""

    @property
    def landed(self) -> bool:
        """True while on the ground."""

    @property
    def time_s(self) -> float:
        """Simulated time since start, s."""

    @property
    def settings(self) -> VehicleSettings:
        """The settings in use."""

    @property
    def frames(self) -> Frames:
        """Ground frame, EKF origin and home."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame."""

    @property
    def height_above_home_m(self) -> float:
        """Height above home, m."""

    @property
    def navigation(self) -> NavigationForModes:
        """The stages flown."""

    @property
    def mission(self) -> MissionForModes:
        """The mission and rally lists and their sequencer."""

    @property
    def ground(self) -> GroundForModes:
        """The land detector."""

    @property
    def arming(self) -> ArmingForModes:
        """Arming and the rotor."""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        """Disarm (refused in flight unless ``force``)."""
