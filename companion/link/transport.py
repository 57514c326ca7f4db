"""The gate's two sockets and its thread: the vehicle side as the user's URL says, MAVSDK's side
on loopback UDP.

Vehicle side, by MAVSDK URL:

- ``udpin://HOST:PORT`` (and ``udp://``): listen; answer the address of the last autopilot
  HEARTBEAT the inbound filter *accepted* (junk, unsigned frames or a ground station's
  heartbeat from elsewhere never redirect the link);
- ``udpout://HOST:PORT``: send to that address, receive its answers;
- ``tcpout://HOST:PORT`` (and ``tcp://``), ``tcpin://``, ``serial://DEVICE[:BAUD]``: through
  pymavlink's ``mavutil`` as a byte stream.

``GateThread`` moves bytes between the two with ``select`` on one thread (a few tens of
microseconds per frame), so the asyncio loop that streams setpoints never parses MAVLink.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import select
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable

from companion.errors import LinkError
from companion.link.gate import LINK_ONLY_MESSAGES, Identity, InboundFilter, OutboundSigner, SigningKey
from heli_common.tlog import TlogWriter
from mavlink_signing import SignatureCheck

log = logging.getLogger(__name__)

MAX_DATAGRAM = 65535
#: The gate thread's longest wait for traffic (s): its own frames wait at most this long.
SELECT_TIMEOUT_S = 0.2
#: The messages the link reads (``inbound.taps``) are handed to the event loop in one batch at
#: most this often (s): each hand-over wakes the loop, and the vehicle's telemetry streams
#: (10 Hz at most) arrive as about 40 datagrams a second. Their arrival times are stamped here.
TAP_HANDOVER_PERIOD_S = 0.1
#: Linux's SO_TIMESTAMP (= SCM_TIMESTAMP; Python's socket module does not name it): the kernel
#: stamps each datagram's arrival (wall clock, struct timeval), so a datagram read in a batch keeps
#: its true arrival time (the vehicle clock's estimate rests on it).
SO_TIMESTAMP = 29 if sys.platform.startswith("linux") else None
#: Most datagrams read in one batch (``GateThread.batch_reads``): the rest wait for the next.
MAX_BATCH_DATAGRAMS = 256


def split_url(url: str) -> tuple[str, str, int]:
    """``(scheme, host_or_device, port_or_baud)`` of a MAVSDK URL (checked by ``check_url``)."""
    scheme, _, rest = url.partition("://")
    if scheme == "serial":
        device, _, baud = rest.rpartition(":") if rest.count(":") else (rest, "", "57600")
        return scheme, device, int(baud or 57600)
    host, _, port = rest.rpartition(":")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise LinkError(f"cannot open {url}: the port must be a number from 1 to 65535")
    return scheme, host or "0.0.0.0", int(port)


class UdpVehicleSide:
    """The vehicle's UDP side: ``udpin`` listens, ``udpout`` sends to a fixed address."""

    def __init__(self, scheme: str, host: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.peer: tuple[str, int] | None = None
        self.last_from: tuple[str, int] | None = None
        try:
            if scheme in ("udpin", "udp"):
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self.sock.bind((host, port))
            else:
                self.peer = (host, port)
        except OSError as exc:
            self.sock.close()
            raise LinkError(f"cannot open {scheme}://{host}:{port}: {exc}") from None
        self.fixed_peer = self.peer is not None
        self.sock.setblocking(False)
        #: Monotonic arrival time of the last datagram read (kernel-stamped; None: not known)
        self.arrival_s: float | None = None
        self._stamped = False
        if SO_TIMESTAMP is not None:
            with contextlib.suppress(OSError):
                self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 1)
                self._stamped = True

    def fileno(self) -> int:
        return self.sock.fileno()

    def read(self) -> bytes:
        if not self._stamped:
            data, self.last_from = self.sock.recvfrom(MAX_DATAGRAM)
            return data
        data, ancillary, _, self.last_from = self.sock.recvmsg(MAX_DATAGRAM, 64)
        self.arrival_s = None
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP and len(value) >= 16:
                sec, usec = struct.unpack("qq", value[:16])
                self.arrival_s = sec + usec * 1e-6 - (time.time() - time.monotonic())
        return data

    def accepted_from_last(self) -> None:
        """The last datagram held an accepted frame: answer its sender from now on."""
        if not self.fixed_peer:
            self.peer = self.last_from

    def write(self, data: bytes) -> None:
        if self.peer is not None:
            try:
                self.sock.sendto(data, self.peer)
            except OSError as exc:  # e.g. ICMP unreachable while the vehicle restarts
                log.debug("send to the vehicle failed: %s", exc)

    def close(self) -> None:
        self.sock.close()


