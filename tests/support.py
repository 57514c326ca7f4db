"""Helpers for integration tests: a real ``sim-vehicle`` process, and a MAVLink ground station.

Integration tests start real processes on loopback and must never bind default ports (other
flights run at the same time), so every port comes from the OS (``heli_common.ports.free_port``).
The processes are ``companion.sitl`` ``ManagedProcess``-es (their own process group, a log file,
ending with the test run; stopped with SIGINT, SIGTERM, then SIGKILL, leaving nothing behind),
run on this checkout (``checkout_env``).

Example
-------
>>> with start_sim_vehicle(out=[f"127.0.0.1:{gcs_port}"], speedup=5) as sim:  # doctest: +SKIP
...     print(sim.port, sim.sysid)          # the vehicle's UDP port and MAVLink system id
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import socket
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

from companion.errors import ProcessError
from companion.sitl.processes import ManagedProcess, python_command
from companion.sitl.vehicles import sim_vehicle_args
from heli_common.ports import free_port

REPO_ROOT = Path(__file__).resolve().parents[1]


def checkout_env() -> dict:
    """This environment with the repository root first on ``PYTHONPATH``: a child process runs
    the code under test even where another checkout is installed (a worktree, a benchmark)."""
    return dict(os.environ, PYTHONPATH=str(REPO_ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


@dataclasses.dataclass
class SimVehicle:
    """A running ``sim-vehicle`` process.

    Attributes
    ----------
    port : int
        UDP port the vehicle listens on (send MAVLink to ``127.0.0.1:port``; it answers to
        every peer it heard in the last 10 s).
    sysid : int
        MAVLink system id (``1 + instance``); the autopilot is component 1.
    instance : int
        The ``--instance`` number.
    proc : companion.sitl.processes.ManagedProcess
        The process (its log: ``proc.log_path``, stdout and stderr).
    out : list of str
        The ``--out HOST:PORT`` addresses telemetry is sent to.
    """

    port: int
    sysid: int
    instance: int
    proc: ManagedProcess
    out: list[str]

    @property
    def address(self) -> str:
        """``127.0.0.1:<port>``, e.g. for MAVProxy ``--master=udpout:<address>``."""
        return f"127.0.0.1:{self.port}"

    @property
    def log_path(self) -> Path:
        return self.proc.log_path

    def log_text(self) -> str:
        """The process log so far (for assertion messages)."""
        return self.proc.log_text()

    def log_tail(self, lines: int = 60) -> str:
        """The last ``lines`` lines of the log."""
        return self.proc.log_tail(lines)

    def is_running(self) -> bool:
        """True while the process has not exited."""
        return self.proc.is_running()


class HeartbeatProbe:
    """A readiness condition: the vehicle ``sysid`` on ``127.0.0.1:port`` answers a GCS heartbeat.

    Each call sends one heartbeat and waits up to ``wait_s`` for the vehicle's. The probe is a
    peer for 10 s only; it does not use any of the ``--out`` ports. A vehicle with a signing key
    hears only a probe that signs with ``signing_key``.
    """

    def __init__(self, port: int, sysid: int, signing_key: bytes | None = None, wait_s: float = 0.2) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        self.address = ("127.0.0.1", int(port))
        self.sysid = int(sysid)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(wait_s)
        self.mav = mavlink2.MAVLink(None, srcSystem=254, srcComponent=190)
        self.mav.robust_parsing = True
        if signing_key is not None:
            sign_with(self.mav, signing_key, link_id=254)
        self.heartbeat = self.mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def __call__(self) -> bool:
        # packed each time: a signed frame sent twice is a replay
        self.sock.sendto(self.heartbeat.pack(self.mav), self.address)
        try:
            data = self.sock.recv(65535)
        except (TimeoutError, ConnectionRefusedError):
            return False
        return any(
            msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == self.sysid
            for msg in self.mav.parse_buffer(data) or []
        )

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> HeartbeatProbe:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def sign_with(mav, key: bytes, link_id: int = 1) -> None:
    """Make the pymavlink ``MAVLink`` object ``mav`` sign what it packs and check what it parses.

    As ``mavutil``'s ``setup_signing(key, sign_outgoing=True)``: the timestamp starts at the
    wall clock (10 us since 2015).
    """
    from mavlink_signing import signing_timestamp_now

    mav.signing.secret_key = bytes(key)
    mav.signing.sign_outgoing = True
    mav.signing.link_id = int(link_id)
    mav.signing.timestamp = signing_timestamp_now()


@contextlib.contextmanager
def start_sim_vehicle(
    port: int | None = None,
    out: Sequence[str] = (),
    speedup: float = 1.0,
    instance: int = 0,
    extra_args: Sequence[str] = (),
    ready_timeout_s: float = 20.0,
    log_dir: str | os.PathLike | None = None,
    signing_key: bytes | None = None,
) -> Iterator[SimVehicle]:
    """Start a real ``sim-vehicle`` process and wait until it sends heartbeats.

    Parameters
    ----------
    port : int, optional
        UDP port to bind (default: a free one).
    out : sequence of str
        ``HOST:PORT`` telemetry destinations (``--out``); empty means none besides peers
        (the default ``--out`` addresses 14550/14540 are never used by tests).
    speedup : float
        ``--speedup``.
    instance : int
        ``--instance`` (system id ``1 + instance``).
    extra_args : sequence of str
        More command-line arguments, e.g. ``["--home", "47.39,8.54,488,0", "-v"]``.
    ready_timeout_s : float
        How long to wait for the first heartbeat.
    log_dir : path, optional
        Where the log file goes (default: a temporary directory).
    signing_key : bytes, optional
        The key the ready probe signs with (pass ``--signing-key FILE`` in ``extra_args``).

    Yields
    ------
    SimVehicle
        With ``.port``, ``.sysid``, ``.proc``, ``.log_text()``. On exit the process is stopped
        (SIGINT, then SIGTERM and SIGKILL if it does not exit).
    """
    port = free_port() if port is None else int(port)
    directory = Path(log_dir) if log_dir is not None else Path(tempfile.mkdtemp(prefix="sim_vehicle_"))
    directory.mkdir(parents=True, exist_ok=True)
    args = sim_vehicle_args(port, outs=out, speedup=speedup, instance=instance, default_outs=False, extra=extra_args)
    proc = ManagedProcess(
        python_command(args),
        directory / f"sim_vehicle_{instance}_{port}.log",
        name=f"sim-vehicle on port {port}",
        env=checkout_env(),
        cwd=REPO_ROOT,
    )
    sim = SimVehicle(port=port, sysid=1 + instance, instance=instance, proc=proc, out=list(out))
    with proc:
        with HeartbeatProbe(port, sim.sysid, signing_key) as probe:
            try:
                proc.wait_ready(probe, ready_timeout_s, "heartbeat", poll_s=0.0)
            except ProcessError as exc:
                raise RuntimeError(f"{exc}; log:\n{sim.log_tail()}") from None
        yield sim


class MavlinkPeer:
    """A minimal pymavlink ground station on loopback for tests (blocking, no threads).

    It sends a GCS heartbeat at least once a second while it waits, so the vehicle keeps it as a
    peer. Like ArduPilot, the vehicle streams nothing but HEARTBEAT to it until it asks:
    :meth:`request` (SET_MESSAGE_INTERVAL per message), as a ground station does. A helicopter
    takes off only with its motor interlock engaged and its rotor run up: :meth:`heli_takeoff`.

    Parameters
    ----------
    port : int
        The vehicle's UDP port.
    sysid : int
        The vehicle's system id (commands target it).
    source_system, source_component : int
        Our own ids.
    signing_key : bytes, optional
        Sign what we send and accept only what is signed with this key (:func:`sign_with`).
    """

    def __init__(
        self,
        port: int,
        sysid: int = 1,
        source_system: int = 250,
        source_component: int = 190,
        signing_key: bytes | None = None,
    ) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        self.mavlink = mavlink2
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.address = ("127.0.0.1", int(port))
        self.sysid = int(sysid)
        self.mav = mavlink2.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        self.mav.robust_parsing = True
        if signing_key is not None:
            sign_with(self.mav, signing_key)
        self.last = {}
        self._last_heartbeat = 0.0
        self.heartbeat()

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> MavlinkPeer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send(self, msg) -> None:
        """Encode and send one message to the vehicle."""
        self.sock.sendto(msg.pack(self.mav), self.address)

    def send_raw(self, data: bytes) -> None:
        """Send raw bytes (for malformed-input tests)."""
        self.sock.sendto(data, self.address)

    def heartbeat(self) -> None:
        m = self.mavlink
        self.send(self.mav.heartbeat_encode(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0))
        self._last_heartbeat = time.monotonic()

    def receive(self, timeout_s: float = 0.05) -> list:
        """Messages from the vehicle that arrive within ``timeout_s`` (one datagram)."""
        if time.monotonic() - self._last_heartbeat > 1.0:
            self.heartbeat()
        self.sock.settimeout(timeout_s)
        try:
            data = self.sock.recv(65535)
        except (TimeoutError, ConnectionRefusedError):
            return []
        out = []
        for msg in self.mav.parse_buffer(data) or []:
            if msg.get_type() == "BAD_DATA" or msg.get_srcSystem() != self.sysid:
                continue
            self.last[msg.get_type()] = msg
            out.append(msg)
        return out

    def wait(self, kind: str, timeout_s: float = 5.0, condition=None):
        """The next message of type ``kind`` (satisfying ``condition``), or None on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for msg in self.receive(min(0.1, max(0.0, deadline - time.monotonic()))):
                if msg.get_type() == kind and (condition is None or condition(msg)):
                    return msg
        return None

    def command(self, command: int, *params: float, timeout_s: float = 3.0, use_int: bool = False, frame: int = 0):
        """Send COMMAND_LONG (or COMMAND_INT in ``frame``) and return its COMMAND_ACK (None if none came)."""
        p = list(params) + [0.0] * (7 - len(params))
        if use_int:
            self.send(
                self.mav.command_int_encode(
                    self.sysid, 1, frame, command, 0, 0, p[0], p[1], p[2], p[3], int(p[4]), int(p[5]), p[6]
                )
            )
        else:
            self.send(self.mav.command_long_encode(self.sysid, 1, command, 0, *p))
        return self.wait("COMMAND_ACK", timeout_s, lambda m: m.command == command)

    def set_mode(self, custom_mode: int):
        """DO_SET_MODE with an ArduCopter mode number; returns the COMMAND_ACK."""
        return self.command(
            self.mavlink.MAV_CMD_DO_SET_MODE, self.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode
        )

    def request(self, *messages: str, rate_hz: float = 10.0) -> None:
        """Ask for ``messages`` (names, e.g. ``"GLOBAL_POSITION_INT"``) at ``rate_hz`` (0 stops them).

        One MAV_CMD_SET_MESSAGE_INTERVAL each, on this peer's link; raises if one is not accepted.
        """
        m = self.mavlink
        interval_us = -1 if rate_hz <= 0 else int(round(1e6 / rate_hz))
        for name in messages:
            ack = self.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, getattr(m, f"MAVLINK_MSG_ID_{name}"), interval_us)
            if ack is None or ack.result != m.MAV_RESULT_ACCEPTED:
                raise AssertionError(f"SET_MESSAGE_INTERVAL {name} at {rate_hz} Hz: {ack}")

    def set_interlock(self, engaged: bool):
        """MAV_CMD_DO_AUX_FUNCTION 32 (motor interlock) high or low; returns the COMMAND_ACK."""
        m = self.mavlink
        return self.command(m.MAV_CMD_DO_AUX_FUNCTION, 32, 2 if engaged else 0)

    def arm_heli(self) -> None:
        """ArduCopter heli start-up: interlock low, arm, interlock high (it takes effect 2 s after arming)."""
        m = self.mavlink
        for step, ack in (
            ("interlock low", lambda: self.set_interlock(False)),
            ("arm", lambda: self.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)),
            ("interlock high", lambda: self.set_interlock(True)),
        ):
            result = ack()
            if result is None or result.result != m.MAV_RESULT_ACCEPTED:
                raise AssertionError(f"{step}: {result}")

    def heli_takeoff(self, alt_m: float, timeout_s: float = 30.0):
        """GUIDED, :meth:`arm_heli`, then NAV_TAKEOFF until accepted (refused during the arming delay).

        The vehicle then waits on the ground for its rotor run-up (H_RSC_RUNUP_TIME) and climbs.
        Returns the accepting COMMAND_ACK; raises if there is none within ``timeout_s`` (wall clock).
        """
        m = self.mavlink
        ack = self.set_mode(4)
        if ack is None or ack.result != m.MAV_RESULT_ACCEPTED:
            raise AssertionError(f"GUIDED: {ack}")
        self.arm_heli()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            ack = self.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt_m)
            if ack is not None and ack.result == m.MAV_RESULT_ACCEPTED:
                return ack
            self.wait("HEARTBEAT", 0.2)
        raise AssertionError(f"NAV_TAKEOFF never accepted; last answer {ack}")

    def download(self, mission_type: int = 0, timeout_s: float = 5.0) -> list | None:
        """The vehicle's list of ``mission_type`` with MISSION_ITEM_INT (None on a protocol failure)."""
        self.send(self.mav.mission_request_list_encode(self.sysid, 1, mission_type))
        count = self.wait("MISSION_COUNT", timeout_s, lambda m: m.mission_type == mission_type)
        if count is None:
            return None
        items = []
        for seq in range(count.count):
            self.send(self.mav.mission_request_int_encode(self.sysid, 1, seq, mission_type))
            item = self.wait("MISSION_ITEM_INT", timeout_s, lambda m, seq=seq: m.seq == seq)
            if item is None:
                return None
            items.append(item)
        self.send(self.mav.mission_ack_encode(self.sysid, 1, 0, mission_type))
        return items

    def upload(self, items: Sequence[tuple], mission_type: int = 0, timeout_s: float = 5.0) -> int | None:
        """Upload ``(frame, command, p1, p2, p3, p4, x_int, y_int, z)`` rows; returns the MISSION_ACK type."""
        self.send(self.mav.mission_count_encode(self.sysid, 1, len(items), mission_type))
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for msg in self.receive(0.1):
                kind = msg.get_type()
                if kind == "MISSION_ACK":
                    return msg.type
                if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and msg.seq < len(items):
                    frame, cmd, p1, p2, p3, p4, x, y, z = items[msg.seq]
                    self.send(
                        self.mav.mission_item_int_encode(
                            self.sysid, 1, msg.seq, frame, cmd, 0, 1, p1, p2, p3, p4, x, y, z, mission_type
                        )
                    )
        return None
