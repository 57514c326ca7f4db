"""Telemetry messages of ``sim-vehicle``: one builder per message, fields as ArduCopter fills them.

Positions: GLOBAL_POSITION_INT ``relative_alt`` is above home; LOCAL_POSITION_NED is NED from
the EKF origin (:mod:`sim_vehicle.frames`); HOME_POSITION carries home and, in ``x, y, z``, its
NED position from the origin (with the NaN quaternion the reference firmware sends);
GPS_GLOBAL_ORIGIN the origin. SERVO_OUTPUT_RAW holds the four swashplate/tail inputs and the
rotor speed controller's output on servo 8; RPM the rotor speed; RC_CHANNELS the RC input (RC8
drives the motor interlock). ADSB_VEHICLE reports one simulated aircraft per message in
ArduPilot's round robin (:class:`sim_vehicle.adsb.RoundRobin`, kept per link).

:meth:`Telemetry.build` returns an encoded-ready pymavlink message (or None when there is
nothing to send, e.g. no traffic); the server decides where it goes.
"""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.adsb import RoundRobin, TrafficModel
from sim_vehicle.autopilot import Autopilot
from sim_vehicle.clock import SimClock
from sim_vehicle.mission_store import MISSION_TYPE_MISSION, MissionStore
from sim_vehicle.streams import LinkStreams

FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (0 << 8) | 255  # "4.5.0 official", like ArduCopter 4.5
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)
SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_AHRS
)
ADSB_FLAGS = (
    mavlink.ADSB_FLAGS_VALID_COORDS
    | mavlink.ADSB_FLAGS_VALID_ALTITUDE
    | mavlink.ADSB_FLAGS_VALID_HEADING
    | mavlink.ADSB_FLAGS_VALID_VELOCITY
    | mavlink.ADSB_FLAGS_VALID_CALLSIGN
    | mavlink.ADSB_FLAGS_VALID_SQUAWK
    | mavlink.ADSB_FLAGS_SIMULATED
    | mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
    | mavlink.ADSB_FLAGS_BARO_VALID
)
"""511, as the reference firmware reports its simulated traffic."""
ADSB_SQUAWK_VFR = 1200
RC_CHANNEL_COUNT = 16
NAN_QUATERNION = [math.nan] * 4


