"""Vehicle behaviour of the SITL helicopter: modes, arming, takeoff, landing, RTL, AUTO missions.

Behaves like ArduCopter (https://ardupilot.org/copter/docs/flight-modes.html) with the mode
numbers of DESIGN section 5 (STABILIZE 0, ALT_HOLD 2, AUTO 3, GUIDED 4, LOITER 5, RTL 6,
LAND 9, BRAKE 17; taken from pymavlink through :mod:`heli_common.mavlink_ids`); with no RC pilot, STABILIZE and ALT_HOLD hold position like LOITER. The
flight controller is the paper's LQI with the PID position loop (section 2.2,
:mod:`heli_model.control`); this package only decides *what* it tracks:

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

Physics runs at ``timing.physics_rate_hz`` (400 Hz) with RK4 (:mod:`heli_model.dynamics`)
and the controller at ``timing.control_rate_hz`` (100 Hz), both in the pure vehicle update
(:mod:`heli_model.vehicle_update`). Pure simulation: no I/O.

The package, modelled on ArduCopter's sources: :class:`Autopilot` holds one collaborator per
concern as a member (not inherited), each built with what it needs; the modes act on the small
interface :class:`ModeContext`.

==============================  ===========================================================
``core``                        :class:`Autopilot`: mode switching, arming, the ticks
``mode_context``                :class:`ModeContext`: what the modes may use of the vehicle
``mode``, ``mode_*``            the flight modes (``mode.h``, ``mode_auto.cpp``, ...)
``airframe``                    :class:`Airframe`: the pure vehicle update, its state, wind
``mission``                     :class:`Mission`: mission and rally lists, items to stages
                                (``AP_Mission``)
``navigation``                  :class:`Navigation`: the stages flown and their setpoints
                                (``AC_WPNav``)
``legs``                        :class:`Leg` (trapezoidal speed profile), :class:`Stage`,
                                :class:`GuidedCommand`
``fence``                       :class:`Geofence`: polygon and circle fences, breach action
                                (``AC_Fence``)
``ground_contact``              :class:`GroundContact`: lift-off, touchdown, auto-disarm
                                (``land_detector.cpp``)
``arming``                      :class:`Arming`: arming, pre-arm checks, motor interlock
                                (``AP_Arming``)
==============================  ===========================================================
"""

from heli_common.geometry import point_in_polygon
from sim_vehicle.autopilot.airframe import Airframe
from sim_vehicle.autopilot.arming import MAV_SEVERITY_CRITICAL, PREARM_REPORT_PERIOD_S, Arming
from sim_vehicle.autopilot.core import MODES, Autopilot
from sim_vehicle.autopilot.fence import (
    CMD_FENCE_CIRCLE_EXCLUSION,
    CMD_FENCE_CIRCLE_INCLUSION,
    CMD_FENCE_POLYGON_EXCLUSION,
    CMD_FENCE_POLYGON_INCLUSION,
    FENCE_ACTION_MODES,
    Fence,
    Geofence,
    fence_breach,
    fence_from_items,
)
from sim_vehicle.autopilot.ground_contact import LIFTOFF_HEIGHT_M, TOUCHDOWN_HEIGHT_M, GroundContact
from sim_vehicle.autopilot.legs import GuidedCommand, Leg, Stage
from sim_vehicle.autopilot.mission import (
    CMD_DO_CHANGE_SPEED,
    CMD_NAV_LAND,
    CMD_NAV_LOITER_TIME,
    CMD_NAV_LOITER_UNLIM,
    CMD_NAV_RALLY_POINT,
    CMD_NAV_RETURN_TO_LAUNCH,
    CMD_NAV_TAKEOFF,
    CMD_NAV_WAYPOINT,
    NAV_COMMANDS,
    Mission,
)
from sim_vehicle.autopilot.mode import (
    ALT_HOLD,
    AUTO,
    BRAKE,
    GUIDED,
    LAND,
    LOITER,
    MODE_NAMES,
    MODE_NUMBERS,
    RTL,
    STABILIZE,
    Mode,
    QuietRefusal,
    mode_name,
)
from sim_vehicle.autopilot.mode_context import ModeContext
from sim_vehicle.autopilot.mode_guided import (
    MAX_TAKEOFF_ALT_M,
    TARGET_INTEGRATION_MAX_S,
    check_setpoint,
    integrate_target,
)
from sim_vehicle.autopilot.navigation import Navigation

__all__ = [
    "Airframe",
    "Arming",
    "Geofence",
    "GroundContact",
    "Mission",
    "ModeContext",
    "Navigation",
    "ALT_HOLD",
    "AUTO",
    "BRAKE",
    "CMD_DO_CHANGE_SPEED",
    "CMD_FENCE_CIRCLE_EXCLUSION",
    "CMD_FENCE_CIRCLE_INCLUSION",
    "CMD_FENCE_POLYGON_EXCLUSION",
    "CMD_FENCE_POLYGON_INCLUSION",
    "CMD_NAV_LAND",
    "CMD_NAV_LOITER_TIME",
    "CMD_NAV_LOITER_UNLIM",
    "CMD_NAV_RALLY_POINT",
    "CMD_NAV_RETURN_TO_LAUNCH",
    "CMD_NAV_TAKEOFF",
    "CMD_NAV_WAYPOINT",
    "FENCE_ACTION_MODES",
    "GUIDED",
    "LAND",
    "LIFTOFF_HEIGHT_M",
    "LOITER",
    "MAV_SEVERITY_CRITICAL",
    "MAX_TAKEOFF_ALT_M",
    "MODES",
    "MODE_NAMES",
    "MODE_NUMBERS",
    "NAV_COMMANDS",
    "PREARM_REPORT_PERIOD_S",
    "RTL",
    "STABILIZE",
    "TARGET_INTEGRATION_MAX_S",
    "TOUCHDOWN_HEIGHT_M",
    "Autopilot",
    "Fence",
    "GuidedCommand",
    "Leg",
    "Mode",
    "QuietRefusal",
    "Stage",
    "check_setpoint",
    "fence_breach",
    "fence_from_items",
    "integrate_target",
    "mode_name",
    "point_in_polygon",
]
