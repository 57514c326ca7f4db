"""The vehicle's MAVLink side composed of its rooms, and the table that routes each message to one.

Implements the MAVLink contract of DESIGN section 5 the way ArduPilot's SITL presents itself
(https://mavlink.io/en/services/): HEARTBEAT as an ArduCopter helicopter at 1 Hz of wall-clock
time and nothing else unasked; telemetry streams per link, only as requested
(:mod:`~sim_vehicle.mavlink.stream_sender`); every COMMAND_LONG / COMMAND_INT addressed to the
vehicle answered with a COMMAND_ACK (:mod:`~sim_vehicle.mavlink.commands`); the mission protocol
for the mission, fence and rally lists with atomic replacement
(:mod:`~sim_vehicle.mavlink.mission_protocol`); the parameter protocol
(:mod:`~sim_vehicle.mavlink.param_protocol`); GUIDED setpoints
(:mod:`~sim_vehicle.mavlink.guided`); TIMESYNC; the motor interlock (DO_AUX_FUNCTION 32 and
RC_CHANNELS_OVERRIDE of RC8 from MAV_GCS_SYSID, :mod:`sim_vehicle.rsc`) and simulated ADS-B
traffic (:mod:`sim_vehicle.adsb`). A STATUSTEXT from another component (a companion) is
forwarded to the other links, as ArduPilot's routing does
(:mod:`~sim_vehicle.mavlink.endpoint`, which also owns the socket, the peers, signing and the
counters). The real-time loop that drives all this is :mod:`sim_vehicle.realtime`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle.adsb import TrafficModel
from sim_vehicle.autopilot import Autopilot
from sim_vehicle.clock import SimClock
from sim_vehicle.config import VehicleSettings
from sim_vehicle.mavlink.commands import CommandProtocol
from sim_vehicle.mavlink.endpoint import COMPONENT_ID, Address, Endpoint, LinkStats
from sim_vehicle.mavlink.guided import GuidedSetpoints
from sim_vehicle.mavlink.missions import MissionProtocols
from sim_vehicle.mavlink.param_protocol import ParamProtocol
from sim_vehicle.mavlink.stream_sender import StreamSender
from sim_vehicle.mission_store import MissionStore
from sim_vehicle.params import ParameterTable
from sim_vehicle.streams import StreamTable
from sim_vehicle.telemetry import Telemetry

log = logging.getLogger(__name__)


class MavlinkServer:
    """The vehicle's MAVLink endpoint: receives, dispatches, answers, and sends what is due.

    Parameters
    ----------
    autopilot : Autopilot
        The simulated vehicle.
    settings : VehicleSettings
        Settings tree (link, timing, streams).
    sysid : int
        MAVLink system id (component is 1).
    port : int
        UDP port to bind.
    tlog_path : str, optional
        Write every packet in and out to this ``.tlog`` file.
    wall_s : callable
        Monotonic wall clock (tests may inject one).
    traffic : TrafficModel, optional
        Simulated ADS-B aircraft (default: ``settings.adsb`` with a generator seeded by
        ``settings.seed``).
    signing_key : bytes, optional
        MAVLink 2 signing key: sign everything sent, accept only what is signed with it
        (:mod:`sim_vehicle.signing`).
    accept_signing_setup : bool
        Take SETUP_SIGNING while there is no signing key.
    """

    def __init__(
        self,
        autopilot: Autopilot,
        settings: VehicleSettings,
        sysid: int,
        port: int,
        tlog_path: str | None = None,
        wall_s: Callable[[], float] = time.monotonic,
        traffic: TrafficModel | None = None,
        signing_key: bytes | None = None,
        accept_signing_setup: bool = False,
    ) -> None:
        self.autopilot = autopilot
        self.sysid = int(sysid)
        self.wall_s = wall_s
        self.params = ParameterTable(settings)
        self.store = MissionStore(settings.link.mission_upload_timeout_s)
        self.clock = SimClock(settings.timing.physics_dt_s, settings.timing.speedup, settings.timing.max_lag_s, wall_s)
        link = settings.link
        self.endpoint = Endpoint(
            self.sysid,
            link.bind_host,
            port,
            link.out,
            link.peer_timeout_s,
            self._dispatch,
            tlog_path,
            wall_s,
            signing_key,
            accept_signing_setup,
        )
        if traffic is None:
            import numpy as np

            traffic = TrafficModel(settings.adsb, np.random.default_rng([settings.seed, 0xAD5B]))
        self.traffic = traffic
        self.telemetry = Telemetry(
            self.endpoint.mav,
            autopilot,
            self.clock,
            self.store,
            traffic,
            self.sysid,
            lambda: self.endpoint.stats.dropped,
        )
        streams = StreamTable(self.endpoint.outs, [link.mav1.as_groups(), link.mav2.as_groups(), link.mav3.as_groups()])
        self.sender = StreamSender(self.endpoint, self.telemetry, streams, self.clock, self.params)
        self.commands = CommandProtocol(self.endpoint, autopilot, self.telemetry, self.sender)
        self.missions = MissionProtocols(self.endpoint, self.store, autopilot, self.telemetry)
        self.param_protocol = ParamProtocol(self.params, self.endpoint, self._apply_settings)
        self.guided = GuidedSetpoints(autopilot, self.endpoint.throttle)
        self._origin_announced = False
        self._handlers: dict[str, Callable[[Any, Address], None]] = {
            "COMMAND_LONG": self.commands.on_command_long,
            "COMMAND_INT": self.commands.on_command_int,
            "SET_MODE": self.commands.on_set_mode,
            "REQUEST_DATA_STREAM": self.sender.on_request_data_stream,
            "RC_CHANNELS_OVERRIDE": self._on_rc_channels_override,
            "TIMESYNC": self._on_timesync,
            "SET_POSITION_TARGET_LOCAL_NED": self.guided.on_set_position_target_local_ned,
            "SET_POSITION_TARGET_GLOBAL_INT": self.guided.on_set_position_target_global_int,
            "MISSION_COUNT": self.missions.on_mission_count,
            "MISSION_ITEM_INT": self.missions.on_mission_item_int,
            "MISSION_ITEM": self.missions.on_mission_item,
            "MISSION_REQUEST_LIST": self.missions.on_mission_request_list,
            "MISSION_REQUEST_INT": self.missions.on_mission_request_int,
            "MISSION_REQUEST": self.missions.on_mission_request,
            "MISSION_CLEAR_ALL": self.missions.on_mission_clear_all,
            "MISSION_SET_CURRENT": self.missions.on_mission_set_current,
            "MISSION_ACK": self.missions.on_mission_ack,
            "PARAM_REQUEST_LIST": self.param_protocol.on_param_request_list,
            "PARAM_REQUEST_READ": self.param_protocol.on_param_request_read,
            "PARAM_SET": self.param_protocol.on_param_set,
            "SETUP_SIGNING": self.endpoint.on_setup_signing,
        }
        """The message dispatch table: message type to the room's handler ``handler(msg, address)``."""

    # ---------------------------------------------------------------- state the rooms share
    @property
    def settings(self) -> VehicleSettings:
        """The current settings tree (kept by the parameter table, which PARAM_SET changes)."""
        return self.params.settings

    @property
    def stats(self) -> LinkStats:
        return self.endpoint.stats

    @property
    def sock(self) -> Any:
        """The UDP socket (tests put a stand-in here)."""
        return self.endpoint.sock

    @sock.setter
    def sock(self, sock: Any) -> None:
        self.endpoint.sock = sock

    def close(self) -> None:
        """Close the socket and the tlog."""
        self.endpoint.close()

    # ---------------------------------------------------------------- what the real-time loop calls
    def receive(self) -> None:
        """Handle the datagrams waiting in the socket."""
        self.endpoint.receive()

    def handle_datagram(self, data: bytes, address: Address) -> None:
        """Handle one datagram from ``address``."""
        self.endpoint.handle_datagram(data, address)

    def send_heartbeat(self) -> None:
        self.sender.send_heartbeat()

    def send_due_streams(self) -> None:
        self.sender.send_due()

    def on_heartbeat_period(self) -> None:
        """Each wall-clock second: signing timestamps, HEARTBEAT, and once at the start home and origin."""
        self.endpoint.signing.tick()
        self.sender.send_heartbeat()
        if not self._origin_announced:  # origin and home are set at start: ArduPilot announces both
            self._origin_announced = True
            self.sender.send_home_and_origin()

    def housekeeping(self) -> None:
        """A few times a second: mission uploads timed out or waiting for a retry."""
        self.missions.update()

    def handle_events(self, events: list[tuple]) -> None:
        """Tell the links what the vehicle reported while stepping (``Autopilot.run_steps``)."""
        send, statustext = self.endpoint.send, self.endpoint.statustext
        for event in events:
            kind = event[0]
            if kind == "mission_item_reached":
                send(self.endpoint.mav.mission_item_reached_encode(event[1]))
                statustext(mavlink.MAV_SEVERITY_INFO, f"Reached waypoint #{event[1]}")
            elif kind == "mission_current":
                send(self.telemetry.msg_mission_current())
            elif kind == "mode":
                self.sender.send_heartbeat()
            elif kind in ("armed", "disarmed"):
                self.sender.send_heartbeat()
                text = "Arming motors" if kind == "armed" else f"Disarming motors ({event[1]})"
                statustext(mavlink.MAV_SEVERITY_INFO, text)
            elif kind == "text":
                statustext(event[1], event[2])

    # the names the in-process tests (tests/unit/sim_vehicle, tests/unit/fuzz) and benchmarks/soak.py drive
    _receive = receive
    _handle_datagram = handle_datagram
    _send_heartbeat = send_heartbeat
    _send_due_streams = send_due_streams
    _handle_events = handle_events

    # ---------------------------------------------------------------- dispatch
    def _for_us(self, msg: Any) -> bool:
        target = getattr(msg, "target_system", 0)
        comp = getattr(msg, "target_component", 0)
        return target in (0, self.sysid) and comp in (0, COMPONENT_ID, mavlink.MAV_COMP_ID_ALL)

    def _dispatch(self, msg: Any, address: Address) -> None:
        handler = self._handlers.get(msg.get_type())
        if handler is None or not self._for_us(msg):
            self.endpoint.stats.ignored += 1
            return
        handler(msg, address)

    def _on_rc_channels_override(self, msg: Any, address: Address) -> None:
        """RC8 override (motor interlock switch); only from MAV_GCS_SYSID, as ArduPilot accepts it."""
        gcs_sysid = self.settings.link.gcs_sysid
        if msg.get_srcSystem() != gcs_sysid:
            if self.endpoint.throttle.count(f"rc_override:{msg.get_srcSystem()}") <= 3:
                log.info(
                    "RC_CHANNELS_OVERRIDE from system %d ignored (MAV_GCS_SYSID is %d)", msg.get_srcSystem(), gcs_sysid
                )
            return
        if msg.chan8_raw != 0xFFFF:  # UINT16_MAX: leave the channel as it is
            self.autopilot.arming.rc_override(int(msg.chan8_raw))

    def _on_timesync(self, msg: Any, address: Address) -> None:
        if msg.tc1 == 0:
            now_ns = int(self.clock.time_s * 1e9)
            self.endpoint.send(self.endpoint.mav.timesync_encode(now_ns, msg.ts1), address)

    def _apply_settings(self, old: VehicleSettings, settings: VehicleSettings) -> None:
        """A PARAM_SET changed the settings: the vehicle, the clock and the traffic follow at once."""
        self.autopilot.apply_settings(settings)
        if settings.timing.speedup != old.timing.speedup:
            self.clock.set_speedup(settings.timing.speedup)
            log.info("speed-up now %g", settings.timing.speedup)
        if settings.adsb != old.adsb:
            self.traffic.apply_settings(settings.adsb)
            log.info("ADS-B traffic: %d aircraft within %g m", settings.adsb.count, settings.adsb.radius_m)
        if settings.link != old.link and any(
            getattr(settings.link, f"mav{n}") != getattr(old.link, f"mav{n}") for n in (1, 2, 3)
        ):
            log.info(
                "MAVn_* stream rates stored; as in ArduPilot they apply at the next start "
                "(use SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM now)"
            )
