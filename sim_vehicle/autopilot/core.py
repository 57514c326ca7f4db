"""The Autopilot: the simulated helicopter's autopilot, composed of its parts.

As ArduCopter's ``Copter`` holds its libraries as members (``AP_Arming``, ``AP_Mission``,
``AC_Fence``, ``AC_WPNav``...), :class:`Autopilot` holds one collaborator per concern, each
given what it needs at construction (state objects, the settings, callables, and the vehicle
itself through a small Protocol of the collaborator's module):

==================  ====================================================================
``airframe``        :class:`~sim_vehicle.autopilot.airframe.Airframe`: the pure vehicle
                    update (:mod:`heli_model.vehicle_update`), its state, the wind
``arming``          :class:`~sim_vehicle.autopilot.arming.Arming`: ``armed``, pre-arm
                    checks, the rotor and motor interlock
``navigation``      :class:`~sim_vehicle.autopilot.navigation.Navigation`: the stages flown
                    and their setpoints
``mission``         :class:`~sim_vehicle.autopilot.mission.Mission`: mission and rally
                    lists, the sequencer
``fence``           :class:`~sim_vehicle.autopilot.fence.Geofence`: the fence and its breach
                    action
``ground``          :class:`~sim_vehicle.autopilot.ground_contact.GroundContact`: ``landed``,
                    lift-off, touchdown, auto-disarm
==================  ====================================================================

The Autopilot itself keeps the mode, the clock and the events, switches modes, arms and
disarms (what that does to every part) and runs the simulation ticks. The flight modes
(``mode_*.py``) act on it through :class:`~sim_vehicle.autopilot.mode_context.ModeContext`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np

from heli_model import dynamics
from heli_model.control import Setpoint
from heli_model.model import HeliModel
from sim_vehicle.autopilot.airframe import Airframe
from sim_vehicle.autopilot.arming import Arming
from sim_vehicle.autopilot.fence import Geofence
from sim_vehicle.autopilot.ground_contact import GroundContact
from sim_vehicle.autopilot.mission import Mission
from sim_vehicle.autopilot.mode import AUTO, GUIDED, MODE_NAMES, STABILIZE, Mode, mode_name
from sim_vehicle.autopilot.mode_auto import ModeAuto
from sim_vehicle.autopilot.mode_brake import ModeBrake
from sim_vehicle.autopilot.mode_guided import ModeGuided
from sim_vehicle.autopilot.mode_land import ModeLand
from sim_vehicle.autopilot.mode_loiter import ModeLoiter
from sim_vehicle.autopilot.mode_rtl import ModeRTL
from sim_vehicle.autopilot.mode_stabilize import ModeAltHold, ModeStabilize
from sim_vehicle.autopilot.navigation import Navigation
from sim_vehicle.config import VehicleSettings
from sim_vehicle.frames import Frames

log = logging.getLogger(__name__)

#: The modes this vehicle flies, number -> mode object.
MODES: dict[int, Mode] = {
    m.number: m
    for m in (
        ModeStabilize(),
        ModeAltHold(),
        ModeAuto(),
        ModeGuided(),
        ModeLoiter(),
        ModeRTL(),
        ModeLand(),
        ModeBrake(),
    )
}
if set(MODES) != set(MODE_NAMES):
    raise RuntimeError("every mode of MODE_NAMES needs its mode object")


class Autopilot:
    """The simulated helicopter and its autopilot.

    Parameters
    ----------
    model : HeliModel
        The vehicle model.
    settings : VehicleSettings
        The settings tree (timing, flight, wind, controller).
    home_lla : tuple (lat_deg, lon_deg, alt_m, yaw_deg)
        Home position and initial heading; the vehicle starts there, landed and disarmed.
    rng : numpy.random.Generator
        Source of the wind gusts.
    origin_lla : tuple (lat_deg, lon_deg, alt_m), optional
        EKF origin, the frame of LOCAL_POSITION_NED (default: home).

    Attributes
    ----------
    mode : int
        ArduCopter mode number.
    settings : VehicleSettings
        The settings in use (the one owner; the parts read them through a callable).
    frames : Frames
        Ground frame (internal), EKF origin and home; ``frame`` is its ground frame.
    airframe : Airframe
        Vehicle update, state (``x``, ``delta``, ``controller``, ``body_rates_rad_s``) and wind.
    arming : Arming
        ``armed``, ``rotor``, ``set_interlock_switch``, ``rc_override``, ``rc8_us``.
    navigation : Navigation
        The stages flown; ``change_speed``, ``speed_m_s``, ``landing``.
    mission : Mission
        ``items``, ``current``, ``finished``, ``has_mission``; ``set_items``, ``set_current``, ``set_rally``.
    fence : Geofence
        ``area``, ``breached``; ``set_items``.
    ground : GroundContact
        ``landed``, ``taking_off``.
    """

    def __init__(
        self,
        model: HeliModel,
        settings: VehicleSettings,
        home_lla: Sequence[float],
        rng: np.random.Generator,
        origin_lla: Sequence[float] | None = None,
    ) -> None:
        lat, lon, alt, yaw_deg = (float(v) for v in home_lla)
        self.frames = Frames((lat, lon, alt), origin_lla)
        self.frame = self.frames.ground
        self._home_yaw_deg = yaw_deg
        self.settings = settings
        self.mode = STABILIZE
        self._steps = 0
        self._events: list[tuple] = []
        emit = self._events.append
        current_settings = lambda: self.settings  # noqa: E731 (the parts always read the settings in use)
        self.airframe = Airframe(model, settings, yaw_deg, rng)
        self.arming = Arming(self, current_settings, emit)
        self.navigation = Navigation(self.airframe, self.frames, current_settings, emit, math.radians(yaw_deg))
        self.mission = Mission(self, self.navigation, self.frames, current_settings, emit)
        self.fence = Geofence(self, self.frames, self.mission.item_target_ned_m, current_settings, emit)
        self.ground = GroundContact(
            self.airframe, self.navigation, self.arming, self, current_settings, self.mission.item_flown
        )

    def apply_settings(self, settings: VehicleSettings) -> None:
        """Use a new settings tree (after PARAM_SET): controller redesigned if its weights changed."""
        old, self.settings = self.settings, settings
        self.airframe.apply_settings(settings, old)
        self.arming.apply_settings(settings)

    # ------------------------------------------------------------------ state views
    @property
    def time_s(self) -> float:
        """Simulated time since start, s."""
        return self._steps * self.airframe.physics_dt_s

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame (from the start point; ground at down 0)."""
        return self.airframe.pos_ned_m

    @property
    def local_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED from the EKF origin (LOCAL_POSITION_NED)."""
        return self.frames.to_local(self.pos_ned_m)

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        """Ground velocity, (3,) m/s NED."""
        return self.airframe.vel_ned_m_s

    @property
    def euler_rad(self) -> np.ndarray:
        """Roll, pitch, yaw, (3,) rad."""
        return self.airframe.euler_rad

    @property
    def home_lla(self) -> tuple[float, float, float, float]:
        """Home: latitude, longitude (degrees), altitude AMSL (m), initial heading (degrees)."""
        return (*self.frames.home_lla, self._home_yaw_deg)

    @property
    def height_above_home_m(self) -> float:
        """Height of the vehicle above home, m."""
        return self.frames.height_above_home(self.pos_ned_m)

    def position_lla(self) -> tuple[float, float, float]:
        """Latitude, longitude (degrees) and altitude AMSL (m) of the vehicle."""
        lat, lon, alt = self.frame.to_lla(*self.pos_ned_m)
        return float(lat), float(lon), float(alt)

    @property
    def armed(self) -> bool:
        """True while armed (:class:`~sim_vehicle.autopilot.arming.Arming`'s state)."""
        return self.arming.armed

    @property
    def landed(self) -> bool:
        """True while on the ground (the land detector's, :class:`~sim_vehicle.autopilot.ground_contact.GroundContact`)."""
        return self.ground.landed

    # ------------------------------------------------------------------ modes
    @property
    def flight_mode(self) -> Mode:
        """The mode object of :attr:`mode`."""
        return MODES[self.mode]

    def set_mode(self, mode: int) -> tuple[bool, str]:
        """Switch flight mode (ArduCopter number): STABILIZE 0, AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9, ..."""
        if mode not in MODE_NAMES:
            return False, f"unknown mode {mode}"
        if mode == self.mode:
            return True, ""
        refusal = MODES[mode].entry_refusal(self)
        if refusal is not None:
            return False, refusal
        previous = self.mode
        self.mode = mode
        self.navigation.guided = None
        self.mission.drop_active_item()
        self._events.append(("mode", mode))
        log.info("mode %s -> %s", mode_name(previous), mode_name(mode))
        if not self.armed:
            self.navigation.set_stages([])
        elif self.landed:
            MODES[mode].enter_landed(self)
        else:
            MODES[mode].enter(self)
        return True, ""

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        """GUIDED takeoff to ``alt_m`` above home.

        Refusals are :class:`QuietRefusal`: ArduCopter answers COMMAND_ACK FAILED without a
        STATUSTEXT (``Mode::do_user_takeoff``). Accepted once the motor interlock is in effect;
        the climb then waits for the rotor run-up.
        """
        return MODES[GUIDED].takeoff(self, alt_m)

    def set_guided_setpoint(self, setpoint: Setpoint) -> tuple[bool, str]:
        """A GUIDED target (SET_POSITION_TARGET_*).

        Position only: flown as a straight leg at WPNAV_SPEED. With velocity or acceleration:
        tracked directly, and the vehicle brakes to a hover if no new one arrives within
        GUID_TIMEOUT.
        """
        return MODES[GUIDED].set_target(self, setpoint)

    def set_yaw(self, yaw_rad: float) -> tuple[bool, str]:
        """MAV_CMD_CONDITION_YAW: hold this heading (GUIDED, AUTO, LOITER, BRAKE; in flight)."""
        if not math.isfinite(yaw_rad):
            return False, f"heading {yaw_rad!r} is not finite"
        if not self.armed or self.landed:
            return False, "not flying"
        if not self.flight_mode.accepts_condition_yaw:
            return False, f"not in {mode_name(self.mode)}"
        yaw = math.remainder(float(yaw_rad), 2.0 * math.pi)  # direct setpoints with a yaw win
        self.navigation.yaw_hold_rad = yaw
        log.info("heading %.1f deg (CONDITION_YAW)", math.degrees(yaw))
        return True, ""

    def mission_start(self, first: int = 0) -> tuple[bool, str]:
        """MAV_CMD_MISSION_START: AUTO from item ``first`` (0 = from item 1)."""
        refusal = self.mission.start_refusal(first)
        if refusal is None and not self.armed:
            refusal = "not armed"
        if refusal is not None:
            return False, refusal
        if self.mode != AUTO:
            self.mode = AUTO
            self._events.append(("mode", AUTO))
            log.info("mode -> AUTO (mission start)")
        self.mission.start(max(1, first))
        return True, ""

    # ------------------------------------------------------------------ arming and home
    def arm(self) -> tuple[bool, str]:
        """Pre-arm checks, then arm. In AUTO the mission starts."""
        if self.armed:
            return True, "already armed"
        refusal = "not landed" if not self.landed else self.flight_mode.arming_refusal(self)
        if refusal is None:
            refusal = self.arming.arming_check(self.airframe.healthy)
        if refusal is not None:
            return False, refusal
        t = self.time_s
        self.arming.arm(t)
        self.ground.restart_idle_timer(t)
        self.navigation.yaw_hold_rad = float(self.airframe.x[dynamics.IDX_PSI])
        self.airframe.reset_controller()
        self.navigation.set_stages([])
        self._events.append(("armed", ""))
        log.info("armed in %s", mode_name(self.mode))
        self.flight_mode.on_armed(self)
        return True, ""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        """Disarm; refused in flight unless ``force`` (the vehicle then drops to the ground)."""
        if not self.armed:
            return True, "already disarmed"
        if not self.landed and not force:
            return False, "flying: land first (or force-disarm)"
        self.arming.disarm()
        self.navigation.clear()
        self.mission.drop_active_item()
        self.ground.settle()
        self._events.append(("disarmed", reason))
        log.info("disarmed (%s)", reason)
        return True, ""

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[bool, str]:
        """MAV_CMD_DO_SET_HOME: move home (RTL, relative altitudes); the EKF origin stays."""
        if not all(math.isfinite(v) for v in (lat_deg, lon_deg, alt_m)):
            return False, "home must be finite"
        if not (-90.0 <= lat_deg <= 90.0 and -180.0 <= lon_deg <= 180.0) or (lat_deg == 0.0 and lon_deg == 0.0):
            return False, f"home {lat_deg!r}, {lon_deg!r} is not a valid position"
        self.frames.set_home(lat_deg, lon_deg, alt_m)
        home = self.frames.home_local_ned_m
        log.info(
            "home set to %.7f, %.7f, %.2f m AMSL (N %.1f E %.1f D %.1f m from the EKF origin)",
            lat_deg,
            lon_deg,
            alt_m,
            *home,
        )
        return True, ""

    # ------------------------------------------------------------------ simulation
    def step(self, dt_s: float) -> list[tuple]:
        """Advance ``dt_s`` of simulated time (rounded to whole physics steps).

        Returns
        -------
        events : list of tuple
            ``('mission_item_reached', seq)``, ``('mission_current', seq)``, ``('mode', m)``,
            ``('armed', '')``, ``('disarmed', reason)``, ``('text', severity, message)``.
        """
        steps = int(round(dt_s / self.airframe.physics_dt_s))
        for _ in range(steps):
            setpoint = self._control_tick() if self._steps % self.airframe.steps_per_control == 0 else None
            self._physics_tick(setpoint)
        events = list(self._events)
        self._events.clear()
        return events

    def run_steps(self, steps: int) -> list[tuple]:
        """Advance ``steps`` physics steps; returns the events (see :meth:`step`)."""
        return self.step(steps * self.airframe.physics_dt_s)

    def _control_tick(self) -> Setpoint | None:
        """Decide what to track; the setpoint for the controller, or None when it does not fly."""
        t = self.time_s
        self.arming.update_rotor(self.airframe.physics_dt_s * self.airframe.steps_per_control)
        if not self.armed:
            self.arming.report_prearm(t)
            return None
        self.fence.check()
        self.flight_mode.run(self, t)
        if self.landed and self.ground.climbing_stage() and not self.arming.rotor.runup_complete:
            self.ground.idle(t)  # waiting for the rotor: the stages (and their legs' timing) start after it
            return None
        if self.navigation.advance(t):
            self.mission.item_flown()
        if self.landed and not self.ground.lifting_off():
            self.ground.idle(t)
            return None
        return self.navigation.setpoint(t)

    def _physics_tick(self, setpoint: Setpoint | None) -> None:
        """One physics step of the pure update (the controller first when ``setpoint`` starts a control period)."""
        self._steps += 1
        if not self.armed or (self.landed and not self.ground.lifting_off()):
            return
        self.airframe.physics_step(setpoint)
        self.ground.after_physics_step()

    def recover(self, reason: str) -> None:
        """After an internal error: drop the GUIDED setpoint and hold (or stay on the ground)."""
        log.error("recovering from an internal error (%s): holding position", reason)
        self.airframe.restore_finite()
        self.airframe.reset_controller(zero_inputs=True)
        self.navigation.hold_after_error(self.landed)
        self._events.append(("text", 3, f"internal error, holding: {reason}"[:50]))
