"""Vehicle behaviour of the SITL helicopter: modes, arming, takeoff, landing, RTL, AUTO missions.

Behaves like ArduCopter (https://ardupilot.org/copter/docs/flight-modes.html) with the mode
numbers of DESIGN section 5 (STABILIZE 0, ALT_HOLD 2, AUTO 3, GUIDED 4, LOITER 5, RTL 6,
LAND 9, BRAKE 17; taken from pymavlink through :mod:`heli_common.mavlink_ids`); with no RC pilot, STABILIZE and ALT_HOLD hold position like LOITER. The
flight controller is the paper's LQI with the PID position loop (section 2.2,
:mod:`sim_vehicle.control`); this module only decides *what* it tracks:

* **Legs.** AUTO waypoints, takeoff, RTL and GUIDED position-only targets are flown as straight
  legs with a trapezoidal speed profile (WPNAV_SPEED horizontally, WPNAV_SPEED_UP/DN
  vertically, WPNAV_ACCEL): position, velocity and acceleration references for the
  controller. This is the straight-leg baseline the companion's smoothed paths must beat.
* **Direct GUIDED.** A setpoint with velocity or acceleration is passed to the controller
  unchanged; without a new one for GUID_TIMEOUT (simulated s) the vehicle brakes to a hover.
* **Mission.** ArduPilot's convention: item 0 of the mission list is home and is not flown;
  AUTO starts at item 1. NAV_WAYPOINT (acceptance radius param2, hold param1), NAV_TAKEOFF,
  NAV_LAND, NAV_RETURN_TO_LAUNCH, NAV_LOITER_UNLIM/TIME and DO_CHANGE_SPEED are flown; other
  DO commands are skipped with a log line. MISSION_ITEM_REACHED events are returned by
  :meth:`Autopilot.step`.
* **Ground.** Flat ground at the start altitude (``down = 0`` of the ground frame,
  :mod:`sim_vehicle.frames`): the vehicle cannot go below it, sits still on it while disarmed or
  idle, and a landing disarms on touchdown. Relative altitudes are above home (DO_SET_HOME
  moves it); the EKF origin (LOCAL_POSITION_NED) may differ from both.
* **Rotor.** ArduCopter heli's rotor speed controller and motor interlock
  (:mod:`sim_vehicle.rsc`): arming is refused while the interlock switch (RC8, DO_AUX_FUNCTION
  32) is engaged, the interlock takes effect ARMING_DELAY_SEC after arming, NAV_TAKEOFF is
  refused until it has, and a vehicle told to climb waits on the ground until the rotor has run
  up (H_RSC_RUNUP_TIME).

Physics runs at ``timing.physics_rate_hz`` (400 Hz) with RK4 (:mod:`sim_vehicle.dynamics`)
and the controller at ``timing.control_rate_hz`` (100 Hz). Pure simulation: no I/O.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any, Sequence

import numpy as np

from heli_common.geometry import point_in_polygon
from heli_common.mavlink_ids import COPTER_MODES, copter_mode_name, mavlink

from sim_vehicle import dynamics, rsc
from sim_vehicle.config import VehicleSettings
from sim_vehicle.control import FlightController, Setpoint
from sim_vehicle.frames import Frames
from sim_vehicle.mission_store import (
    FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_LOCAL_NED, FRAME_MISSION, MissionItem,
)
from sim_vehicle.model import HeliModel
from sim_vehicle.wind import WindModel, WindSettings

log = logging.getLogger(__name__)

# ArduCopter flight modes (custom_mode of HEARTBEAT; numbers from pymavlink's mode_mapping_acm)
STABILIZE = COPTER_MODES["STABILIZE"]
ALT_HOLD = COPTER_MODES["ALT_HOLD"]
AUTO = COPTER_MODES["AUTO"]
GUIDED = COPTER_MODES["GUIDED"]
LOITER = COPTER_MODES["LOITER"]
RTL = COPTER_MODES["RTL"]
LAND = COPTER_MODES["LAND"]
BRAKE = COPTER_MODES["BRAKE"]
#: the modes this vehicle flies, number -> name
MODE_NAMES = {number: copter_mode_name(number) for number in
              (STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, BRAKE)}
MODE_NUMBERS = {name: number for number, name in MODE_NAMES.items()}

# MAV_CMD numbers of the mission items the vehicle flies (pymavlink's generated enums)
CMD_NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
CMD_NAV_LOITER_UNLIM = mavlink.MAV_CMD_NAV_LOITER_UNLIM
CMD_NAV_LOITER_TIME = mavlink.MAV_CMD_NAV_LOITER_TIME
CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
CMD_DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
CMD_NAV_RALLY_POINT = mavlink.MAV_CMD_NAV_RALLY_POINT
CMD_FENCE_POLYGON_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
CMD_FENCE_POLYGON_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CMD_FENCE_CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
CMD_FENCE_CIRCLE_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
NAV_COMMANDS = frozenset({CMD_NAV_WAYPOINT, CMD_NAV_LOITER_UNLIM, CMD_NAV_LOITER_TIME, CMD_NAV_RETURN_TO_LAUNCH,
                          CMD_NAV_LAND, CMD_NAV_TAKEOFF})

LIFTOFF_HEIGHT_M = 0.2
"""Height above ground at which a climbing vehicle counts as airborne."""
TOUCHDOWN_HEIGHT_M = 0.03
"""Height below which a descending vehicle counts as landed."""
MAX_TAKEOFF_ALT_M = 1000.0
PREARM_REPORT_PERIOD_S = 30.0
"""While disarmed, a failing pre-arm check is reported this often (ArduPilot's PREARM_DISPLAY_PERIOD)."""
MAV_SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL


class QuietRefusal(str):
    """A refusal reason that is logged but not sent as STATUSTEXT (ArduPilot sends none there)."""


def mode_name(mode: int) -> str:
    """ArduCopter mode name of ``mode`` (or ``MODE_<n>``)."""
    return MODE_NAMES.get(mode, f"MODE_{mode}")


# ============================================================================ geofence
@dataclasses.dataclass(frozen=True)
class Fence:
    """A geofence in the local frame (ArduPilot's polygon and circle fences).

    Attributes
    ----------
    inclusion_polygons, exclusion_polygons : list of ndarray, shape (K, 2)
        North-east vertices, m.
    inclusion_circles, exclusion_circles : list of (ndarray (2,), float)
        Centre north-east (m) and radius (m).
    """

    inclusion_polygons: tuple = ()
    exclusion_polygons: tuple = ()
    inclusion_circles: tuple = ()
    exclusion_circles: tuple = ()

    @property
    def empty(self) -> bool:
        """True when no polygon or circle is defined."""
        return not (self.inclusion_polygons or self.exclusion_polygons or self.inclusion_circles
                    or self.exclusion_circles)


def fence_breach(fence: Fence, pos_ned_m: np.ndarray, alt_max_m: float) -> str | None:
    """Why ``pos_ned_m`` violates the fence (or the ceiling), or None if it does not."""
    if -pos_ned_m[2] > alt_max_m:
        return f"above FENCE_ALT_MAX {alt_max_m:g} m"
    ne = pos_ned_m[:2]
    for poly in fence.inclusion_polygons:
        if not point_in_polygon(ne, poly):
            return "outside an inclusion polygon"
    for poly in fence.exclusion_polygons:
        if point_in_polygon(ne, poly):
            return "inside an exclusion polygon"
    for centre, radius in fence.inclusion_circles:
        if math.hypot(ne[0] - centre[0], ne[1] - centre[1]) > radius:
            return "outside an inclusion circle"
    for centre, radius in fence.exclusion_circles:
        if math.hypot(ne[0] - centre[0], ne[1] - centre[1]) < radius:
            return "inside an exclusion circle"
    return None


# ============================================================================ speed profiles
class Leg:
    """A straight leg flown with a trapezoidal (or triangular) speed profile.

    Parameters
    ----------
    start_ned_m, end_ned_m : (3,) array_like
        End points, m NED.
    speed_xy_m_s, speed_up_m_s, speed_down_m_s : float
        Limits of the horizontal, climb and descent components of the leg speed.
    accel_m_s2 : float
        Acceleration and deceleration along the leg.
    t0_s : float
        Simulated time at which the leg starts.
    """

    def __init__(self, start_ned_m: Any, end_ned_m: Any, speed_xy_m_s: float, speed_up_m_s: float,
                 speed_down_m_s: float, accel_m_s2: float, t0_s: float) -> None:
        self.start = np.asarray(start_ned_m, dtype=float).copy()
        self.end = np.asarray(end_ned_m, dtype=float).copy()
        delta = self.end - self.start
        self.length_m = float(np.linalg.norm(delta))
        self.t0_s = float(t0_s)
        self.dir = delta / self.length_m if self.length_m > 1e-9 else np.zeros(3)
        speed = math.inf
        horizontal = math.hypot(delta[0], delta[1])
        if horizontal > 1e-9:
            speed = min(speed, speed_xy_m_s * self.length_m / horizontal)
        if delta[2] < -1e-9:
            speed = min(speed, speed_up_m_s * self.length_m / -delta[2])
        elif delta[2] > 1e-9:
            speed = min(speed, speed_down_m_s * self.length_m / delta[2])
        if not math.isfinite(speed):
            speed = speed_xy_m_s
        self.accel_m_s2 = float(accel_m_s2)
        if self.length_m * self.accel_m_s2 < speed * speed:  # triangular: never reaches cruise speed
            speed = math.sqrt(self.length_m * self.accel_m_s2)
        self.speed_m_s = float(speed)
        self.t_acc_s = self.speed_m_s / self.accel_m_s2 if self.accel_m_s2 > 0 else 0.0
        cruise_m = self.length_m - self.speed_m_s * self.t_acc_s
        self.t_cruise_s = cruise_m / self.speed_m_s if self.speed_m_s > 1e-9 else 0.0
        self.duration_s = 2.0 * self.t_acc_s + self.t_cruise_s

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference at simulated time ``t_s``: position (3,), velocity (3,), acceleration (3,)."""
        tau = t_s - self.t0_s
        a, v, ta, tc = self.accel_m_s2, self.speed_m_s, self.t_acc_s, self.t_cruise_s
        if tau <= 0.0 or self.length_m <= 1e-9:
            s, sd, sdd = 0.0, 0.0, 0.0
        elif tau < ta:
            s, sd, sdd = 0.5 * a * tau * tau, a * tau, a
        elif tau < ta + tc:
            s, sd, sdd = 0.5 * a * ta * ta + v * (tau - ta), v, 0.0
        elif tau < self.duration_s:
            rem = self.duration_s - tau
            s, sd, sdd = self.length_m - 0.5 * a * rem * rem, a * rem, -a
        else:
            s, sd, sdd = self.length_m, 0.0, 0.0
        if self.length_m <= 1e-9:
            return self.end.copy(), np.zeros(3), np.zeros(3)
        return self.start + self.dir * s, self.dir * sd, self.dir * sdd

    def finished(self, t_s: float) -> bool:
        """True once the reference has arrived at the end."""
        return t_s >= self.t0_s + self.duration_s


# ============================================================================ navigation stages
@dataclasses.dataclass
class Stage:
    """One step of what the vehicle is doing.

    kind: ``leg`` (fly to ``target``), ``hold`` (stay at ``target``, for ``duration_s`` or
    forever when None), ``land`` (descend until touchdown), ``direct`` (GUIDED setpoint).
    """

    kind: str
    target: np.ndarray | None = None
    duration_s: float | None = None
    radius_m: float = 0.0
    speed_xy_m_s: float | None = None
    vertical_only: bool = False
    leg: Leg | None = None
    started_s: float | None = None
    arrived_s: float | None = None


@dataclasses.dataclass
class _GuidedCommand:
    setpoint: Setpoint
    received_s: float


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
    armed, landed : bool
    time_s : float
        Simulated time since start.
    x : ndarray, shape (17,) or (21,)
        Simulation state (see :mod:`sim_vehicle.dynamics`).
    delta : ndarray, shape (4,)
        Last rotor inputs ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1].
    mission_current : int
        Sequence number of the current mission item.
    frames : Frames
        Ground frame (internal), EKF origin and home.
    rotor : sim_vehicle.rsc.RotorState
        Interlock switch, effective interlock and rotor run-up.
    """

    def __init__(self, model: HeliModel, settings: VehicleSettings, home_lla: Sequence[float],
                 rng: np.random.Generator, origin_lla: Sequence[float] | None = None) -> None:
        lat, lon, alt, yaw_deg = (float(v) for v in home_lla)
        self.model = model
        self.rng = rng
        self.frames = Frames((lat, lon, alt), origin_lla)
        self.frame = self.frames.ground
        self._home_yaw_deg = yaw_deg
        self.x = dynamics.hover_state(model, (0.0, 0.0, 0.0), math.radians(yaw_deg))
        self.delta = np.zeros(4)
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
        self._guided: _GuidedCommand | None = None
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
            self.controller = FlightController(self.model, controller_settings)
            self.controller.reset(self.x)
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

    @property
    def has_mission(self) -> bool:
        """True if the mission list holds a flyable item after the home item 0."""
        return any(it.command in NAV_COMMANDS for it in self.mission_items[1:])

    # ------------------------------------------------------------------ commands
    def arm(self) -> tuple[bool, str]:
        """Pre-arm checks, then arm. In AUTO the mission starts."""
        if self.armed:
            return True, "already armed"
        if not self.landed:
            return False, "not landed"
        if self.mode in (RTL, LAND):
            return False, f"cannot arm in {mode_name(self.mode)}"
        if self.mode == AUTO and not self.has_mission:
            return False, "AUTO: no mission (upload one with a NAV item after item 0)"
        if not np.all(np.isfinite(self.x)):
            return False, "state estimate not healthy"
        if self.settings.flight.prearm_fail:
            return False, "PreArm: simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return False, "Arm: Motor Interlock Enabled"
        self.armed = True
        self.rotor_control.armed(self.time_s)
        self._landed_since_s = self.time_s
        self._yaw_hold_rad = float(self.x[dynamics.IDX_PSI])
        self.controller.reset(self.x)
        self._stages = []
        self._events.append(("armed", ""))
        log.info("armed in %s", mode_name(self.mode))
        if self.mode == AUTO:
            self._start_mission(self._resume_seq())
        return True, ""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        """Disarm; refused in flight unless ``force``."""
        if not self.armed:
            return True, "already disarmed"
        if not self.landed and not force:
            return False, "flying: land first (or force-disarm)"
        self.armed = False
        self._stages = []
        self._guided = None
        self._item_active = False
        self._settle_on_ground()
        self._events.append(("disarmed", reason))
        log.info("disarmed (%s)", reason)
        return True, ""

    def set_mode(self, mode: int) -> tuple[bool, str]:
        """Switch flight mode (ArduCopter number)."""
        if mode not in MODE_NAMES:
            return False, f"unknown mode {mode}"
        if mode == self.mode:
            return True, ""
        if mode == AUTO and self.armed and not self.has_mission:
            return False, "AUTO: no mission"
        if mode == RTL and self.armed and self.landed:
            return False, "RTL: landed"
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
            return
        if self.landed and mode != AUTO:
            if mode == LAND:
                self.disarm(reason="LAND on the ground")
            self._stages = []
            return
        if mode == AUTO:
            self._start_mission(self._resume_seq())
        elif mode == RTL:
            self._stages = self._rtl_stages()
        elif mode == LAND:
            self._stages = [Stage("land")]
        else:  # GUIDED, LOITER, BRAKE, STABILIZE, ALT_HOLD: brake to a hover
            self._stages = [Stage("hold", target=self._brake_point())]

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        """GUIDED takeoff to ``alt_m`` above home.

        Refusals are :class:`QuietRefusal`: ArduCopter answers COMMAND_ACK FAILED without a
        STATUSTEXT (``Mode::do_user_takeoff``). Accepted once the motor interlock is in effect;
        the climb then waits for the rotor run-up.
        """
        ok, reason = self._takeoff_refusal(alt_m)
        if not ok:
            return False, QuietRefusal(reason)
        self._stages = [self._takeoff_stage(alt_m), Stage("hold")]
        log.info("takeoff to %.1f m%s", alt_m, "" if self.rotor.runup_complete else " once the rotor has run up")
        return True, ""

    def _takeoff_refusal(self, alt_m: float) -> tuple[bool, str]:
        if not math.isfinite(alt_m) or not 0.5 <= alt_m <= MAX_TAKEOFF_ALT_M:
            return False, f"takeoff altitude {alt_m!r} m outside 0.5..{MAX_TAKEOFF_ALT_M:g}"
        if not self.armed:
            return False, "not armed"
        if self.mode != GUIDED:
            return False, f"takeoff needs GUIDED, mode is {mode_name(self.mode)}"
        if not self.landed:
            return False, "already flying"
        if alt_m <= self.height_above_home_m:
            return False, f"takeoff altitude {alt_m:g} m is not above the vehicle"
        if not self.rotor.interlock:
            return False, ("motor interlock not in effect yet (ARMING_DELAY_SEC after arming)"
                           if self.rotor.switch_engaged else "motor interlock not engaged (RC8 or DO_AUX_FUNCTION 32)")
        return True, ""

    def land(self) -> tuple[bool, str]:
        """Switch to LAND."""
        return self.set_mode(LAND)

    def rtl(self) -> tuple[bool, str]:
        """Switch to RTL."""
        return self.set_mode(RTL)

    # ------------------------------------------------------------------ rotor and interlock
    @property
    def rotor(self) -> rsc.RotorState:
        """Interlock switch, effective interlock and rotor run-up now."""
        return self.rotor_control.state

    def set_interlock_switch(self, position: int) -> tuple[bool, str]:
        """MAV_CMD_DO_AUX_FUNCTION 32: interlock switch LOW (0), MIDDLE (1) or HIGH (2).

        Accepted at any time on the ground, as ArduPilot does (during ARMING_DELAY_SEC after
        arming it is stored and takes effect afterwards); refused in flight when it would stop
        the rotor.
        """
        engaged_before = self.rotor.switch_engaged
        ok, reason = self.rotor_control.set_switch(position, flying=self.armed and not self.landed)
        if ok and self.rotor.switch_engaged != engaged_before:
            log.info("motor interlock switch %s", "engaged" if self.rotor.switch_engaged else "released")
        return ok, reason

    def rc_override(self, chan8_us: int) -> None:
        """RC_CHANNELS_OVERRIDE of RC8 in us (0 releases it back to the RC input)."""
        self.rotor_control.rc_override(chan8_us, self.time_s)

    @property
    def rc8_us(self) -> int:
        """RC8 input now (the override while fresh, else the SITL's stick at 1500 us)."""
        return self.rotor_control.rc8_us(self.time_s)

    def _update_rotor(self, dt_s: float) -> None:
        was_complete = self.rotor.runup_complete
        for severity, text in self.rotor_control.tick(self.time_s, dt_s, self.armed, self.armed and not self.landed):
            log.info("%s", text)
            self._events.append(("text", severity, text))
        if self.rotor.runup_complete != was_complete:
            log.info("rotor run-up %s", "complete" if self.rotor.runup_complete else "lost (below H_RSC_CRITICAL)")

    def prearm_failure(self) -> str | None:
        """The failing pre-arm check (as ArduPilot words it after "PreArm: "), or None."""
        if self.settings.flight.prearm_fail:
            return "simulated sensor failure (SIM_PREARM_FAIL)"
        if self.rotor.switch_engaged:
            return "Motor Interlock Enabled"
        return None

    def _report_prearm(self, t: float) -> None:
        if t - self._prearm_reported_s < PREARM_REPORT_PERIOD_S:
            return
        self._prearm_reported_s = t
        failure = self.prearm_failure()
        if failure is not None:
            self._events.append(("text", MAV_SEVERITY_CRITICAL, f"PreArm: {failure}"))

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

    def mission_start(self, first: int = 0) -> tuple[bool, str]:
        """MAV_CMD_MISSION_START: AUTO from item ``first`` (0 = from item 1)."""
        if not self.has_mission:
            return False, "no mission"
        if not 0 <= first < len(self.mission_items):
            return False, f"item {first} outside the mission (0..{len(self.mission_items) - 1})"
        if not self.armed:
            return False, "not armed"
        self.mission_current = max(1, first)
        if self.mode != AUTO:
            self.mode = AUTO
            self._events.append(("mode", AUTO))
            log.info("mode -> AUTO (mission start)")
        self._start_mission(self.mission_current)
        return True, ""

    def set_mission(self, items: Sequence[MissionItem]) -> None:
        """A new mission list (after a completed upload or a clear)."""
        self.mission_items = tuple(items)
        self.mission_finished = False
        if not self.has_mission:
            self.mission_current = 0
            if self.mode == AUTO and self.armed and not self.landed:
                self._stages = [Stage("hold", target=self._brake_point())]
            return
        if not 1 <= self.mission_current < len(self.mission_items):
            self.mission_current = 1
        if self.mode == AUTO and self.armed:
            self._start_mission(self.mission_current)

    def change_speed(self, speed_m_s: float | None) -> tuple[bool, str]:
        """MAV_CMD_DO_CHANGE_SPEED: horizontal leg speed from now on (None = back to WPNAV_SPEED)."""
        if speed_m_s is None:
            self._speed_override_m_s = None
            return True, ""
        limit = self.settings.flight.max_speed_m_s
        if not math.isfinite(speed_m_s) or not 0.1 <= speed_m_s <= limit:
            return False, f"speed {speed_m_s!r} outside 0.1..{limit:g} m/s"
        self._speed_override_m_s = float(speed_m_s)
        log.info("speed set to %.1f m/s", speed_m_s)
        return True, ""

    def set_yaw(self, yaw_rad: float) -> tuple[bool, str]:
        """MAV_CMD_CONDITION_YAW: hold this heading (GUIDED, AUTO, LOITER, BRAKE; in flight)."""
        if not math.isfinite(yaw_rad):
            return False, f"heading {yaw_rad!r} is not finite"
        if not self.armed or self.landed:
            return False, "not flying"
        if self.mode not in (GUIDED, AUTO, LOITER, BRAKE):
            return False, f"not in {mode_name(self.mode)}"
        self._yaw_hold_rad = math.remainder(float(yaw_rad), 2.0 * math.pi)  # direct setpoints with a yaw win
        log.info("heading %.1f deg (CONDITION_YAW)", math.degrees(self._yaw_hold_rad))
        return True, ""

    @property
    def speed_m_s(self) -> float:
        """Current horizontal leg speed (DO_CHANGE_SPEED or WPNAV_SPEED), m/s."""
        return self._speed_override_m_s if self._speed_override_m_s is not None else self.settings.flight.wp_speed_m_s

    @property
    def landing(self) -> bool:
        """True while descending to land (LAND, the end of RTL, a NAV_LAND item)."""
        return bool(self._stages) and self._stages[0].kind == "land"

    def set_fence(self, items: Sequence[MissionItem]) -> None:
        """New fence list (polygon vertices grouped by their vertex count, circles)."""
        polygons: dict[int, list] = {CMD_FENCE_POLYGON_INCLUSION: [], CMD_FENCE_POLYGON_EXCLUSION: []}
        circles: dict[int, list] = {CMD_FENCE_CIRCLE_INCLUSION: [], CMD_FENCE_CIRCLE_EXCLUSION: []}
        current: list = []
        current_cmd = None
        for it in items:
            if it.command in polygons:
                count = int(it.param1) if math.isfinite(it.param1) and 3 <= it.param1 <= 1000 else 1000
                if current_cmd != it.command or not current or len(current) >= count:
                    current = []
                    current_cmd = it.command
                    polygons[it.command].append(current)
                current.append(self.item_target_ned_m(it)[:2])
            elif it.command in circles and math.isfinite(it.param1) and it.param1 > 0:
                circles[it.command].append((self.item_target_ned_m(it)[:2], float(it.param1)))
                current_cmd = None
        self.fence = Fence(
            tuple(np.array(p) for p in polygons[CMD_FENCE_POLYGON_INCLUSION] if len(p) >= 3),
            tuple(np.array(p) for p in polygons[CMD_FENCE_POLYGON_EXCLUSION] if len(p) >= 3),
            tuple(circles[CMD_FENCE_CIRCLE_INCLUSION]), tuple(circles[CMD_FENCE_CIRCLE_EXCLUSION]))
        self.fence_breached = None
        log.info("fence: %d inclusion / %d exclusion polygons, %d / %d circles", len(self.fence.inclusion_polygons),
                 len(self.fence.exclusion_polygons), len(self.fence.inclusion_circles),
                 len(self.fence.exclusion_circles))

    def _check_fence(self) -> None:
        f = self.settings.flight
        if not f.fence_enable or self.landed:
            return
        pos = self.pos_ned_m.copy()
        pos[2] = -self.frames.height_above_home(pos)  # FENCE_ALT_MAX is above home
        reason = fence_breach(self.fence, pos, f.fence_alt_max_m)
        if reason is None:
            if self.fence_breached is not None:
                log.info("fence: back inside")
            self.fence_breached = None
            return
        if self.fence_breached is not None:
            return  # already acting on this breach
        self.fence_breached = reason
        log.warning("fence breached (%s): action %d", reason, f.fence_action)
        self._events.append(("text", 2, f"Fence breach: {reason}"[:50]))
        action = {1: RTL, 2: LAND, 4: BRAKE}.get(f.fence_action)
        if action is not None and self.mode not in (RTL, LAND):
            ok, why = self.set_mode(action)
            if not ok and action == RTL:
                self.set_mode(LAND)

    def set_rally(self, items: Sequence[MissionItem]) -> None:
        """New rally points: RTL returns to the nearest of home and these (ArduPilot's rally)."""
        points = []
        for it in items:
            if it.command == CMD_NAV_RALLY_POINT and not (it.x == 0 and it.y == 0):
                target = self.item_target_ned_m(it)
                points.append(target)
        self.rally_ned_m = points
        log.info("%d rally points", len(points))

    def set_current(self, seq: int) -> tuple[bool, str]:
        """MISSION_SET_CURRENT: continue the mission at ``seq``."""
        if not 0 <= seq < len(self.mission_items):
            return False, f"item {seq} outside the mission (0..{len(self.mission_items) - 1})"
        self.mission_current = max(1, seq) if len(self.mission_items) > 1 else seq
        self.mission_finished = False
        self._events.append(("mission_current", self.mission_current))
        if self.mode == AUTO and self.armed:
            self._start_mission(self.mission_current)
        return True, ""

    def set_guided_setpoint(self, setpoint: Setpoint) -> tuple[bool, str]:
        """A GUIDED target (SET_POSITION_TARGET_*).

        Position only: flown as a straight leg at WPNAV_SPEED. With velocity or acceleration:
        tracked directly, and the vehicle brakes to a hover if no new one arrives within
        GUID_TIMEOUT.
        """
        if self.mode != GUIDED:
            return False, f"not in GUIDED (mode {mode_name(self.mode)})"
        if not self.armed:
            return False, "not armed"
        checked = _check_setpoint(setpoint, self.settings.flight.max_speed_m_s)
        if isinstance(checked, str):
            return False, checked
        if self.landed and not self._climbing_stage():
            return False, "landed: take off first (MAV_CMD_NAV_TAKEOFF)"
        if checked.vel_ned_m_s is None and checked.acc_ned_m_s2 is None:
            if checked.pos_ned_m is None:  # yaw only: turn on the spot
                self._yaw_hold_rad = self._yaw_target(checked)
                target = self._hold_target()
                self._stages = [Stage("hold", target=target)]
                return True, ""
            target = self._fill_nan(np.asarray(checked.pos_ned_m, dtype=float))
            if checked.yaw_rad is not None or checked.yaw_rate_rad_s is not None:
                self._yaw_hold_rad = self._yaw_target(checked)
            current = self._stages[0] if self._stages else None
            same = (current is not None and current.kind in ("leg", "hold") and current.target is not None
                    and float(np.linalg.norm(current.target - target)) < 0.05)
            if not same:
                self._stages = [Stage("leg", target=target), Stage("hold", target=target)]
            self._guided = None
            return True, ""
        self._guided = _GuidedCommand(checked, self.time_s)
        if not self._stages or self._stages[0].kind != "direct":
            self._stages = [Stage("direct")]
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
            if self._steps % self.steps_per_control == 0:
                self._control_tick()
            self._physics_tick()
        events, self._events = self._events, []
        return events

    def run_steps(self, steps: int) -> list[tuple]:
        """Advance ``steps`` physics steps; returns the events (see :meth:`step`)."""
        return self.step(steps * self.physics_dt_s)

    def _control_tick(self) -> None:
        t = self.time_s
        self._update_rotor(self.physics_dt_s * self.steps_per_control)
        if not self.armed:
            self._report_prearm(t)
            return
        self._check_fence()
        if self.mode == AUTO:
            self._advance_mission(t)
        if self.landed and self._climbing_stage() and not self.rotor.runup_complete:
            self._idle_on_ground(t)  # waiting for the rotor: the stages (and their legs' timing) start after it
            return
        self._advance_stages(t)
        if self.landed and not self._lifting_off():
            self._idle_on_ground(t)
            return
        setpoint = self._setpoint(t)
        self.delta = self.controller.update(self.x, setpoint, self.physics_dt_s * self.steps_per_control)

    def _physics_tick(self) -> None:
        self._steps += 1
        if not self.armed or (self.landed and not self._lifting_off()):
            return
        wind = None if self._wind_calm else self.wind.step(self.physics_dt_s)
        self.x = dynamics.step_rk4(self.model, self.x, self.delta, self.physics_dt_s, wind)
        self._ground_contact()

    # ------------------------------------------------------------------ ground
    def _ground_contact(self) -> None:
        x = self.x
        if x[16] >= 0.0:
            x[16] = 0.0
            if x[2] > 0.0:
                x[2] = 0.0
        height = -float(x[16])
        if self.landed and height > LIFTOFF_HEIGHT_M:
            self.landed = False
            log.info("airborne")
        elif not self.landed and height < TOUCHDOWN_HEIGHT_M and self._descending_to_ground():
            self._touchdown()

    def _descending_to_ground(self) -> bool:
        if not self._stages:
            return False
        stage = self._stages[0]
        if stage.kind == "land":
            return True
        if stage.kind == "direct" and self._guided is not None:
            sp = self._guided.setpoint
            if sp.pos_ned_m is not None and not math.isnan(sp.pos_ned_m[2]):
                return sp.pos_ned_m[2] >= -TOUCHDOWN_HEIGHT_M
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] > 0.0
        return stage.target is not None and stage.target[2] >= -TOUCHDOWN_HEIGHT_M

    def _touchdown(self) -> None:
        self.landed = True
        self._landed_since_s = self.time_s
        self._settle_on_ground()
        log.info("touchdown at N %.1f E %.1f", self.x[14], self.x[15])
        if self._stages and self._stages[0].kind == "land":
            stage = self._stages.pop(0)
            stage.arrived_s = self.time_s
            if self.mode == AUTO and self._item_active:
                self._complete_item()
            self.disarm(reason="landed")

    def _settle_on_ground(self) -> None:
        n, e, psi = float(self.x[14]), float(self.x[15]), float(self.x[dynamics.IDX_PSI])
        self.x = dynamics.hover_state(self.model, (n, e, 0.0), psi)  # a forced disarm in flight drops it
        self.landed = True
        self.delta = np.zeros(4)
        self.controller.reset(self.x)

    def _idle_on_ground(self, t: float) -> None:
        """Sit on the ground; disarm as ArduCopter heli's auto-disarm does.

        Never while the rotor turns above H_RSC_CRITICAL; after half of DISARM_DELAY when the
        interlock is off; otherwise after DISARM_DELAY (not in AUTO).
        """
        self.delta = np.zeros(4)
        self.controller.reset(self.x)
        delay = self.settings.flight.disarm_delay_s
        if self.rotor.above_critical(self.settings.rsc):
            self._landed_since_s = t
            return
        interlock_off = not self.rotor.interlock
        if interlock_off:
            delay *= 0.5
        if delay > 0 and t - self._landed_since_s >= delay and (interlock_off or self.mode != AUTO):
            self.disarm(reason=f"landed and idle for {delay:g} s")

    def _lifting_off(self) -> bool:
        """True when a landed vehicle is told to climb and its rotor has run up."""
        return self._climbing_stage() and self.rotor.runup_complete

    def _climbing_stage(self) -> bool:
        """True when the current stage asks a landed vehicle to lift off."""
        if not self._stages:
            return False
        stage = self._stages[0]
        if stage.kind in ("leg", "hold"):
            return stage.target is not None and stage.target[2] < -LIFTOFF_HEIGHT_M
        if stage.kind == "direct" and self._guided is not None:
            sp = self._guided.setpoint
            if sp.pos_ned_m is not None and sp.pos_ned_m[2] < -LIFTOFF_HEIGHT_M:
                return True
            return sp.vel_ned_m_s is not None and sp.vel_ned_m_s[2] < -0.05
        return False

    def recover(self, reason: str) -> None:
        """After an internal error: drop the GUIDED setpoint and hold (or stay on the ground)."""
        log.error("recovering from an internal error (%s): holding position", reason)
        self._guided = None
        if not np.all(np.isfinite(self.x)):
            pos = np.nan_to_num(self.pos_ned_m)
            self.x = dynamics.hover_state(self.model, (pos[0], pos[1], min(0.0, pos[2])), 0.0)
        self.delta = np.zeros(4)
        self.controller.reset(self.x)
        self._ref_pos = None
        self._stages = [] if self.landed else [Stage("hold", target=self._brake_point())]
        self._events.append(("text", 3, f"internal error, holding: {reason}"[:50]))

    @property
    def taking_off(self) -> bool:
        """True from lift-off until a takeoff has reached its altitude (MAV_LANDED_STATE_TAKEOFF).

        A vehicle waiting on the ground for its rotor to run up is still ON_GROUND, as in ArduPilot.
        """
        if not self.armed or not self._stages:
            return False
        stage = self._stages[0]
        takeoff = stage.kind == "leg" and stage.vertical_only
        return takeoff and (not self.landed or self._lifting_off())

    # ------------------------------------------------------------------ stages
    def _speed_xy(self, stage: Stage) -> float:
        if stage.speed_xy_m_s is not None:
            return stage.speed_xy_m_s
        if self._speed_override_m_s is not None:
            return self._speed_override_m_s
        return self.settings.flight.wp_speed_m_s

    def _leg_start(self) -> np.ndarray:
        pos = self.pos_ned_m
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - pos)) < 2.0:
            return self._ref_pos.copy()
        return pos

    def _advance_stages(self, t: float) -> None:
        while self._stages:
            stage = self._stages[0]
            if stage.started_s is None:
                stage.started_s = t
                if stage.kind == "leg":
                    f = self.settings.flight
                    speed_xy = self._speed_xy(stage)
                    up = f.takeoff_speed_m_s if stage.vertical_only else f.wp_speed_up_m_s
                    stage.leg = Leg(self._leg_start(), stage.target, speed_xy, up, f.wp_speed_down_m_s,
                                    f.wp_accel_m_s2, t)
                elif stage.kind == "hold" and stage.target is None:
                    stage.target = self._hold_target()
                elif stage.kind == "land":
                    stage.target = self._leg_start()
            if not self._stage_done(stage, t):
                return
            self._stages.pop(0)
            if stage.kind in ("leg", "hold") and stage.target is not None:
                self._ref_pos = stage.target.copy()
            if not self._stages and self._item_active and self.mode == AUTO:
                self._complete_item()
                return

    def _stage_done(self, stage: Stage, t: float) -> bool:
        if stage.kind == "leg":
            if not stage.leg.finished(t):
                return False
            radius = stage.radius_m if stage.radius_m > 0 else self.settings.flight.wp_radius_m
            if float(np.linalg.norm(self.pos_ned_m - stage.target)) > radius:
                return False
            return True
        if stage.kind == "hold":
            if stage.duration_s is None:
                return False
            return t - stage.started_s >= stage.duration_s
        if stage.kind == "direct":
            if self._guided is None or t - self._guided.received_s > self.settings.flight.guided_timeout_s:
                log.warning("GUIDED: no setpoint for %.1f s (GUID_TIMEOUT): braking to a hover",
                            self.settings.flight.guided_timeout_s)
                self._events.append(("text", 4, "GUIDED setpoint timeout: braking"))
                self._guided = None
                self._stages.insert(1, Stage("hold", target=self._brake_point()))
                return True
            return False
        return False  # land ends at touchdown

    def _setpoint(self, t: float) -> Setpoint:
        stage = self._stages[0] if self._stages else None
        if stage is None:
            target = self._hold_target()
            self._stages = [Stage("hold", target=target, started_s=t)]
            stage = self._stages[0]
        if stage.kind == "leg":
            pos, vel, acc = stage.leg.sample(t)
            self._ref_pos = pos
            return Setpoint(pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc, yaw_rad=self._yaw_hold_rad)
        if stage.kind == "hold":
            self._ref_pos = stage.target
            return Setpoint(pos_ned_m=stage.target, vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self._yaw_hold_rad)
        if stage.kind == "land":
            return self._land_setpoint(stage)
        if stage.kind == "direct" and self._guided is not None:
            sp = _integrate_target(self._guided.setpoint, t - self._guided.received_s)
            if sp.yaw_rad is None and sp.yaw_rate_rad_s is None:
                sp = dataclasses.replace(sp, yaw_rad=self._yaw_hold_rad)
            if sp.pos_ned_m is not None:
                self._ref_pos = np.asarray(sp.pos_ned_m, dtype=float)
            else:
                self._ref_pos = None
            return sp
        return Setpoint(pos_ned_m=self._hold_target(), vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=self._yaw_hold_rad)

    def _land_setpoint(self, stage: Stage) -> Setpoint:
        f = self.settings.flight
        height = -float(self.x[16])
        speed = f.land_speed_high_m_s if height > f.land_slow_alt_m else f.land_speed_m_s
        target = stage.target
        return Setpoint(pos_ned_m=(target[0], target[1], float("nan")), vel_ned_m_s=(0.0, 0.0, speed),
                        yaw_rad=self._yaw_hold_rad)

    def _hold_target(self) -> np.ndarray:
        if self._ref_pos is not None and float(np.linalg.norm(self._ref_pos - self.pos_ned_m)) < 2.0:
            return np.asarray(self._ref_pos, dtype=float).copy()
        return self._brake_point()

    def _brake_point(self) -> np.ndarray:
        """Where the vehicle stops when braking at ``brake_accel_m_s2`` from its current velocity."""
        pos = self.pos_ned_m
        vel = self.vel_ned_m_s
        speed = float(np.linalg.norm(vel))
        stop = pos + vel * speed / (2.0 * self.settings.flight.brake_accel_m_s2)
        stop[2] = min(stop[2], 0.0)
        return stop

    def _fill_nan(self, target: np.ndarray) -> np.ndarray:
        base = self._hold_target()
        return np.where(np.isfinite(target), target, base)

    def _yaw_target(self, sp: Setpoint) -> float:
        if sp.yaw_rad is not None:
            return float(sp.yaw_rad)
        return self._yaw_hold_rad

    def _takeoff_stage(self, alt_m: float) -> Stage:
        """Climb straight up to ``alt_m`` above home."""
        pos = self.pos_ned_m
        down = self.frames.down_at_height_above_home(float(alt_m))
        return Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=0.5, vertical_only=True)

    def _rtl_stages(self) -> list[Stage]:
        f = self.settings.flight
        pos = self.pos_ned_m
        height = self.frames.height_above_home(pos)
        alt_m = max(f.rtl_alt_m, height)
        down = min(self.frames.down_at_height_above_home(alt_m), float(pos[2]))
        stages = []
        if height < alt_m - 0.5:
            stages.append(Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=1.0))
        destination = self._rtl_destination(pos)
        stages.append(Stage("leg", target=np.array([destination[0], destination[1], down])))
        stages.append(Stage("land"))
        return stages

    def _rtl_destination(self, pos: np.ndarray) -> np.ndarray:
        """Nearest (horizontally) of home and the rally points."""
        candidates = [self.frames.home_ground_ned_m.copy()] + list(self.rally_ned_m)
        distances = [math.hypot(c[0] - pos[0], c[1] - pos[1]) for c in candidates]
        best = candidates[int(np.argmin(distances))]
        if best is not candidates[0]:
            log.info("RTL to rally point at N %.1f E %.1f", best[0], best[1])
        return best

    # ------------------------------------------------------------------ mission
    def _resume_seq(self) -> int:
        """Where AUTO (re)starts: the current item, or item 1 after a completed mission."""
        if self.mission_finished or not 1 <= self.mission_current < len(self.mission_items):
            return 1
        return self.mission_current

    def _start_mission(self, seq: int) -> None:
        self.mission_finished = False
        self._item_active = False
        self._stages = []
        self.mission_current = seq
        self._events.append(("mission_current", seq))
        log.info("AUTO: mission from item %d", seq)

    def _advance_mission(self, t: float) -> None:
        guard = 0
        while not self._item_active and not self.mission_finished and guard < len(self.mission_items) + 1:
            guard += 1
            if not 1 <= self.mission_current < len(self.mission_items):
                self._finish_mission()
                return
            item = self.mission_items[self.mission_current]
            stages = self._item_stages(item)
            if stages is None:  # a DO command or an unsupported one: done at once
                self._advance_item(reached=False)
                continue
            self._stages = stages
            self._item_active = True

    def _complete_item(self) -> None:
        self._item_active = False
        self._advance_item(reached=True)

    def _advance_item(self, reached: bool) -> None:
        seq = self.mission_current
        if reached:
            self._events.append(("mission_item_reached", seq))
            log.info("AUTO: reached item %d", seq)
        if seq + 1 < len(self.mission_items):
            self.mission_current = seq + 1
            self._events.append(("mission_current", self.mission_current))
        else:
            self._finish_mission()

    def _finish_mission(self) -> None:
        if not self.mission_finished:
            self.mission_finished = True
            log.info("AUTO: mission complete")
            self._events.append(("text", 6, "Mission complete"))
        if self.armed and not self.landed and not self._stages:
            self._stages = [Stage("hold", target=self._hold_target())]

    def item_target_ned_m(self, item: MissionItem) -> np.ndarray:
        """Target of a mission item in NED, m; a missing position keeps the current one."""
        pos = self.pos_ned_m
        has_position = not (item.x == 0 and item.y == 0)
        if item.frame == FRAME_LOCAL_NED:  # metres from the EKF origin, as in ArduPilot
            return self.frames.from_local((item.x * 1e-4, item.y * 1e-4, item.z))
        if item.frame == FRAME_MISSION or not has_position:
            north, east = pos[0], pos[1]
        else:
            alt_amsl = item.z if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else self.frames.home_alt_m + item.z
            north, east, _ = self.frame.to_ned(item.lat_deg, item.lon_deg, alt_amsl)
        if item.frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
            down = -(item.z - self.frame.alt0_m)
        else:  # relative altitudes are above home
            down = self.frames.down_at_height_above_home(item.z)
        return np.array([north, east, down])

    def _item_stages(self, item: MissionItem) -> list[Stage] | None:
        cmd = item.command
        if cmd == CMD_DO_CHANGE_SPEED:
            speed = item.param2
            if math.isfinite(speed) and speed > 0:
                self._speed_override_m_s = min(speed, self.settings.flight.max_speed_m_s)
                log.info("AUTO: speed %.1f m/s (DO_CHANGE_SPEED)", self._speed_override_m_s)
            return None
        if cmd not in NAV_COMMANDS:
            log.info("AUTO: item %d command %d not simulated; skipped", item.seq, cmd)
            return None
        if cmd == CMD_NAV_TAKEOFF:
            alt_m = item.z if item.frame not in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else item.z - self.frames.home_alt_m
            if self.height_above_home_m >= alt_m - 0.5:
                return [Stage("hold", duration_s=0.0)]
            return [self._takeoff_stage(alt_m)]
        if cmd == CMD_NAV_RETURN_TO_LAUNCH:
            return self._rtl_stages()
        target = self.item_target_ned_m(item)
        if cmd == CMD_NAV_LAND:
            stages = []
            pos = self.pos_ned_m
            if not (item.x == 0 and item.y == 0) and math.hypot(target[0] - pos[0], target[1] - pos[1]) > 0.5:
                stages.append(Stage("leg", target=np.array([target[0], target[1], min(pos[2], -1.0)])))
            stages.append(Stage("land"))
            return stages
        if target[2] > -1.0 and not self.landed:
            target[2] = -1.0  # never fly a leg into the ground; land items do that
        radius = item.param2 if cmd == CMD_NAV_WAYPOINT and math.isfinite(item.param2) and item.param2 > 0 else 0.0
        stages = [Stage("leg", target=target, radius_m=radius)]
        if cmd == CMD_NAV_WAYPOINT and math.isfinite(item.param1) and item.param1 > 0:
            stages.append(Stage("hold", target=target, duration_s=float(item.param1)))
        elif cmd == CMD_NAV_LOITER_TIME:
            stages.append(Stage("hold", target=target, duration_s=max(0.0, float(item.param1))))
        elif cmd == CMD_NAV_LOITER_UNLIM:
            stages.append(Stage("hold", target=target, duration_s=None))
        return stages


#: Longest time a GUIDED target is integrated forward (simulated s); beyond it the target stays.
TARGET_INTEGRATION_MAX_S = 0.5


def _integrate_target(sp: Setpoint, age_s: float) -> Setpoint:
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


def _check_setpoint(sp: Setpoint, max_speed_m_s: float) -> Setpoint | str:
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
    return Setpoint(pos_ned_m=out["pos_ned_m"], vel_ned_m_s=out["vel_ned_m_s"], acc_ned_m_s2=out["acc_ned_m_s2"],
                    yaw_rad=sp.yaw_rad, yaw_rate_rad_s=sp.yaw_rate_rad_s)