class Telemetry:
    """Builds the vehicle's messages.

    Parameters
    ----------
    mav : pymavlink MAVLink
        Encoder with the vehicle's ids.
    autopilot : Autopilot
        The vehicle.
    clock : SimClock
        Simulated time (``time_boot_ms``).
    store : MissionStore
        Mission lists (MISSION_CURRENT's total).
    traffic : TrafficModel
        Simulated ADS-B aircraft.
    sysid : int
        Own system id (AUTOPILOT_VERSION uid).
    dropped : callable
        Returns the count of malformed packets dropped (SYS_STATUS ``errors_comm``).
    """

    def __init__(
        self,
        mav: Any,
        autopilot: Autopilot,
        clock: SimClock,
        store: MissionStore,
        traffic: TrafficModel,
        sysid: int,
        dropped: Any = lambda: 0,
    ) -> None:
        self.mav = mav
        self.autopilot = autopilot
        self.clock = clock
        self.store = store
        self.traffic = traffic
        self.sysid = sysid
        self.dropped = dropped

    def build(self, name: str, link: LinkStreams | None = None) -> Any | None:
        """The message ``name`` now (None: nothing to send; ADSB_VEHICLE keeps its turn per link)."""
        builder = getattr(self, f"msg_{name.lower()}", None)
        if builder is None:
            return None
        if name == "ADSB_VEHICLE":
            return builder(link)
        return builder()

    def time_boot_ms(self) -> int:
        """Simulated time since start, ms (uint32)."""
        return int(self.clock.time_s * 1000.0) & 0xFFFFFFFF

    def _time_usec(self) -> int:
        return int(self.clock.time_s * 1e6)

    # ------------------------------------------------------------------ status
    def msg_heartbeat(self) -> Any:
        a = self.autopilot
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if a.mode in (ap.GUIDED, ap.AUTO, ap.RTL, ap.LOITER, ap.LAND, ap.BRAKE):
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        if a.mode == ap.AUTO:
            base |= mavlink.MAV_MODE_FLAG_AUTO_ENABLED
        if a.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink.MAV_STATE_ACTIVE if a.armed else mavlink.MAV_STATE_STANDBY
        return self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, a.mode, status
        )

    def msg_sys_status(self) -> Any:
        return self.mav.sys_status_encode(
            SENSORS,
            SENSORS,
            SENSORS,
            250,
            22200,
            1000 if self.autopilot.armed else 0,
            100,
            0,
            self.dropped() & 0xFFFF,
            0,
            0,
            0,
            0,
        )

    def msg_extended_sys_state(self) -> Any:
        a = self.autopilot
        if a.ground.taking_off:
            state = mavlink.MAV_LANDED_STATE_TAKEOFF
        elif a.landed:
            state = mavlink.MAV_LANDED_STATE_ON_GROUND
        elif a.navigation.landing:
            state = mavlink.MAV_LANDED_STATE_LANDING
        else:
            state = mavlink.MAV_LANDED_STATE_IN_AIR
        return self.mav.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_MC, state)  # as ArduCopter sends it

    def msg_mission_current(self) -> Any:
        a = self.autopilot
        total = len(self.store.items(MISSION_TYPE_MISSION))
        if total == 0:
            state = mavlink.MISSION_STATE_NO_MISSION
        elif a.mission.finished:
            state = mavlink.MISSION_STATE_COMPLETE
        elif a.mode == ap.AUTO and a.armed:
            state = mavlink.MISSION_STATE_ACTIVE
        else:
            state = mavlink.MISSION_STATE_NOT_STARTED
        return self.mav.mission_current_encode(a.mission.current, total, state, 1 if a.mode == ap.AUTO else 2)

    def msg_system_time(self) -> Any:
        return self.mav.system_time_encode(int(time.time() * 1e6), self.time_boot_ms())

    def msg_autopilot_version(self) -> Any:
        return self.mav.autopilot_version_encode(
            CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x5157_0000 + self.sysid
        )

    # ------------------------------------------------------------------ position and attitude
    def msg_global_position_int(self) -> Any:
        a = self.autopilot
        lat, lon, alt = a.position_lla()
        vel = a.vel_ned_m_s
        heading = math.degrees(a.euler_rad[2]) % 360.0
        relative_mm = (alt - a.frames.home_alt_m) * 1000.0
        return self.mav.global_position_int_encode(
            self.time_boot_ms(),
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1000.0)),
            int(round(relative_mm)),
            _i16(vel[0] * 100.0),
            _i16(vel[1] * 100.0),
            _i16(vel[2] * 100.0),
            int(round(heading * 100.0)) % 36000,
        )

    def msg_local_position_ned(self) -> Any:
        a = self.autopilot
        p, v = a.local_ned_m, a.vel_ned_m_s
        return self.mav.local_position_ned_encode(self.time_boot_ms(), p[0], p[1], p[2], v[0], v[1], v[2])

    def msg_attitude(self) -> Any:
        a = self.autopilot
        roll, pitch, yaw = a.euler_rad
        p, q, r = a.airframe.body_rates_rad_s
        return self.mav.attitude_encode(self.time_boot_ms(), roll, pitch, yaw, p, q, r)

    def msg_vfr_hud(self) -> Any:
        a = self.autopilot
        v = a.vel_ned_m_s
        ground = math.hypot(v[0], v[1])
        air = float(math.hypot(*(v[:2] - a.airframe.wind.current()[:2])))
        heading = int(round(math.degrees(a.euler_rad[2]))) % 360
        collective = a.airframe.delta[3]
        throttle = int(round(min(100.0, max(0.0, 50.0 + 50.0 * collective)))) if a.armed and not a.landed else 0
        _, _, alt = a.position_lla()
        return self.mav.vfr_hud_encode(air, ground, heading, throttle, alt, -v[2])

    def msg_gps_raw_int(self) -> Any:
        a = self.autopilot
        lat, lon, alt = a.position_lla()
        v = a.vel_ned_m_s
        cog = int(round(math.degrees(math.atan2(v[1], v[0])) % 360.0 * 100.0)) % 36000
        return self.mav.gps_raw_int_encode(
            self._time_usec(),
            3,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1000.0)),
            70,
            90,
            int(round(math.hypot(v[0], v[1]) * 100.0)),
            cog,
            14,
        )

    def msg_home_position(self) -> Any:
        frames = self.autopilot.frames
        lat, lon, alt = frames.home_lla
        x, y, z = (float(v) for v in frames.home_local_ned_m)
        return self.mav.home_position_encode(
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1000.0)),
            x,
            y,
            z,
            NAN_QUATERNION,
            0.0,
            0.0,
            0.0,
            self._time_usec(),
        )

    def msg_gps_global_origin(self) -> Any:
        lat, lon, alt = self.autopilot.frames.origin_lla
        return self.mav.gps_global_origin_encode(
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)), self._time_usec()
        )

    # ------------------------------------------------------------------ rotor, servos, RC
    def msg_servo_output_raw(self) -> Any:
        a = self.autopilot
        us = [int(round(1500.0 + 500.0 * max(-1.0, min(1.0, float(v))))) for v in a.airframe.delta]
        rsc_us = rsc.output_pwm_us(a.arming.rotor, a.settings.rsc)
        # servo1 lateral cyclic, servo2 longitudinal cyclic, servo3 collective, servo4 tail rotor, servo8 RSC
        return self.mav.servo_output_raw_encode(
            self._time_usec() & 0xFFFFFFFF, 0, us[0], us[1], us[3], us[2], 0, 0, 0, rsc_us
        )

    def msg_rpm(self) -> Any:
        return self.mav.rpm_encode(float(self.autopilot.arming.rotor.speed * rsc.ROTOR_RPM_NOMINAL), -1.0)

    def msg_rc_channels(self) -> Any:
        channels = [1500] * 8 + [0] * 10
        channels[7] = self.autopilot.arming.rc8_us
        return self.mav.rc_channels_encode(self.time_boot_ms(), RC_CHANNEL_COUNT, *channels, 255)

    # ------------------------------------------------------------------ traffic
    def msg_adsb_vehicle(self, link: LinkStreams | None = None) -> Any | None:
        """The next simulated aircraft of ``link``'s round robin (None when it is not its turn)."""
        aircraft = self.traffic.aircraft
        turn = link.extra.setdefault("adsb", RoundRobin()) if link is not None else RoundRobin()
        index = turn.next(len(aircraft), self.clock.time_s)
        if index is None:
            return None
        plane = aircraft[index]
        lat, lon, alt = self.autopilot.frames.to_lla(plane.pos_ned_m)
        return self.mav.adsb_vehicle_encode(
            plane.icao_address,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            mavlink.ADSB_ALTITUDE_TYPE_PRESSURE_QNH,
            int(round(alt * 1000.0)),
            int(round(plane.heading_deg * 100.0)) % 36000,
            int(round(plane.ground_speed_m_s * 100.0)),
            _i16(-plane.vel_ned_m_s[2] * 100.0),
            plane.callsign.encode()[:9],
            plane.emitter_type,
            1,
            ADSB_FLAGS,
            ADSB_SQUAWK_VFR,
        )


def _i16(value: float) -> int:
    return int(max(-32768, min(32767, round(value))))


__all__ = ["Telemetry", "CAPABILITIES", "FLIGHT_SW_VERSION", "ADSB_FLAGS"]