class StreamVehicleSide:
    """TCP or serial to the vehicle through ``mavutil`` (a byte stream)."""

    def __init__(self, scheme: str, host: str, port: int) -> None:
        from pymavlink import mavutil

        device = {"tcpout": f"tcp:{host}:{port}", "tcp": f"tcp:{host}:{port}", "tcpin": f"tcpin:{host}:{port}"}.get(
            scheme, host
        )
        try:
            self.conn = mavutil.mavlink_connection(
                device, baud=port if scheme == "serial" else 57600, autoreconnect=True
            )
        except Exception as exc:
            raise LinkError(f"cannot open {scheme}://{host}:{port}: {exc}") from None

    def fileno(self) -> int:
        return self.conn.fd if getattr(self.conn, "fd", None) is not None else self.conn.port.fileno()

    #: Arrival times are not known on a byte stream: the gate stamps what it reads when it reads it.
    arrival_s = None

    def read(self) -> bytes:
        return bytes(self.conn.recv(MAX_DATAGRAM) or b"")

    def accepted_from_last(self) -> None:
        pass

    def write(self, data: bytes) -> None:
        try:
            self.conn.write(data)
        except OSError as exc:
            log.debug("send to the vehicle failed: %s", exc)

    def close(self) -> None:
        self.conn.close()


def open_vehicle_side(url: str):
    scheme, host, port = split_url(url)
    if scheme in ("udpin", "udp", "udpout"):
        return UdpVehicleSide(scheme, host, port)
    return StreamVehicleSide(scheme, host, port)


