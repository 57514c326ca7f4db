"""MAVLink I/O of ``sim-vehicle``: one UDP socket, streams, commands, missions, parameters.

Implements the MAVLink contract of DESIGN section 5 the way ArduPilot's SITL presents itself
(https://mavlink.io/en/services/): HEARTBEAT as an ArduCopter helicopter at 1 Hz of wall-clock
time and nothing else unasked; telemetry streams per link, only as requested with
SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM or the MAVn_* parameters (:mod:`sim_vehicle.streams`;
messages built by :mod:`sim_vehicle.telemetry`); every COMMAND_LONG / COMMAND_INT addressed to
the vehicle answered with a COMMAND_ACK; the mission protocol (MISSION_INT and the legacy float
items) for the mission, fence and rally lists with atomic replacement
(:mod:`sim_vehicle.mission_store`); the parameter protocol (:mod:`sim_vehicle.params`);
TIMESYNC, REQUEST_MESSAGE, DO_SET_HOME (HOME_POSITION and GPS_GLOBAL_ORIGIN follow the ACK to
every link, as ArduPilot sends them whenever home is set), the motor interlock
(DO_AUX_FUNCTION 32 and RC_CHANNELS_OVERRIDE of RC8 from MAV_GCS_SYSID, :mod:`sim_vehicle.rsc`)
and simulated ADS-B traffic (:mod:`sim_vehicle.adsb`). A STATUSTEXT from another component (a
companion) is forwarded to the other links, as ArduPilot's routing does.

Everything runs in one thread and one process: :meth:`MavlinkServer.run` paces the
simulation (:mod:`sim_vehicle.clock`), drains the socket, and sends what is due, sleeping in
``select`` in between. Each datagram is parsed on its own, so random bytes, truncated frames,
wrong CRCs and unknown message ids are counted (``stats``), logged (rate-limited) and dropped
without disturbing the flight. With a signing key (:mod:`sim_vehicle.signing`) everything sent
is signed, and a message that is not signed with the key, or replays an old timestamp, is
counted by reason and dropped before dispatch and routing. An optional ``.tlog`` records every
packet in and out in the standard format (8-byte big-endian microseconds since the Unix epoch,
then the raw packet), which MAVProxy and MAVExplorer open.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import select
import socket
import struct
import time
from typing import Any, Callable, Iterable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle import autopilot as ap
from sim_vehicle import rsc
from sim_vehicle.adsb import TrafficModel
from sim_vehicle.autopilot import Autopilot, QuietRefusal
from sim_vehicle.clock import SimClock, WallTimer
from sim_vehicle.config import VehicleSettings, parse_host_port, replace_path
from sim_vehicle.control import Setpoint
from sim_vehicle.mission_store import (
    FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT,
    FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT, FRAME_LOCAL_NED, MISSION_TYPE_MISSION,
    MISSION_TYPE_FENCE, MISSION_TYPE_NAMES, MISSION_TYPE_RALLY, MISSION_TYPES, MissionItem, MissionResult, MissionStore,
)
from sim_vehicle.params import ParameterTable
from sim_vehicle.signing import Verdict, VehicleSigning
from sim_vehicle.streams import MESSAGE_IDS, NAMES_BY_ID, StreamTable
from sim_vehicle.telemetry import CAPABILITIES, Telemetry

log = logging.getLogger(__name__)

COMPONENT_ID = 1
FORCE_DISARM_MAGIC = 21196
MAX_STREAM_WALL_HZ = 50.0
"""A stream is never sent faster than this in wall-clock time, whatever the speed-up."""
REQUEST_RETRY_S = 1.0
REQUESTABLE: dict[str, int] = {**MESSAGE_IDS, "AUTOPILOT_VERSION": mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION}
"""Messages MAV_CMD_REQUEST_MESSAGE answers (once, on the requesting link)."""
STATUSTEXT_CHUNK = 50
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT,
                           FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT})

Address = tuple[str, int]


@dataclasses.dataclass
class LinkStats:
    """Counters of the link (logged at shutdown; tests read them from the log)."""

    packets_in: int = 0
    messages_in: int = 0
    packets_out: int = 0
    bad_crc: int = 0
    unknown_id: int = 0
    bad_data: int = 0
    truncated: int = 0
    ignored: int = 0
    commands: int = 0
    # dropped by the signing check (sim_vehicle.signing.Verdict); not in ``dropped`` (SYS_STATUS errors_comm)
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0
    stale: int = 0

    @property
    def dropped(self) -> int:
        """Malformed input dropped so far."""
        return self.bad_crc + self.unknown_id + self.bad_data + self.truncated


@dataclasses.dataclass
class _UploadPeer:
    address: Address
    sysid: int
    compid: int
    legacy: bool
    last_request_wall_s: float = 0.0
    requested_seq: int = 0


#: Kernel receive buffer of the vehicle's socket (the kernel may cap it at net.core.rmem_max).
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024


class MavlinkServer:
    """The vehicle's MAVLink endpoint and main loop.

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

    def __init__(self, autopilot: Autopilot, settings: VehicleSettings, sysid: int, port: int,
                 tlog_path: str | None = None, wall_s: Callable[[], float] = time.monotonic,
                 traffic: TrafficModel | None = None, signing_key: bytes | None = None,
                 accept_signing_setup: bool = False) -> None:
        self.autopilot = autopilot
        self.settings = settings
        self.sysid = int(sysid)
        self.params = ParameterTable(settings)
        self.store = MissionStore(settings.link.mission_upload_timeout_s)
        self.clock = SimClock(settings.timing.physics_dt_s, settings.timing.speedup, settings.timing.max_lag_s, wall_s)
        self.heartbeat = WallTimer(1.0, wall_s)
        self.housekeeping = WallTimer(0.25, wall_s)
        self.wall_s = wall_s
        self.stats = LinkStats()
        self.mav = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
        self.signing = VehicleSigning(self.mav, signing_key, accept_signing_setup)
        self.outs: list[Address] = [self._resolve(a) for a in settings.link.out]
        self.peers: dict[Address, float] = {}
        if traffic is None:
            import numpy as np

            traffic = TrafficModel(settings.adsb, np.random.default_rng([settings.seed, 0xAD5B]))
        self.traffic = traffic
        link = settings.link
        self.streams = StreamTable(self.outs, [link.mav1.as_groups(), link.mav2.as_groups(), link.mav3.as_groups()])
        self.telemetry = Telemetry(self.mav, autopilot, self.clock, self.store, traffic, self.sysid,
                                   lambda: self.stats.dropped)
        self._origin_announced = False
        self._statustext_id = 0
        self._uploads: dict[int, _UploadPeer] = {}
        self._completed_upload: dict[int, tuple[int, float]] = {}
        self._bad_logged = collections.Counter()
        self._refused_requests: set[int] = set()
        self._after_ack: list[tuple[Any, Address | None]] = []
        self._tlog = open(tlog_path, "ab") if tlog_path else None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 0)
        # a flood (or a burst while the physics steps) must not overflow the kernel's buffer
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        self.sock.bind((settings.link.bind_host, int(port)))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self._stop = False

    # ================================================================== lifecycle
    @staticmethod
    def _resolve(text: str) -> Address:
        host, port = parse_host_port(text, "out")
        return socket.gethostbyname(host), port

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler)."""
        self._stop = True

    def close(self) -> None:
        """Close the socket and the tlog."""
        self.sock.close()
        if self._tlog is not None:
            self._tlog.close()
            self._tlog = None

    def run(self, duration_wall_s: float | None = None) -> None:
        """Main loop: simulate, receive, send; returns after :meth:`stop` (or the duration)."""
        start = self.wall_s()
        log.info("sim-vehicle sysid %d listening on UDP %s:%d, telemetry to %s and peers; speed-up %g",
                 self.sysid, self.settings.link.bind_host, self.port,
                 ", ".join(f"{h}:{p}" for h, p in self.outs) or "(no --out)", self.clock.speedup)
        log.info("MAVLink 2 signing: %s", f"on, key {self.signing.fingerprint}" if self.signing.enabled else
                 "off" + (", SETUP_SIGNING accepted" if self.signing.accept_setup else ""))
        while not self._stop:
            if duration_wall_s is not None and self.wall_s() - start >= duration_wall_s:
                break
            self.run_once()
            self._wait()
        log.info("link statistics: %s", dataclasses.asdict(self.stats))

    def run_once(self) -> None:
        """One pass: run due physics, read the socket, send what is due."""
        due = self.clock.steps_due()
        if due:
            chunk = min(due, 4 * int(self.settings.timing.physics_rate_hz))
            try:
                events = self.autopilot.run_steps(chunk)
            except Exception as exc:  # never stop flying: log, hold, carry on
                log.exception("simulation step failed")
                self.autopilot.recover(f"{type(exc).__name__}: {exc}")
                events = self.autopilot.run_steps(0)
            self.clock.advance(chunk)
            self.traffic.step(chunk * self.clock.physics_dt_s)
            self._handle_events(events)
        self._receive()
        if self.heartbeat.due():
            self.signing.tick()
            self._send_heartbeat()
            if not self._origin_announced:  # origin and home are set at start: ArduPilot announces both
                self._origin_announced = True
                self._send_home_and_origin()
        self._send_due_streams()
        if self.housekeeping.due():
            self._housekeeping()

    def _wait(self) -> None:
        batch = max(1, int(0.01 * self.clock.speedup / self.clock.physics_dt_s))  # <= 100 wake-ups per s
        timeout = min(self.clock.wall_until_step_s(batch), self.heartbeat.remaining_s(), 0.05)
        if timeout > 0:
            select.select([self.sock], [], [], timeout)

    # ================================================================== sending
    def _destinations(self) -> list[Address]:
        now = self.wall_s()
        timeout = self.settings.link.peer_timeout_s
        dests = list(self.outs)
        for address, heard in list(self.peers.items()):
            if now - heard > timeout:
                del self.peers[address]
            elif address not in dests:
                dests.append(address)
        return dests

    def _send(self, msg: Any, to: Address | Iterable[Address] | None = None) -> None:
        """Encode once and send to ``to`` (one address or several) or to every destination."""
        buf = msg.pack(self.mav)
        if to is None:
            targets = self._destinations()
        elif isinstance(to, tuple) and len(to) == 2 and isinstance(to[1], int):
            targets = [to]
        else:
            targets = list(to)
        for address in targets:
            try:
                self.sock.sendto(buf, address)
                self.stats.packets_out += 1
            except OSError as exc:  # unreachable peer, full buffer: never stop flying
                log.debug("send to %s failed: %s", address, exc)
        if self._tlog is not None:
            self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + buf)

    def _send_heartbeat(self) -> None:
        self._send(self.telemetry.msg_heartbeat())

    def _send_home_and_origin(self) -> None:
        """GPS_GLOBAL_ORIGIN then HOME_POSITION to every link (ArduPilot does so whenever home is set)."""
        self._send(self.telemetry.msg_gps_global_origin())
        self._send(self.telemetry.msg_home_position())

    def _send_due_streams(self) -> None:
        """Each link's due messages, to that link only (streams are per link, as in ArduPilot)."""
        now = self.clock.time_s
        min_period = self.clock.speedup / MAX_STREAM_WALL_HZ
        for address in self._destinations():
            link = self.streams.link(address, now)
            for name in link.due(now, min_period):
                try:
                    msg = self.telemetry.build(name, link)
                except Exception as exc:  # e.g. a value out of the field's range: skip it, keep flying
                    key = f"stream:{name}"
                    n = self._bad_logged[key] = self._bad_logged[key] + 1
                    if n <= 3 or n % 1000 == 0:
                        log.error("cannot send %s: %s: %s", name, type(exc).__name__, exc)
                    continue
                if msg is not None:
                    self._send(msg, address)

    def _statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every link; longer texts in 50-character chunks with an id, as ArduPilot sends them."""
        data = text.encode(errors="replace")
        if len(data) <= STATUSTEXT_CHUNK:
            self._send(self.mav.statustext_encode(severity, data))
            return
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        chunks = [data[i:i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
        for seq, chunk in enumerate(chunks[:255]):
            self._send(self.mav.statustext_encode(severity, chunk, self._statustext_id, seq))

    # ================================================================== receiving
    def _receive(self) -> None:
        for _ in range(256):  # bounded, so a flood cannot starve the simulation
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # e.g. ICMP port unreachable reported on some systems
                log.debug("receive error: %s", exc)
                return
            self.stats.packets_in += 1
            self._handle_datagram(data, address)

    def _handle_datagram(self, data: bytes, address: Address) -> None:
        parser = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
        parser.robust_parsing = True
        try:
            messages = parser.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises a few odd errors on garbage: drop, never crash
            self._count_bad("bad_data", f"{type(exc).__name__}: {exc}", address)
            return
        for msg in messages:
            if msg.get_type() == "BAD_DATA":
                reason = str(getattr(msg, "reason", ""))
                if "CRC" in reason.upper():
                    self._count_bad("bad_crc", reason, address)
                elif "unknown" in reason.lower() and "id" in reason.lower():
                    self._count_bad("unknown_id", reason, address)
                else:
                    self._count_bad("bad_data", reason, address)
                continue
            if isinstance(msg, mavlink.MAVLink_unknown):
                self._count_bad("unknown_id", f"unknown message id {msg.get_msgId()}", address)
                continue
            verdict = self.signing.verdict(msg)
            if verdict is not Verdict.ACCEPTED:  # before dispatch and routing, before it makes a peer
                self._count_bad(verdict.value, msg.get_type(), address, what="unauthenticated message")
                continue
            self.stats.messages_in += 1
            self.peers[address] = self.wall_s()  # before dispatch: a reply broadcast (STATUSTEXT) reaches it too
            if self._tlog is not None:
                self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + bytes(msg.get_msgbuf()))
            try:
                self._dispatch(msg, address)
                self._route(msg, address)
            except Exception:  # a handler bug must not stop the vehicle: log it loudly
                log.exception("error handling %s from %s", msg.get_type(), address)
        if parser.buf_len() > 0:
            self._count_bad("truncated", f"{parser.buf_len()} bytes left over", address)

    def _count_bad(self, kind: str, reason: str, address: Address, what: str = "malformed packet") -> None:
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        n = self._bad_logged[kind] = self._bad_logged[kind] + 1
        if n <= 10 or n % 100 == 0:
            log.warning("dropped %s from %s:%d (%s: %s; %d so far)", what, address[0], address[1], kind, reason, n)

    def _route(self, msg: Any, address: Address) -> None:
        """Forward a broadcast message of another component to every other destination.

        ArduPilot's MAVLink routing (``GCS_MAVLink/MAVLink_routing.cpp``) forwards a message
        without a target to all its links but the one it came in on, so a companion's
        STATUSTEXT shows on every ground station. Only the types in ``ROUTED`` are forwarded
        here (unchanged, with the sender's ids), never back to the sender, never our own.
        """
        if msg.get_type() not in self.ROUTED or (msg.get_srcSystem(), msg.get_srcComponent()) == \
                (self.sysid, COMPONENT_ID):
            return
        buf = bytes(msg.get_msgbuf())
        for dest in self._destinations():
            if dest == address:
                continue
            try:
                self.sock.sendto(buf, dest)
                self.stats.packets_out += 1
            except OSError as exc:  # unreachable peer, full buffer: never stop flying
                log.debug("forward to %s failed: %s", dest, exc)
        if self._tlog is not None:
            self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + buf)

    def _for_us(self, msg: Any) -> bool:
        target = getattr(msg, "target_system", 0)
        comp = getattr(msg, "target_component", 0)
        return target in (0, self.sysid) and comp in (0, COMPONENT_ID, mavlink.MAV_COMP_ID_ALL)

    def _dispatch(self, msg: Any, address: Address) -> None:
        kind = msg.get_type()
        handler = self._HANDLERS.get(kind)
        if handler is None:
            self.stats.ignored += 1
            return
        if not self._for_us(msg):
            self.stats.ignored += 1
            return
        handler(self, msg, address)

    # ================================================================== commands
    def _ack(self, msg: Any, address: Address, command: int, result: int) -> None:
        self._send(self.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()),
                   address)

    def _on_command_long(self, msg: Any, address: Address) -> None:
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        self._command(msg, address, msg.command, params, None)

    def _on_command_int(self, msg: Any, address: Address) -> None:
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z]
        self._command(msg, address, msg.command, params, msg.frame)

    def _command(self, msg: Any, address: Address, command: int, params: list[float], frame: int | None) -> None:
        self.stats.commands += 1
        self._after_ack = []
        handler = self._COMMANDS.get(command)
        if handler is None:
            name = mavlink.enums["MAV_CMD"].get(command)
            log.info("command %s (%d) from %s:%d: UNSUPPORTED", name.name if name else "?", command, *address)
            self._ack(msg, address, command, mavlink.MAV_RESULT_UNSUPPORTED)
            return
        try:
            result, reason = handler(self, params, frame, msg, address)
        except Exception:
            log.exception("command %d failed", command)
            result, reason = mavlink.MAV_RESULT_FAILED, "internal error"
        if result != mavlink.MAV_RESULT_ACCEPTED:
            name = mavlink.enums["MAV_CMD"].get(command)
            log.warning("command %s refused (%s): %s", name.name if name else command,
                        mavlink.enums["MAV_RESULT"][result].name, reason)
        self._ack(msg, address, command, result)
        replies, self._after_ack = self._after_ack, []
        for reply, to in replies:  # requested messages follow the ACK, as in ArduPilot
            self._send(reply, to)
        if (result != mavlink.MAV_RESULT_ACCEPTED and reason and result == mavlink.MAV_RESULT_FAILED
                and not isinstance(reason, QuietRefusal)):
            self._statustext(mavlink.MAV_SEVERITY_CRITICAL if reason.startswith(("Arm:", "PreArm:"))
                             else mavlink.MAV_SEVERITY_WARNING, reason)

    @staticmethod
    def _outcome(ok_reason: tuple[bool, str]) -> tuple[int, str]:
        ok, reason = ok_reason
        return (mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED), reason

    def _cmd_arm(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        if p[0] == 1.0:
            return self._outcome(self.autopilot.arm())
        if p[0] == 0.0:
            return self._outcome(self.autopilot.disarm(force=p[1] == FORCE_DISARM_MAGIC))
        return mavlink.MAV_RESULT_DENIED, f"param1 must be 1 (arm) or 0 (disarm), got {p[0]!r}"

    def _cmd_takeoff(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        alt = p[6]
        if frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
            alt = alt - self.autopilot.home_lla[2]
        if not math.isfinite(alt) or not 0.5 <= alt <= ap.MAX_TAKEOFF_ALT_M:
            return mavlink.MAV_RESULT_DENIED, f"takeoff altitude (param7) {p[6]!r} outside 0.5..{ap.MAX_TAKEOFF_ALT_M:g} m"
        return self._outcome(self.autopilot.takeoff(alt))

    def _cmd_land(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        return self._outcome(self.autopilot.land())

    def _cmd_rtl(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        return self._outcome(self.autopilot.rtl())

    def _cmd_do_set_mode(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        base, custom = p[0], p[1]
        if not (math.isfinite(base) and math.isfinite(custom)):
            return mavlink.MAV_RESULT_DENIED, f"mode parameters must be finite, got {base!r}, {custom!r}"
        if not int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mavlink.MAV_RESULT_DENIED, "param1 must have MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"
        if custom != int(custom) or int(custom) not in ap.MODE_NAMES:
            return mavlink.MAV_RESULT_DENIED, f"unknown ArduCopter mode {custom!r}"
        return self._outcome(self.autopilot.set_mode(int(custom)))

    def _cmd_mission_start(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        first = 0.0 if math.isnan(p[0]) else p[0]
        count = len(self.autopilot.mission_items)
        if not math.isfinite(first) or first != int(first) or first < 0 or (count and first >= count):
            return mavlink.MAV_RESULT_DENIED, f"first item (param1) {p[0]!r} is not an item of the mission (0..{count - 1})"
        return self._outcome(self.autopilot.mission_start(int(first)))

    def _cmd_set_mission_current(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        seq = p[0]
        if not math.isfinite(seq) or seq != int(seq) or not 0 <= seq < len(self.autopilot.mission_items):
            return mavlink.MAV_RESULT_DENIED, f"mission item {seq!r} does not exist"
        result = self._outcome(self.autopilot.set_current(int(seq)))
        self._send(self.telemetry.msg_mission_current())
        return result

    def _cmd_change_speed(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        speed = p[1]
        if speed == -1.0:
            return self._outcome(self.autopilot.change_speed(None))
        ok, reason = self.autopilot.change_speed(speed)
        return (mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_DENIED), reason

    def _cmd_condition_yaw(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        angle_deg, direction, relative = p[0], p[2], p[3]
        if not all(math.isfinite(v) for v in (angle_deg, direction, relative)) or not 0.0 <= angle_deg <= 360.0:
            return mavlink.MAV_RESULT_DENIED, f"angle (param1) {angle_deg!r} outside 0..360 degrees"
        yaw = math.radians(angle_deg)
        if relative:
            yaw = float(self.autopilot.euler_rad[2]) + (-yaw if direction < 0 else yaw)
        return self._outcome(self.autopilot.set_yaw(yaw))

    def _cmd_reposition(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        """MAV_CMD_DO_REPOSITION (MAVSDK goto_location): a GUIDED position target."""
        if frame is None:  # COMMAND_LONG: degrees, altitude AMSL
            lat, lon, frame = p[4], p[5], FRAME_GLOBAL
        else:
            lat, lon = p[4] * 1e-7, p[5] * 1e-7
        alt = p[6]
        if not all(math.isfinite(v) for v in (lat, lon, alt)) or abs(lat) > 90.0 or abs(lon) > 180.0:
            return mavlink.MAV_RESULT_DENIED, f"position {p[4]!r}, {p[5]!r}, {p[6]!r} invalid"
        if frame not in GLOBAL_FRAMES:
            return mavlink.MAV_RESULT_DENIED, f"frame {frame} not supported (use a global frame)"
        a = self.autopilot
        if a.mode != ap.GUIDED:
            change_mode = math.isfinite(p[1]) and bool(int(p[1]) & mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)
            if not change_mode:
                return mavlink.MAV_RESULT_FAILED, "DO_REPOSITION needs GUIDED (or the change-mode flag)"
            ok, reason = a.set_mode(ap.GUIDED)
            if not ok:
                return mavlink.MAV_RESULT_FAILED, reason
        alt_amsl = alt if frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else a.home_lla[2] + alt
        yaw = None if not math.isfinite(p[3]) else math.radians(p[3])
        target = a.frame.to_ned(lat, lon, alt_amsl)
        return self._outcome(a.set_guided_setpoint(Setpoint(pos_ned_m=target, yaw_rad=yaw)))

    def _cmd_set_message_interval(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        """SET_MESSAGE_INTERVAL for the requesting link (:meth:`StreamTable.set_message_interval`)."""
        result, text = self.streams.set_message_interval(address, p[0], p[1], self.clock.time_s)
        if text:
            self._statustext(mavlink.MAV_SEVERITY_INFO, text)  # ArduPilot's own words, sent by it too
        if result != mavlink.MAV_RESULT_ACCEPTED:
            return result, QuietRefusal(text or f"message {p[0]!r} interval {p[1]!r} us refused")
        return result, ""

    def _cmd_get_message_interval(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        if not math.isfinite(p[0]):
            return mavlink.MAV_RESULT_DENIED, "message id must be finite"
        name = NAMES_BY_ID.get(int(p[0]))
        interval = 0 if name is None else self.streams.link(address, self.clock.time_s).interval_us(name)
        # ArduPilot sends MESSAGE_INTERVAL before the COMMAND_ACK
        self._send(self.mav.message_interval_encode(int(p[0]), interval), address)
        return mavlink.MAV_RESULT_ACCEPTED, ""

    def _cmd_request_message(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        """REQUEST_MESSAGE: the message once, after the ACK, on the requesting link; unknown: FAILED."""
        if not math.isfinite(p[0]):
            return mavlink.MAV_RESULT_DENIED, "message id (param1) must be finite"
        name = next((n for n, i in REQUESTABLE.items() if i == int(p[0])), None)
        if name is None:
            if int(p[0]) not in self._refused_requests:
                self._refused_requests.add(int(p[0]))
                log.info("REQUEST_MESSAGE %d: not available", int(p[0]))
            return mavlink.MAV_RESULT_FAILED, QuietRefusal(f"message {int(p[0])} not available")
        reply = self.telemetry.build(name, self.streams.link(address, self.clock.time_s))
        if reply is not None:
            self._after_ack.append((reply, address))
        return mavlink.MAV_RESULT_ACCEPTED, ""

    def _cmd_autopilot_capabilities(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        self._after_ack.append((self.telemetry.msg_autopilot_version(), address))
        return mavlink.MAV_RESULT_ACCEPTED, ""

    def _cmd_get_home(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        self._after_ack.append((self.telemetry.msg_home_position(), address))
        return mavlink.MAV_RESULT_ACCEPTED, ""

    def _cmd_set_home(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        """MAV_CMD_DO_SET_HOME: param1 1 (or lat = lon = 0) = here, else params 5-7.

        COMMAND_LONG: degrees and metres AMSL. COMMAND_INT: degE7, altitude in ``frame``
        (GLOBAL: AMSL, GLOBAL_RELATIVE_ALT: above the current home). Then GPS_GLOBAL_ORIGIN and
        HOME_POSITION go to every link, as ArduPilot sends them.
        """
        a = self.autopilot
        if not all(math.isfinite(v) for v in (p[0], p[4], p[5], p[6])):
            return mavlink.MAV_RESULT_DENIED, "DO_SET_HOME parameters must be finite"
        if frame is None:
            lat, lon, alt = p[4], p[5], p[6]
        else:
            lat, lon, alt = p[4] * 1e-7, p[5] * 1e-7, p[6]
            if frame in (FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT):
                alt = a.frames.home_alt_m + alt
            elif frame not in (FRAME_GLOBAL, FRAME_GLOBAL_INT):
                return mavlink.MAV_RESULT_DENIED, f"DO_SET_HOME: frame {frame} not supported (use a global frame)"
        if p[0] == 1.0 or (p[4] == 0 and p[5] == 0):
            lat, lon, alt = a.position_lla()
        result = self._outcome(a.set_home(lat, lon, alt))
        if result[0] == mavlink.MAV_RESULT_ACCEPTED:
            self._after_ack.append((self.telemetry.msg_gps_global_origin(), None))
            self._after_ack.append((self.telemetry.msg_home_position(), None))
        return result

    def _cmd_aux_function(self, p: list[float], frame: Any, msg: Any, address: Address) -> tuple[int, str]:
        """MAV_CMD_DO_AUX_FUNCTION: only 32 (MOTOR_INTERLOCK) is simulated; position 0/1/2."""
        function, position = p[0], p[1]
        if not (math.isfinite(function) and math.isfinite(position)) or position not in (0.0, 1.0, 2.0):
            return mavlink.MAV_RESULT_DENIED, f"switch position (param2) {position!r}: expected 0, 1 or 2"
        if function != rsc.AUX_FUNCTION_MOTOR_INTERLOCK:
            return mavlink.MAV_RESULT_FAILED, QuietRefusal(f"aux function {function:g} not simulated")
        return self._outcome(self.autopilot.set_interlock_switch(int(position)))

    _COMMANDS: dict[int, Callable] = {
        mavlink.MAV_CMD_COMPONENT_ARM_DISARM: _cmd_arm,
        mavlink.MAV_CMD_NAV_TAKEOFF: _cmd_takeoff,
        mavlink.MAV_CMD_NAV_LAND: _cmd_land,
        mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: _cmd_rtl,
        mavlink.MAV_CMD_DO_SET_MODE: _cmd_do_set_mode,
        mavlink.MAV_CMD_MISSION_START: _cmd_mission_start,
        mavlink.MAV_CMD_DO_SET_MISSION_CURRENT: _cmd_set_mission_current,
        mavlink.MAV_CMD_DO_CHANGE_SPEED: _cmd_change_speed,
        mavlink.MAV_CMD_DO_REPOSITION: _cmd_reposition,
        mavlink.MAV_CMD_CONDITION_YAW: _cmd_condition_yaw,
        mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: _cmd_set_message_interval,
        mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: _cmd_get_message_interval,
        mavlink.MAV_CMD_REQUEST_MESSAGE: _cmd_request_message,
        mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _cmd_autopilot_capabilities,
        mavlink.MAV_CMD_GET_HOME_POSITION: _cmd_get_home,
        mavlink.MAV_CMD_DO_SET_HOME: _cmd_set_home,
        mavlink.MAV_CMD_DO_AUX_FUNCTION: _cmd_aux_function,
    }

    def _on_set_mode(self, msg: Any, address: Address) -> None:
        if msg.target_system != self.sysid:
            return
        if not msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED or msg.custom_mode not in ap.MODE_NAMES:
            log.warning("SET_MODE refused: base_mode %d custom_mode %d", msg.base_mode, msg.custom_mode)
            result = mavlink.MAV_RESULT_DENIED
        else:
            ok, reason = self.autopilot.set_mode(msg.custom_mode)
            if not ok:
                log.warning("SET_MODE %s refused: %s", ap.mode_name(msg.custom_mode), reason)
            result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED
        self._ack(msg, address, mavlink.MAVLINK_MSG_ID_SET_MODE, result)

    def _on_request_data_stream(self, msg: Any, address: Address) -> None:
        """REQUEST_DATA_STREAM for the requesting link; a numbered link's MAVn_ parameter follows."""
        changed = self.streams.request_data_stream(address, msg.req_stream_id, msg.req_message_rate, msg.start_stop,
                                                   self.clock.time_s)
        n = self.streams.number(address)
        if n is None or n > 3 or not changed:
            return
        settings = self.settings
        for group, hz in changed:
            settings = replace_path(settings, f"link.mav{n}.{group.lower()}", min(int(hz), 1000))
        self.settings = self.params.settings = settings

    def _on_rc_channels_override(self, msg: Any, address: Address) -> None:
        """RC8 override (motor interlock switch); only from MAV_GCS_SYSID, as ArduPilot accepts it."""
        if msg.get_srcSystem() != self.settings.link.gcs_sysid:
            key = f"rc_override:{msg.get_srcSystem()}"
            n = self._bad_logged[key] = self._bad_logged[key] + 1
            if n <= 3:
                log.info("RC_CHANNELS_OVERRIDE from system %d ignored (MAV_GCS_SYSID is %d)", msg.get_srcSystem(),
                         self.settings.link.gcs_sysid)
            return
        if msg.chan8_raw != 0xFFFF:  # UINT16_MAX: leave the channel as it is
            self.autopilot.rc_override(int(msg.chan8_raw))

    def _on_timesync(self, msg: Any, address: Address) -> None:
        if msg.tc1 == 0:
            now_ns = int(self.clock.time_s * 1e9)
            self._send(self.mav.timesync_encode(now_ns, msg.ts1), address)

    # ================================================================== GUIDED setpoints
    def _on_set_position_target_local_ned(self, msg: Any, address: Address) -> None:
        frame = msg.coordinate_frame
        if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
                         mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED):
            log.warning("SET_POSITION_TARGET_LOCAL_NED: frame %d not supported; ignored", frame)
            return
        pos = (msg.x, msg.y, msg.z)
        vel = (msg.vx, msg.vy, msg.vz)
        acc = (msg.afx, msg.afy, msg.afz)
        a = self.autopilot
        yaw = float(a.euler_rad[2])
        c, s = math.cos(yaw), math.sin(yaw)

        def rotate(v: tuple) -> tuple:
            return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])

        here = a.pos_ned_m
        if frame in (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED):
            vel, acc = rotate(vel), rotate(acc)  # velocities and accelerations in body axes
        if frame == mavlink.MAV_FRAME_BODY_OFFSET_NED:
            off = rotate(pos)
            pos = (off[0] + here[0], off[1] + here[1], off[2] + here[2])
        elif frame == mavlink.MAV_FRAME_LOCAL_OFFSET_NED:
            pos = (pos[0] + here[0], pos[1] + here[1], pos[2] + here[2])
        elif frame == mavlink.MAV_FRAME_LOCAL_NED:  # metres from the EKF origin, as in ArduPilot
            pos = tuple(a.frames.from_local(pos))
        self._guided_target(msg, pos, vel, acc)

    def _on_set_position_target_global_int(self, msg: Any, address: Address) -> None:
        frame = msg.coordinate_frame
        if frame not in GLOBAL_FRAMES:
            log.warning("SET_POSITION_TARGET_GLOBAL_INT: frame %d not supported; ignored", frame)
            return
        mask = msg.type_mask
        pos: tuple = (math.nan, math.nan, math.nan)
        if not mask & 0b111:
            lat, lon = msg.lat_int * 1e-7, msg.lon_int * 1e-7
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or not math.isfinite(msg.alt):
                log.warning("SET_POSITION_TARGET_GLOBAL_INT: position %r, %r, %r invalid; ignored",
                            msg.lat_int, msg.lon_int, msg.alt)
                return
            home_alt = self.autopilot.home_lla[2]
            alt_amsl = msg.alt if frame in (FRAME_GLOBAL, FRAME_GLOBAL_INT) else home_alt + msg.alt
            pos = self.autopilot.frame.to_ned(lat, lon, alt_amsl)
        self._guided_target(msg, pos, (msg.vx, msg.vy, msg.vz), (msg.afx, msg.afy, msg.afz), position_known=True)

    def _guided_target(self, msg: Any, pos: tuple, vel: tuple, acc: tuple, position_known: bool = False) -> None:
        mask = msg.type_mask
        ignore_pos = bool(mask & 0b000000000111)
        ignore_vel = bool(mask & 0b000000111000)
        ignore_acc = bool(mask & 0b000111000000)
        ignore_yaw = bool(mask & 0b010000000000)
        ignore_yaw_rate = bool(mask & 0b100000000000)
        force = bool(mask & 0b001000000000)
        setpoint = Setpoint(
            pos_ned_m=None if ignore_pos else pos,
            vel_ned_m_s=None if ignore_vel else vel,
            acc_ned_m_s2=None if (ignore_acc or force) else acc,
            yaw_rad=None if ignore_yaw else float(msg.yaw),
            yaw_rate_rad_s=None if ignore_yaw_rate else float(msg.yaw_rate),
        )
        if setpoint.pos_ned_m is None and setpoint.vel_ned_m_s is None and setpoint.acc_ned_m_s2 is None \
                and setpoint.yaw_rad is None and setpoint.yaw_rate_rad_s is None:
            log.warning("%s: type_mask %#x ignores everything; ignored", msg.get_type(), mask)
            return
        ok, reason = self.autopilot.set_guided_setpoint(setpoint)
        if not ok:
            key = f"guided:{reason}"
            n = self._bad_logged[key] = self._bad_logged[key] + 1
            if n <= 3 or n % 100 == 0:
                log.warning("%s refused: %s", msg.get_type(), reason)

    # ================================================================== missions
    def _mission_type(self, msg: Any) -> int:
        return int(getattr(msg, "mission_type", MISSION_TYPE_MISSION))

    def _mission_ack(self, msg: Any, address: Address, result: int, mission_type: int) -> None:
        self._send(self.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), int(result), mission_type),
                   address)

    def _request_item(self, mission_type: int, seq: int) -> None:
        peer = self._uploads[mission_type]
        if peer.legacy:
            out = self.mav.mission_request_encode(peer.sysid, peer.compid, seq, mission_type)
        else:
            out = self.mav.mission_request_int_encode(peer.sysid, peer.compid, seq, mission_type)
        peer.requested_seq = seq
        peer.last_request_wall_s = self.wall_s()
        self._send(out, peer.address)

    def _on_mission_count(self, msg: Any, address: Address) -> None:
        mission_type = self._mission_type(msg)
        result = self.store.begin_upload(mission_type, int(msg.count), self.wall_s())
        if result != MissionResult.ACCEPTED:
            log.warning("MISSION_COUNT %d (type %d) refused: %s", msg.count, mission_type, result.name)
            self._mission_ack(msg, address, result, mission_type)
            return
        log.info("%s upload of %d items from %s:%d", MISSION_TYPE_NAMES[mission_type], msg.count, *address)
        if msg.count == 0:
            self._apply_list(mission_type)
            self._mission_ack(msg, address, MissionResult.ACCEPTED, mission_type)
            return
        self._uploads[mission_type] = _UploadPeer(address, msg.get_srcSystem(), msg.get_srcComponent(),
                                                  legacy=False)
        self._request_item(mission_type, 0)

    def _on_mission_item_int(self, msg: Any, address: Address) -> None:
        item = MissionItem(seq=msg.seq, frame=msg.frame, command=msg.command, current=msg.current,
                           autocontinue=msg.autocontinue, param1=msg.param1, param2=msg.param2, param3=msg.param3,
                           param4=msg.param4, x=int(msg.x), y=int(msg.y), z=float(msg.z),
                           mission_type=self._mission_type(msg))
        self._receive_item(msg, address, item)

    def _on_mission_item(self, msg: Any, address: Address) -> None:
        frame = msg.frame
        if frame in GLOBAL_FRAMES:
            if not (math.isfinite(msg.x) and math.isfinite(msg.y)) or abs(msg.x) > 90.0 or abs(msg.y) > 180.0:
                x, y = 2_000_000_000, 2_000_000_000  # refused by the store as INVALID_PARAM5_X
            else:
                x, y = int(round(msg.x * 1e7)), int(round(msg.y * 1e7))
        elif frame == FRAME_LOCAL_NED and math.isfinite(msg.x) and math.isfinite(msg.y):
            x, y = int(round(msg.x * 1e4)), int(round(msg.y * 1e4))
        else:
            x, y = (int(msg.x), int(msg.y)) if math.isfinite(msg.x) and math.isfinite(msg.y) else (0, 0)
        item = MissionItem(seq=msg.seq, frame=frame, command=msg.command, current=msg.current,
                           autocontinue=msg.autocontinue, param1=msg.param1, param2=msg.param2, param3=msg.param3,
                           param4=msg.param4, x=x, y=y, z=float(msg.z), mission_type=self._mission_type(msg))
        peer = self._uploads.get(item.mission_type)
        if peer is not None and peer.address == address:
            peer.legacy = True  # answer a legacy sender with legacy requests
        self._receive_item(msg, address, item)

    def _receive_item(self, msg: Any, address: Address, item: MissionItem) -> None:
        mission_type = item.mission_type
        peer = self._uploads.get(mission_type)
        if peer is None:
            done = self._completed_upload.get(mission_type)
            if done is not None and item.seq == done[0] - 1 and self.wall_s() - done[1] < 5.0:
                self._mission_ack(msg, address, MissionResult.ACCEPTED, mission_type)  # our ACK was lost
                return
            log.warning("mission item %d (type %d) from %s:%d outside any upload: refused", item.seq, mission_type,
                        *address)
            self._mission_ack(msg, address, MissionResult.DENIED, mission_type)
            return
        result, complete = self.store.receive_item(item, self.wall_s())
        if result == MissionResult.INVALID_SEQUENCE:
            self._mission_ack(msg, address, result, mission_type)
            self._request_item(mission_type, self.store.upload_in_progress(mission_type).next_seq)
            return
        if result != MissionResult.ACCEPTED:
            self._uploads.pop(mission_type, None)
            self._mission_ack(msg, address, result, mission_type)
            return
        if complete:
            self._uploads.pop(mission_type, None)
            self._completed_upload[mission_type] = (len(self.store.items(mission_type)), self.wall_s())
            self._apply_list(mission_type)
            self._mission_ack(msg, address, MissionResult.ACCEPTED, mission_type)
            return
        upload = self.store.upload_in_progress(mission_type)
        if upload is not None and upload.next_seq != peer.requested_seq:
            self._request_item(mission_type, upload.next_seq)

    def _apply_list(self, mission_type: int) -> None:
        if mission_type == MISSION_TYPE_MISSION:
            self.autopilot.set_mission(self.store.items(MISSION_TYPE_MISSION))
            self._send(self.telemetry.msg_mission_current())
        elif mission_type == MISSION_TYPE_RALLY:
            self.autopilot.set_rally(self.store.items(MISSION_TYPE_RALLY))
        else:
            self.autopilot.set_fence(self.store.items(MISSION_TYPE_FENCE))

    def _on_mission_request_list(self, msg: Any, address: Address) -> None:
        mission_type = self._mission_type(msg)
        if mission_type not in MISSION_TYPES:
            self._mission_ack(msg, address, MissionResult.UNSUPPORTED, mission_type)
            return
        self._send(self.mav.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                                 len(self.store.items(mission_type)), mission_type), address)

    def _download_item(self, msg: Any, address: Address, legacy: bool) -> None:
        mission_type = self._mission_type(msg)
        items = self.store.items(mission_type)
        if not 0 <= msg.seq < len(items):
            log.warning("MISSION_REQUEST for item %d of %d (type %d): refused", msg.seq, len(items), mission_type)
            self._mission_ack(msg, address, MissionResult.INVALID_SEQUENCE, mission_type)
            return
        it = items[msg.seq]
        current = it.current  # a download returns exactly what was uploaded
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if legacy:
            if it.frame in GLOBAL_FRAMES:
                x, y = it.x * 1e-7, it.y * 1e-7
            elif it.frame == FRAME_LOCAL_NED:
                x, y = it.x * 1e-4, it.y * 1e-4
            else:
                x, y = float(it.x), float(it.y)
            out = self.mav.mission_item_encode(sysid, compid, it.seq, it.frame, it.command, current, it.autocontinue,
                                               it.param1, it.param2, it.param3, it.param4, x, y, it.z, mission_type)
        else:
            out = self.mav.mission_item_int_encode(sysid, compid, it.seq, it.frame, it.command, current,
                                                   it.autocontinue, it.param1, it.param2, it.param3, it.param4,
                                                   it.x, it.y, it.z, mission_type)
        self._send(out, address)

    def _on_mission_request_int(self, msg: Any, address: Address) -> None:
        self._download_item(msg, address, legacy=False)

    def _on_mission_request(self, msg: Any, address: Address) -> None:
        self._download_item(msg, address, legacy=True)

    def _on_mission_clear_all(self, msg: Any, address: Address) -> None:
        mission_type = self._mission_type(msg)
        result = self.store.clear(mission_type)
        for t in (MISSION_TYPES if mission_type == 255 else (mission_type,)):
            self._uploads.pop(t, None)
            if result == MissionResult.ACCEPTED:
                self._apply_list(t)
        self._mission_ack(msg, address, result, mission_type)

    def _on_mission_set_current(self, msg: Any, address: Address) -> None:
        ok, reason = self.autopilot.set_current(int(msg.seq))
        if not ok:
            log.warning("MISSION_SET_CURRENT %d refused: %s", msg.seq, reason)
            self._statustext(mavlink.MAV_SEVERITY_WARNING, f"set current refused: {reason}")
        self._send(self.telemetry.msg_mission_current())

    def _on_mission_ack(self, msg: Any, address: Address) -> None:
        mission_type = self._mission_type(msg)
        peer = self._uploads.get(mission_type)
        if peer is not None and peer.address == address and msg.type != MissionResult.ACCEPTED:
            self.store.cancel_upload(mission_type, f"sender sent MISSION_ACK {msg.type}")
            self._uploads.pop(mission_type, None)

    # ================================================================== signing
    def _on_setup_signing(self, msg: Any, address: Address) -> None:
        """SETUP_SIGNING: change or switch off the key by the rules of :mod:`sim_vehicle.signing`; log either way."""
        done, what = self.signing.setup(msg)
        if done:
            log.info("SETUP_SIGNING from %s:%d (system %d): %s", *address, msg.get_srcSystem(), what)
            return
        n = self._bad_logged["setup_signing"] = self._bad_logged["setup_signing"] + 1
        if n <= 10 or n % 100 == 0:
            log.warning("SETUP_SIGNING from %s:%d (system %d) refused: %s; %d so far", *address,
                        msg.get_srcSystem(), what, n)

    # ================================================================== parameters
    def _param_value(self, index: int, address: Address | None = None) -> None:
        spec = self.params.specs[index]
        self._send(self.mav.param_value_encode(spec.name.encode(), self.params.value(spec), spec.param_type,
                                               len(self.params), index), address)

    def _on_param_request_list(self, msg: Any, address: Address) -> None:
        for index in range(len(self.params)):
            self._param_value(index, address)

    def _on_param_request_read(self, msg: Any, address: Address) -> None:
        name = _param_name(msg.param_id)
        index = msg.param_index if msg.param_index >= 0 else self.params.index(name)
        if not 0 <= index < len(self.params):
            log.info("PARAM_REQUEST_READ %r (index %d): no such parameter", name, msg.param_index)
            return
        self._param_value(index, address)

    def _on_param_set(self, msg: Any, address: Address) -> None:
        name = _param_name(msg.param_id)
        index = self.params.index(name)
        if index < 0:
            log.warning("PARAM_SET %r: no such parameter; ignored", name)
            return
        ok, reason = self.params.set(name, float(msg.param_value))
        if ok:
            self._apply_settings(self.params.settings)
        else:
            self._statustext(mavlink.MAV_SEVERITY_WARNING, f"{name} refused")
        self._param_value(index)  # everyone sees the (new or unchanged) value

    def _apply_settings(self, settings: VehicleSettings) -> None:
        old = self.settings
        self.settings = settings
        self.autopilot.apply_settings(settings)
        if settings.timing.speedup != old.timing.speedup:
            self.clock.set_speedup(settings.timing.speedup)
            log.info("speed-up now %g", settings.timing.speedup)
        if settings.adsb != old.adsb:
            self.traffic.apply_settings(settings.adsb)
            log.info("ADS-B traffic: %d aircraft within %g m", settings.adsb.count, settings.adsb.radius_m)
        if settings.link != old.link and any(getattr(settings.link, f"mav{n}") != getattr(old.link, f"mav{n}")
                                             for n in (1, 2, 3)):
            log.info("MAVn_* stream rates stored; as in ArduPilot they apply at the next start "
                     "(use SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM now)")

    #: Broadcast messages forwarded between links (``_route``), as ArduPilot does.
    ROUTED = frozenset({"STATUSTEXT"})

    _HANDLERS: dict[str, Callable] = {
        "COMMAND_LONG": _on_command_long,
        "COMMAND_INT": _on_command_int,
        "SET_MODE": _on_set_mode,
        "REQUEST_DATA_STREAM": _on_request_data_stream,
        "RC_CHANNELS_OVERRIDE": _on_rc_channels_override,
        "TIMESYNC": _on_timesync,
        "SET_POSITION_TARGET_LOCAL_NED": _on_set_position_target_local_ned,
        "SET_POSITION_TARGET_GLOBAL_INT": _on_set_position_target_global_int,
        "MISSION_COUNT": _on_mission_count,
        "MISSION_ITEM_INT": _on_mission_item_int,
        "MISSION_ITEM": _on_mission_item,
        "MISSION_REQUEST_LIST": _on_mission_request_list,
        "MISSION_REQUEST_INT": _on_mission_request_int,
        "MISSION_REQUEST": _on_mission_request,
        "MISSION_CLEAR_ALL": _on_mission_clear_all,
        "MISSION_SET_CURRENT": _on_mission_set_current,
        "MISSION_ACK": _on_mission_ack,
        "PARAM_REQUEST_LIST": _on_param_request_list,
        "PARAM_REQUEST_READ": _on_param_request_read,
        "PARAM_SET": _on_param_set,
        "SETUP_SIGNING": _on_setup_signing,
    }

    # ================================================================== events and housekeeping
    def _handle_events(self, events: list[tuple]) -> None:
        for event in events:
            kind = event[0]
            if kind == "mission_item_reached":
                self._send(self.mav.mission_item_reached_encode(event[1]))
                self._statustext(mavlink.MAV_SEVERITY_INFO, f"Reached waypoint #{event[1]}")
            elif kind == "mission_current":
                self._send(self.telemetry.msg_mission_current())
            elif kind == "mode":
                self._send_heartbeat()
            elif kind in ("armed", "disarmed"):
                self._send_heartbeat()
                text = "Arming motors" if kind == "armed" else f"Disarming motors ({event[1]})"
                self._statustext(mavlink.MAV_SEVERITY_INFO, text)
            elif kind == "text":
                self._statustext(event[1], event[2])

    def _housekeeping(self) -> None:
        now = self.wall_s()
        for upload in self.store.expire_uploads(now):
            peer = self._uploads.pop(upload.mission_type, None)
            if peer is not None:
                self._send(self.mav.mission_ack_encode(peer.sysid, peer.compid,
                                                       MissionResult.OPERATION_CANCELLED, upload.mission_type),
                           peer.address)
        for mission_type, peer in list(self._uploads.items()):
            if now - peer.last_request_wall_s > REQUEST_RETRY_S:
                self._request_item(mission_type, peer.requested_seq)


def _param_name(raw: Any) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return str(raw).split("\x00", 1)[0]


def _i16(value: float) -> int:
    return int(max(-32768, min(32767, round(value))))


__all__ = ["MavlinkServer", "LinkStats", "CAPABILITIES"]
