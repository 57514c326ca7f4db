"""The vehicle's UDP endpoint: one socket, its peers, sending, receiving, signing verdicts, counters.

Each datagram is parsed on its own, so random bytes, truncated frames, wrong CRCs and unknown
message ids are counted (:class:`LinkStats`), logged (rate-limited) and dropped without
disturbing the flight. With a signing key (:mod:`sim_vehicle.signing`) everything sent is
signed, and a message that is not signed with the key, or replays an old timestamp, is counted
by reason and dropped before dispatch and routing. Messages sent go to the ``--out`` addresses
and to every peer heard within ``peer_timeout_s`` (as ArduPilot's links do). An optional
``.tlog`` records every packet in and out in the standard format (8-byte big-endian
microseconds since the Unix epoch, then the raw packet), which MAVProxy and MAVExplorer open.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import socket
import time
from collections.abc import Callable, Iterable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.tlog import TlogWriter
from sim_vehicle.config import parse_host_port
from sim_vehicle.signing import VehicleSigning, Verdict

log = logging.getLogger(__name__)

COMPONENT_ID = 1
#: Kernel receive buffer of the vehicle's socket (the kernel may cap it at net.core.rmem_max).
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
STATUSTEXT_CHUNK = 50
#: Broadcast messages of other components forwarded between links (:meth:`Endpoint.route`), as ArduPilot does:
#: texts, heartbeats, and an ADS-B receiver's traffic reports (which reach the companion through the vehicle).
ROUTED = frozenset({"STATUSTEXT", "HEARTBEAT", "ADSB_VEHICLE", "COLLISION"})

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


class LogThrottle:
    """Occurrences counted per key, so that a repeated warning is logged the first times, then rarely."""

    def __init__(self) -> None:
        self._counts: collections.Counter[str] = collections.Counter()

    def count(self, key: str) -> int:
        """Count one more occurrence of ``key``; returns how many so far."""
        self._counts[key] += 1
        return self._counts[key]


def resolve(text: str) -> Address:
    """``host:port`` of an ``--out`` link as a numeric address."""
    host, port = parse_host_port(text, "out")
    return socket.gethostbyname(host), port


class Endpoint:
    """One UDP socket with its destinations: the fixed ``--out`` links and the peers heard.

    Parameters
    ----------
    sysid : int
        MAVLink system id of the vehicle (component is :data:`COMPONENT_ID`).
    bind_host, port : str, int
        Where to bind (port 0: any free port; the bound one is ``self.port``).
    outs : list of str
        ``host:port`` links that always receive what is broadcast.
    peer_timeout_s : float
        A peer not heard for this long (wall-clock seconds) is no longer sent to.
    deliver : callable
        ``deliver(msg, address)`` for each accepted message (before it is routed).
    tlog_path : str, optional
        Write every packet in and out to this ``.tlog`` file.
    wall_s : callable
        Monotonic wall clock.
    signing_key : bytes, optional
        MAVLink 2 signing key (:mod:`sim_vehicle.signing`).
    accept_signing_setup : bool
        Take SETUP_SIGNING while there is no signing key.
    """

    def __init__(
        self,
        sysid: int,
        bind_host: str,
        port: int,
        outs: Iterable[str],
        peer_timeout_s: float,
        deliver: Callable[[Any, Address], None],
        tlog_path: str | None = None,
        wall_s: Callable[[], float] = time.monotonic,
        signing_key: bytes | None = None,
        accept_signing_setup: bool = False,
    ) -> None:
        self.sysid = int(sysid)
        self.peer_timeout_s = peer_timeout_s
        self.wall_s = wall_s
        self.stats = LinkStats()
        self.throttle = LogThrottle()
        self.mav = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
        self.signing = VehicleSigning(self.mav, signing_key, accept_signing_setup)
        self.outs: list[Address] = [resolve(a) for a in outs]
        self.peers: dict[Address, float] = {}
        #: Where each other component was last heard: (system, component) -> address (routing).
        self.routes: dict[tuple[int, int], Address] = {}
        self._deliver = deliver
        self._statustext_id = 0
        self._tlog = TlogWriter(tlog_path) if tlog_path else None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 0)
        # a flood (or a burst while the physics steps) must not overflow the kernel's buffer
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        self.sock.bind((bind_host, int(port)))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]

    def close(self) -> None:
        """Close the socket and the tlog."""
        self.sock.close()
        if self._tlog is not None:
            self._tlog.close()
            self._tlog = None

    # ---------------------------------------------------------------- sending
    def destinations(self) -> list[Address]:
        """The ``--out`` links, then the peers heard within ``peer_timeout_s`` (others are forgotten)."""
        now = self.wall_s()
        dests = list(self.outs)
        for address, heard in list(self.peers.items()):
            if now - heard > self.peer_timeout_s:
                del self.peers[address]
            elif address not in dests:
                dests.append(address)
        return dests

    def send(self, msg: Any, to: Address | Iterable[Address] | None = None) -> None:
        """Encode once and send to ``to`` (one address or several) or to every destination."""
        buf = msg.pack(self.mav)
        if to is None:
            targets = self.destinations()
        elif isinstance(to, tuple) and len(to) == 2 and isinstance(to[1], int):
            targets = [to]
        else:
            targets = list(to)
        self._transmit(buf, targets, "send")

    def route(self, msg: Any, came_from: Address) -> None:
        """Forward another component's message, as ArduPilot's MAVLink routing does
        (``GCS_MAVLink/MAVLink_routing.cpp``), never back where it came from, never our own.

        - A message addressed to another component (``target_system`` / ``target_component``,
          e.g. a ground station's MISSION_START to the companion, 191, or the companion's
          COMMAND_ACK back to that ground station) goes to the link where that component was
          last heard (:attr:`routes`; ``target_component`` 0 of another system: every component
          heard of it). Unlike ArduPilot, a message to our own system with ``target_component``
          0 is handled here only, not also forwarded to the companion.
        - A broadcast of a type in :data:`ROUTED` (STATUSTEXT, HEARTBEAT, ADSB_VEHICLE, COLLISION)
          goes to every other destination, so a ground station sees the companion component, its
          texts and its traffic alerts, and the companion hears an ADS-B receiver's traffic.
        """
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if source == (self.sysid, COMPONENT_ID):
            return
        target_system = getattr(msg, "target_system", 0)
        target_component = getattr(msg, "target_component", 0)
        if target_system:
            if target_system == self.sysid and target_component in (0, COMPONENT_ID):
                return
            targets = {
                address
                for (sysid, compid), address in self.routes.items()
                if sysid == target_system and target_component in (0, compid)
            }
        elif msg.get_type() in ROUTED:
            targets = set(self.destinations())
        else:
            return
        targets.discard(came_from)
        if targets:
            self._transmit(bytes(msg.get_msgbuf()), sorted(targets), "forward")

    def _transmit(self, buf: bytes, targets: Iterable[Address], what: str) -> None:
        for address in targets:
            try:
                self.sock.sendto(buf, address)
                self.stats.packets_out += 1
            except OSError as exc:  # unreachable peer, full buffer: never stop flying
                log.debug("%s to %s failed: %s", what, address, exc)
        if self._tlog is not None:
            self._record(buf)

    def _record(self, buf: bytes) -> None:
        self._tlog.write(buf)

    def statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every link; longer texts in 50-character chunks with an id, as ArduPilot sends them."""
        data = text.encode(errors="replace")
        if len(data) <= STATUSTEXT_CHUNK:
            self.send(self.mav.statustext_encode(severity, data))
            return
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        chunks = [data[i : i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
        for seq, chunk in enumerate(chunks[:255]):
            self.send(self.mav.statustext_encode(severity, chunk, self._statustext_id, seq))

    # ---------------------------------------------------------------- receiving
    def receive(self) -> None:
        """Handle the datagrams waiting in the socket (at most 256, so a flood cannot starve the simulation)."""
        for _ in range(256):
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # e.g. ICMP port unreachable reported on some systems
                log.debug("receive error: %s", exc)
                return
            self.stats.packets_in += 1
            self.handle_datagram(data, address)

    def handle_datagram(self, data: bytes, address: Address) -> None:
        """Parse one datagram; deliver and route each well-formed, authenticated message; count the rest."""
        parser = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
        parser.robust_parsing = True
        try:
            messages = parser.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises a few odd errors on garbage: drop, never crash
            self.count_bad("bad_data", f"{type(exc).__name__}: {exc}", address)
            return
        for msg in messages:
            if self._accepted(msg, address):
                self._accept(msg, address)
        if parser.buf_len() > 0:
            self.count_bad("truncated", f"{parser.buf_len()} bytes left over", address)

    def _accepted(self, msg: Any, address: Address) -> bool:
        """False (counted) for a BAD_DATA, unknown or unauthenticated message."""
        if msg.get_type() == "BAD_DATA":
            reason = str(getattr(msg, "reason", ""))
            if "CRC" in reason.upper():
                self.count_bad("bad_crc", reason, address)
            elif "unknown" in reason.lower() and "id" in reason.lower():
                self.count_bad("unknown_id", reason, address)
            else:
                self.count_bad("bad_data", reason, address)
            return False
        if isinstance(msg, mavlink.MAVLink_unknown):
            self.count_bad("unknown_id", f"unknown message id {msg.get_msgId()}", address)
            return False
        verdict = self.signing.verdict(msg)
        if verdict is not Verdict.ACCEPTED:  # before dispatch and routing, before it makes a peer
            self.count_bad(verdict.value, msg.get_type(), address, what="unauthenticated message")
            return False
        return True

    def _accept(self, msg: Any, address: Address) -> None:
        self.stats.messages_in += 1
        self.peers[address] = self.wall_s()  # before dispatch: a reply broadcast (STATUSTEXT) reaches it too
        self.routes[(msg.get_srcSystem(), msg.get_srcComponent())] = address
        if self._tlog is not None:
            self._record(bytes(msg.get_msgbuf()))
        try:
            self._deliver(msg, address)
            self.route(msg, address)
        except Exception:  # a handler bug must not stop the vehicle: log it loudly
            log.exception("error handling %s from %s", msg.get_type(), address)

    def count_bad(self, kind: str, reason: str, address: Address, what: str = "malformed packet") -> None:
        """Count a dropped message under ``kind`` (a :class:`LinkStats` field) and log it, rate-limited."""
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        n = self.throttle.count(kind)
        if n <= 10 or n % 100 == 0:
            log.warning("dropped %s from %s:%d (%s: %s; %d so far)", what, address[0], address[1], kind, reason, n)

    def on_setup_signing(self, msg: Any, address: Address) -> None:
        """SETUP_SIGNING: change or switch off the key by the rules of :mod:`sim_vehicle.signing`; log either way."""
        done, what = self.signing.setup(msg)
        if done:
            log.info("SETUP_SIGNING from %s:%d (system %d): %s", *address, msg.get_srcSystem(), what)
            return
        n = self.throttle.count("setup_signing")
        if n <= 10 or n % 100 == 0:
            log.warning(
                "SETUP_SIGNING from %s:%d (system %d) refused: %s; %d so far", *address, msg.get_srcSystem(), what, n
            )