class GateThread:
    """Runs the gate: ``mavsdk_url`` is what MAVSDK connects to (``udpout://127.0.0.1:PORT``).

    Parameters
    ----------
    url : str
        The vehicle's MAVSDK URL.
    inbound : InboundFilter
    outbound : OutboundSigner
    tlog : TlogWriter, optional
        Records every frame accepted from the vehicle and every frame sent to it (closed with
        the gate).
    onboard_period_s : float
        With ``inbound.onboard`` (the companion's own component): its HEARTBEAT period.
    """

    def __init__(
        self,
        url: str,
        inbound: InboundFilter,
        outbound: OutboundSigner,
        tlog: TlogWriter | None = None,
        onboard_period_s: float = 1.0,
    ) -> None:
        self.inbound, self.outbound, self.tlog = inbound, outbound, tlog
        self.onboard_period_s = onboard_period_s
        self._heartbeat_due_s = 0.0
        self._own: collections.deque[bytes] = collections.deque()  # post_own's, sent by the gate's thread
        self._send_lock = threading.Lock()  # the encoder and the vehicle side, shared with the loop
        #: ``on_tap(batch)`` on the gate's thread with the ``inbound.taps`` read since the last
        #: hand-over, at most every ``TAP_HANDOVER_PERIOD_S`` (the link's)
        self.on_tap: Callable[[list], None] | None = None
        self._handover_due_s = 0.0
        #: > 0: the vehicle's datagrams are read in batches this often (``batch_reads``)
        self.read_period_s = 0.0
        self._vehicle_due_s = 0.0
        self.vehicle = open_vehicle_side(url)
        self.local = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.local.bind(("127.0.0.1", 0))
        self.local.setblocking(False)
        self.mavsdk_address: tuple[str, int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink-gate", daemon=True)

    @property
    def mavsdk_url(self) -> str:
        return f"udpout://127.0.0.1:{self.local.getsockname()[1]}"

    def start(self) -> GateThread:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread (the frames ``post_own`` still holds are sent first) and close."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        with contextlib.suppress(OSError, ValueError):
            self._send_posted()
        self.vehicle.close()
        self.local.close()
        if self.tlog is not None:
            self.tlog.close()

    def send_own(self, frame: bytes) -> None:
        """Send a frame of the companion's own component (signed with the link's key)."""
        with self._send_lock:
            signed = self.outbound.sign(frame)
            if signed is not None:
                self._write(signed)

    def send_message(self, msg) -> bool:
        """Send a pymavlink message from MAVSDK's address now, from any thread (the setpoint
        stream's: no trip through MAVSDK); False until that address is known."""
        with self._send_lock:
            frame = self.outbound.pack_own(msg)
            if frame is not None:
                self._write(frame)
        return frame is not None

    def _write(self, frame: bytes) -> None:
        self.vehicle.write(frame)
        if self.tlog is not None:
            self.tlog.write(frame)

    def post_own(self, frame: bytes) -> None:
        """Send a frame of the companion's own component from any thread (the gate's thread
        signs and sends it within its next turn, at most ``SELECT_TIMEOUT_S``)."""
        self._own.append(frame)

    def _send_posted(self) -> None:
        while self._own:
            self.send_own(self._own.popleft())

    def _onboard_heartbeat(self) -> None:
        now = time.monotonic()
        if self.inbound.onboard is not None and now >= self._heartbeat_due_s:
            self._heartbeat_due_s = now + self.onboard_period_s
            frame = self.inbound.onboard.heartbeat()
            if frame is not None:
                self.send_own(frame)

    def batch_reads(self, period_s: float) -> None:
        """Read the vehicle's datagrams every ``period_s`` (all that wait, at once) instead of
        as each arrives; 0: as each arrives. The companion batches while its setpoint stream
        runs: about 40 telemetry datagrams a second then cost 10 wake-ups of this thread
        instead of 40; MAVSDK's frames to the vehicle still go at once."""
        self.read_period_s = max(float(period_s), 0.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._onboard_heartbeat()
                self._send_posted()
                now = time.monotonic()
                watched = [self.local, self.vehicle] if now >= self._vehicle_due_s else [self.local]
                ready, _, _ = select.select(watched, [], [], self._select_timeout_s(now))
            except (OSError, ValueError):
                return  # closed under us
            for side in ready:
                try:
                    self._read_vehicle() if side is self.vehicle else self._from_mavsdk()
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError as exc:
                    log.debug("gate: %s", exc)
                except Exception:  # never let the gate die silently
                    log.exception("gate: unexpected error (the link goes on)")
            self._hand_over_taps()

    def _select_timeout_s(self, now: float) -> float:
        """Until the next batch of the vehicle's datagrams or hand-over of the messages read
        (``_hand_over_taps``), when one is due sooner than ``SELECT_TIMEOUT_S``."""
        timeout = SELECT_TIMEOUT_S
        if now < self._vehicle_due_s:
            timeout = min(timeout, self._vehicle_due_s - now)
        if self.inbound.taps:
            timeout = min(timeout, self._handover_due_s - now)
        return max(timeout, 0.0)

    def _read_vehicle(self) -> None:
        """One datagram (or read of a byte stream); with ``read_period_s``, every datagram that
        waits, and the next read not before ``read_period_s``."""
        if self.read_period_s <= 0.0:
            self._from_vehicle()
            return
        self._vehicle_due_s = time.monotonic() + self.read_period_s
        for _ in range(MAX_BATCH_DATAGRAMS if isinstance(self.vehicle, UdpVehicleSide) else 1):
            self._from_vehicle()  # BlockingIOError when none is left

    def _hand_over_taps(self) -> None:
        """Hand the messages read to ``on_tap`` in one batch, at most every ``TAP_HANDOVER_PERIOD_S``."""
        now = time.monotonic()
        if not self.inbound.taps or now < self._handover_due_s:
            return
        self._handover_due_s = now + TAP_HANDOVER_PERIOD_S
        taps, self.inbound.taps = self.inbound.taps, []
        if self.on_tap is not None:
            self.on_tap(taps)

    def _from_vehicle(self) -> None:
        data = self.vehicle.read()
        frames = self.inbound.filter(data, self.vehicle.arrival_s)
        while self.inbound.replies:
            self.send_own(self.inbound.replies.pop(0))
        if self.inbound.autopilot_heard:
            self.vehicle.accepted_from_last()
        for frame, kind in zip(frames, self.inbound.kinds):
            if self.tlog is not None:
                self.tlog.write(frame)
            if self.mavsdk_address is not None and kind not in LINK_ONLY_MESSAGES:
                self.local.sendto(frame, self.mavsdk_address)

    def _from_mavsdk(self) -> None:
        data, self.mavsdk_address = self.local.recvfrom(MAX_DATAGRAM)
        with self._send_lock:
            for frame in self.outbound.convert(data):
                if self.inbound.onboard is not None and is_heartbeat(frame):
                    continue  # the companion component's own HEARTBEAT speaks for us
                self._write(frame)


def is_heartbeat(frame: bytes) -> bool:
    """Is ``frame`` (one MAVLink 1 or 2 frame) a HEARTBEAT (message id 0)?"""
    if frame[:1] == b"\xfd":
        return frame[7:10] == b"\x00\x00\x00"
    return frame[:1] == b"\xfe" and frame[5:6] == b"\x00"


def open_gate(
    url: str, key: SigningKey | None = None, link_id: int = 0, tlog_path: str | None = None, onboard=None
) -> GateThread:
    """Open the vehicle side of ``url`` and start the gate (signing with ``key`` if given;
    recording the traffic to the ``.tlog`` file ``tlog_path`` if given; speaking as the
    companion component ``onboard``, a ``companion.link.onboard.OnboardComponent``, if given)."""
    identity = Identity()
    check = None if key is None else SignatureCheck(key.key)
    outbound = OutboundSigner(identity, None if key is None else key.key, link_id)
    try:
        tlog = TlogWriter(tlog_path) if tlog_path else None
    except OSError as exc:
        raise LinkError(f"--tlog: cannot write {tlog_path} ({exc.strerror or exc})") from None
    gate = GateThread(url, InboundFilter(identity, check, onboard=onboard), outbound, tlog)
    gate.inbound.stream = not isinstance(gate.vehicle, UdpVehicleSide)
    return gate.start()
