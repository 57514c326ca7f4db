"""The Autopilot: the simulated helicopter's autopilot, composed of its parts.

ArduCopter's ``Copter`` class is one class whose methods live in many files (``mode_*.cpp``,
``land_detector.cpp``, ``fence.cpp``, ``motors.cpp``...); so is this one: the state views,
mode switching and the simulation ticks are here, the rest in the mixins it is made of
(:mod:`~sim_vehicle.autopilot.arming`, :mod:`~sim_vehicle.autopilot.mission`,
:mod:`~sim_vehicle.autopilot.fence`, :mod:`~sim_vehicle.autopilot.ground_contact`,
:mod:`~sim_vehicle.autopilot.navigation`) and in the mode objects (``mode_*.py``).
The vehicle itself (controller and RK4 physics) is the pure update of
:mod:`heli_model.vehicle_update`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Sequence

import numpy as np

from heli_model import dynamics
from sim_vehicle import rsc
from sim_vehicle.autopilot.arming import ArmingMixin
from sim_vehicle.autopilot.fence import Fence, FenceMixin
from sim_vehicle.autopilot.ground_contact import GroundContactMixin
from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mission import MissionMixin
from sim_vehicle.autopilot.mode import GUIDED, LAND, MODE_NAMES, RTL, STABILIZE, Mode, mode_name
from sim_vehicle.autopilot.mode_auto import ModeAuto
from sim_vehicle.autopilot.mode_brake import ModeBrake
from sim_vehicle.autopilot.mode_guided import GuidedCommand, ModeGuided
from sim_vehicle.autopilot.mode_land import ModeLand
from sim_vehicle.autopilot.mode_loiter import ModeLoiter
from sim_vehicle.autopilot.mode_rtl import ModeRTL
from sim_vehicle.autopilot.mode_stabilize import ModeAltHold, ModeStabilize
from sim_vehicle.autopilot.navigation import NavigationMixin
from sim_vehicle.config import VehicleSettings
from heli_model.control import ControlLaw, Setpoint, initial_controller_state
from sim_vehicle.frames import Frames
from sim_vehicle.mission_store import MissionItem
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleState, VehicleUpdate
from heli_model.wind import WindModel, WindSettings

log = logging.getLogger(__name__)

#: The modes this vehicle flies, number -> mode object.
MODES: dict[int, Mode] = {m.number: m for m in (ModeStabilize(), ModeAltHold(), ModeAuto(), ModeGuided(), ModeLoiter(),
                                                ModeRTL(), ModeLand(), ModeBrake())}
if set(MODES) != set(MODE_NAMES):
    raise RuntimeError("every mode of MODE_NAMES needs its mode object")


class Autopilot(ArmingMixin, MissionMixin, FenceMixin, GroundContactMixin, NavigationMixin):
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
    armed, landed : bool
    time_s : float
        Simulated time since start.
    x : ndarray, shape (17,) or (21,)
        Simulation state (see :mod:`heli_model.dynamics`).
    delta : ndarray, shape (4,)
        Last rotor inputs ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1].
    mission_current : int
        Sequence number of the current mission item.
    frames : Frames
        Ground frame (internal), EKF origin and home.
    rotor : sim_vehicle.rsc.RotorState
        Interlock switch, effective interlock and rotor run-up.
    vehicle : VehicleUpdate
        The pure vehicle update (model, designed controller, physics step).
    vehicle_state : VehicleState
        Its state: ``x``, ``delta`` and the flight controller's state.
    controller : ControlLaw
        The designed flight controller (``gains``, ``settings``).
    """

    def __init__(self, model: HeliModel, settings: VehicleSettings, home_lla: Sequence[float],
                 rng: np.random.Generator, origin_lla: Sequence[float] | None = None) -> None:
        lat, lon, alt, yaw_deg = (float(v) for v in home_lla)
        self.model = model
        self.rng = rng
        self.frames = Frames((lat, lon, alt), origin_lla)
        self.frame = self.frames.ground
        self._home_yaw_deg = yaw_deg
        self.vehicle_state = VehicleState(x=dynamics.hover_state(model, (0.0, 0.0, 0.0), math.radians(yaw_deg)),
                                          delta=np.zeros(4), controller=initial_controller_state())
        self.mode = STABILIZE
        self.armed = False
        self.landed = True
        self._steps = 0
        self.mission_items: tuple[MissionItem, ...] = ()
        self.rally_ned_m: list[np.ndarray] = []
        self.fence = Fence()
        self.fence_breached: str | None = None
        self.mission_current = 0
        self.mission_finished = False
        self._stages: list[Stage] = []
        self._item_active = False
        self._guided: GuidedCommand | None = None
        self._speed_override_m_s: float | None = None
        self._yaw_hold_rad = math.radians(yaw_deg)
        self._ref_pos: np.ndarray | None = None
        self._landed_since_s = 0.0
        self._events: list[tuple] = []
        self.settings = settings
        self.rotor_control = rsc.RotorControl(settings.rsc)
        self._prearm_reported_s = 0.0
        self._apply_settings(settings, first=True)

    # ------------------------------------------------------------------ settings
    def _apply_settings(self, settings: VehicleSettings, first: bool = False) -> None:
        old = None if first else self.settings
        self.settings = settings
        self.physics_dt_s = settings.timing.physics_dt_s
        self.steps_per_control = settings.timing.physics_steps_per_control
        control_dt_s = self.physics_dt_s * self.steps_per_control
        controller_settings = dataclasses.replace(settings.controller, control_dt_s=control_dt_s)
        if first or controller_settings != self.controller.settings:
            self.vehicle = VehicleUpdate.build(self.model, controller_settings, self.physics_dt_s)
            self.vehicle_state = self.vehicle.reset_controller(self.vehicle_state)
        elif self.vehicle.physics_dt_s != self.physics_dt_s:
            self.vehicle = dataclasses.replace(self.vehicle, physics_dt_s=self.physics_dt_s)
        if not first:
            self.rotor_control.settings = settings.rsc
        if first or settings.wind != old.wind:
            wind = settings.wind
            if wind.enabled:
                wind_settings = WindSettings(wind.steady_ned_m_s(), wind.gust_m_s, wind.gust_tau_s)
            else:
                wind_settings = self.model.wind
            self.wind = WindModel(wind_settings, self.rng)
            self._wind_calm = wind_settings.is_calm

    def apply_settings(self, settings: VehicleSettings) -> None:
        """Use a new settings tree (after PARAM_SET): controller redesigned if its weights changed."""
        self._apply_settings(settings)

    # ------------------------------------------------------------------ vehicle
    @property
    def x(self) -> np.ndarray:
        """Simulation state, (17,) or (21,) (see :mod:`heli_model.dynamics`)."""
        return self.vehicle_state.x

    @x.setter
    def x(self, value: np.ndarray) -> None:
        self.vehicle_state = self.vehicle_state._replace(x=value)

    @property
    def delta(self) -> np.ndarray:
        """Rotor inputs held now, (4,) ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1]."""
        return self.vehicle_state.delta

    @delta.setter
    def delta(self, value: np.ndarray) -> None:
        self.vehicle_state = self.vehicle_state._replace(delta=value)

    @property
    def controller(self) -> ControlLaw:
        """The designed flight controller (``gains``, ``settings``); its state is in :attr:`vehicle_state`."""
        return self.vehicle.law

    # ------------------------------------------------------------------ state views
    @property
    def time_s(self) -> float:
        """Simulated time since start, s."""
        return self._steps * self.physics_dt_s

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame (from the start point; ground at down 0)."""
        return dynamics.pos_ned_m(self.x)

    @property
    def local_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED from the EKF origin (LOCAL_POSITION_NED)."""
        return self.frames.to_local(self.pos_ned_m)

    @property
    def home_lla(self) -> tuple[float, float, float, float]:
        """Home: latitude, longitude (degrees), altitude AMSL (m), initial heading (degrees)."""
        return (*self.frames.home_lla, self._home_yaw_deg)

    @property
    def height_above_home_m(self) -> float:
        """Height of the vehicle above home, m."""
        return self.frames.height_above_home(self.pos_ned_m)

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        """Ground velocity, (3,) m/s NED."""
        return dynamics.vel_ned_m_s(self.x)

    @property
    def euler_rad(self) -> np.ndarray:
        """Roll, pitch, yaw, (3,) rad."""
        return dynamics.euler_rad(self.x)

    @property
    def body_rates_rad_s(self) -> np.ndarray:
        """Body rates p, q, r, (3,) rad/s."""
        return dynamics.body_rates_rad_s(self.x)

    def position_lla(self) -> tuple[float, float, float]:
        """Latitude, longitude (degrees) and altitude AMSL (m) of the vehicle."""
        lat, lon, alt = self.frame.to_lla(*self.pos_ned_m)
        return float(lat), float(lon), float(alt)


    # ------------------------------------------------------------------ modes
    @property
    def flight_mode(self) -> Mode:
        """The mode object of :attr:`mode`."""
        return MODES[self.mode]

    def set_mode(self, mode: int) -> tuple[bool, str]:
        """Switch flight mode (ArduCopter number)."""
        if mode not in MODE_NAMES:
            return False, f"unknown mode {mode}"
        if mode == self.mode:
            return True, ""
        refusal = MODES[mode].entry_refusal(self)
        if refusal is not None:
            return False, refusal
        previous = self.mode
        self.mode = mode
        self._guided = None
        self._item_active = False
        self._events.append(("mode", mode))
        log.info("mode %s -> %s", mode_name(previous), mode_name(mode))
        self._enter_mode(mode)
        return True, ""

    def _enter_mode(self, mode: int) -> None:
        if not self.armed:
            self._stages = []
        elif self.landed:
            MODES[mode].enter_landed(self)
        else:
            MODES[mode].enter(self)

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

    def land(self) -> tuple[bool, str]:
        """Switch to LAND."""
        return self.set_mode(LAND)

    def rtl(self) -> tuple[bool, str]:
        """Switch to RTL."""
        return self.set_mode(RTL)

    def set_yaw(self, yaw_rad: float) -> tuple[bool, str]:
        """MAV_CMD_CONDITION_YAW: hold this heading (GUIDED, AUTO, LOITER, BRAKE; in flight)."""
        if not math.isfinite(yaw_rad):
            return False, f"heading {yaw_rad!r} is not finite"
        if not self.armed or self.landed:
            return False, "not flying"
        if not self.flight_mode.accepts_condition_yaw:
            return False, f"not in {mode_name(self.mode)}"
        self._yaw_hold_rad = math.remainder(float(yaw_rad), 2.0 * math.pi)  # direct setpoints with a yaw win
        log.info("heading %.1f deg (CONDITION_YAW)", math.degrees(self._yaw_hold_rad))
        return True, ""

    # ------------------------------------------------------------------ home
    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[bool, str]:
        """MAV_CMD_DO_SET_HOME: move home (RTL, relative altitudes); the EKF origin stays."""
        if not all(math.isfinite(v) for v in (lat_deg, lon_deg, alt_m)):
            return False, "home must be finite"
        if not (-90.0 <= lat_deg <= 90.0 and -180.0 <= lon_deg <= 180.0) or (lat_deg == 0.0 and lon_deg == 0.0):
            return False, f"home {lat_deg!r}, {lon_deg!r} is not a valid position"
        self.frames.set_home(lat_deg, lon_deg, alt_m)
        home = self.frames.home_local_ned_m
        log.info("home set to %.7f, %.7f, %.2f m AMSL (N %.1f E %.1f D %.1f m from the EKF origin)", lat_deg, lon_deg,
                 alt_m, *home)
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
        steps = int(round(dt_s / self.physics_dt_s))
        for _ in range(steps):
            setpoint = self._control_tick() if self._steps % self.steps_per_control == 0 else None
            self._physics_tick(setpoint)
        events, self._events = self._events, []
        return events

    def run_steps(self, steps: int) -> list[tuple]:
        """Advance ``steps`` physics steps; returns the events (see :meth:`step`)."""
        return self.step(steps * self.physics_dt_s)

    def _control_tick(self) -> Setpoint | None:
        """Decide what to track; the setpoint for the controller, or None when it does not fly."""
        t = self.time_s
        self._update_rotor(self.physics_dt_s * self.steps_per_control)
        if not self.armed:
            self._report_prearm(t)
            return None
        self._check_fence()
        self.flight_mode.run(self, t)
        if self.landed and self._climbing_stage() and not self.rotor.runup_complete:
            self._idle_on_ground(t)  # waiting for the rotor: the stages (and their legs' timing) start after it
            return None
        self._advance_stages(t)
        if self.landed and not self._lifting_off():
            self._idle_on_ground(t)
            return None
        return self._setpoint(t)

    def _physics_tick(self, setpoint: Setpoint | None) -> None:
        """One physics step of the pure update (the controller first when ``setpoint`` starts a control period)."""
        self._steps += 1
        if not self.armed or (self.landed and not self._lifting_off()):
            return
        wind = None if self._wind_calm else self.wind.step(self.physics_dt_s)
        self.vehicle_state = self.vehicle.update(self.vehicle_state, VehicleCommand(setpoint, wind), self.physics_dt_s)
        self._ground_contact()

    def recover(self, reason: str) -> None:
        """After an internal error: drop the GUIDED setpoint and hold (or stay on the ground)."""
        log.error("recovering from an internal error (%s): holding position", reason)
        self._guided = None
        if not np.all(np.isfinite(self.x)):
            pos = np.nan_to_num(self.pos_ned_m)
            self.x = dynamics.hover_state(self.model, (pos[0], pos[1], min(0.0, pos[2])), 0.0)
        self.vehicle_state = self.vehicle.reset_controller(self.vehicle_state._replace(delta=np.zeros(4)))
        self._ref_pos = None
        self._stages = [] if self.landed else [Stage("hold", target=self._brake_point())]
        self._events.append(("text", 3, f"internal error, holding: {reason}"[:50]))
