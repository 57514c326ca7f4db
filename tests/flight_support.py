"""Helpers for companion flight tests: a telemetry listener and the companion process.

The flights with threats (``flight_processes``: ``companion.sitl.vehicles``'s; ``fly``:
``companion.demo``'s) and any other child process (``spawn``: a ``companion.sitl``
``ManagedProcess``) run on this checkout: the child processes get the repository root on their
``PYTHONPATH`` (``support.checkout_env``), so they run the code under test even where another
checkout is installed (a worktree, a benchmark run as a script). ``DEMO_MISSION`` is the demo's
mission (``mission_files/`` links to the package data). The other flight helpers are
re-exported from ``companion.demo``.

``TrackListener`` is an independent pymavlink listener on its own UDP port (give its address to
``sim-vehicle --out``): the flown track and the armed state come from the vehicle itself, not
from the companion under test. Like any logger of an ArduPilot vehicle it asks for what it
records: on the first HEARTBEAT it sends SET_MESSAGE_INTERVAL for LOCAL_POSITION_NED back to the
address the heartbeat came from (its own link), and asks again each second until the track flows.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np
from support import REPO_ROOT, checkout_env

from companion import demo as _demo
from companion.demo import DEMO_HOME, FlightWatcher, Injection, inject, last_json_line, place  # noqa: F401
from companion.sitl import processes, vehicles
from heli_common.ports import free_port

MAV_MODE_FLAG_SAFETY_ARMED = 128


class TrackListener:
    """Collects LOCAL_POSITION_NED and HEARTBEAT from the vehicle on a UDP port of its own, and,
    as a ground station sees them, the companion's COLLISION and STATUSTEXT (forwarded by the
    vehicle), each with its wall-clock receipt time.

    Parameters
    ----------
    rate_hz : float
        LOCAL_POSITION_NED rate it asks for, Hz of simulated time.
    """

    def __init__(self, rate_hz: float = 10.0) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        self.mavlink = mavlink2
        self.rate_hz = float(rate_hz)
        self.port = free_port()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", self.port))
        self._sock.settimeout(0.2)
        self._mav = mavlink2.MAVLink(None, srcSystem=253, srcComponent=191)
        self._mav.robust_parsing = True
        self._requested_wall_s = -1e9
        self.track: list[tuple[float, float, float, float]] = []  # (time_boot_s, n, e, d)
        self.armed: bool | None = None
        self.mode: int | None = None
        self.collisions: list[tuple[float, object]] = []  # (monotonic s, COLLISION)
        self.companion_texts: list[tuple[float, object]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, vehicle = self._sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            for msg in self._mav.parse_buffer(data) or []:
                kind = msg.get_type()
                if kind == "LOCAL_POSITION_NED":
                    self.track.append((msg.time_boot_ms / 1000.0, msg.x, msg.y, msg.z))
                elif kind == "COLLISION":
                    self.collisions.append((time.monotonic(), msg))
                elif kind == "STATUSTEXT" and msg.get_srcComponent() != 1:
                    self.companion_texts.append((time.monotonic(), msg))
                elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                    self.armed = bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
                    self.mode = msg.custom_mode
                    self._ask_for_track(vehicle, msg.get_srcSystem())

    def _ask_for_track(self, vehicle: tuple[str, int], sysid: int) -> None:
        """SET_MESSAGE_INTERVAL LOCAL_POSITION_NED to the vehicle, until the track flows."""
        now = time.monotonic()
        if self.track or now - self._requested_wall_s < 1.0:
            return
        self._requested_wall_s = now
        m = self.mavlink
        request = self._mav.command_long_encode(
            sysid,
            1,
            m.MAV_CMD_SET_MESSAGE_INTERVAL,
            0,
            m.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
            int(round(1e6 / self.rate_hz)),
            0,
            0,
            0,
            0,
            0,
        )
        try:
            self._sock.sendto(request.pack(self._mav), vehicle)
        except OSError:
            pass

    def positions(self) -> np.ndarray:
        """The track so far as (K, 3) NED positions."""
        return self.samples()[1]

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """One consistent snapshot of the track (the listener keeps appending): times (K,) in s
        since the vehicle's boot and NED positions (K, 3)."""
        track = np.array(list(self.track), dtype=float).reshape(-1, 4)
        return track[:, 0], track[:, 1:]

    def __enter__(self) -> TrackListener:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._sock.close()


def run_companion(*args: str, timeout_s: float = 240.0) -> subprocess.CompletedProcess:
    """Run ``companion ARGS`` to completion (stdout, stderr captured as text)."""
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", *args],
        cwd=str(REPO_ROOT),
        capture_output=True,
        text=True,
        timeout=timeout_s,
        env=env,
    )


def wait_until(predicate, timeout_s: float, what: str, poll_s: float = 0.1) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)


#: The demo's mission in this checkout (a link to ``companion/data/exclusion_zones.plan``).
DEMO_MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"


def spawn(module_args: list[str], log_path) -> processes.ManagedProcess:
    """``python -m <module_args>`` on this checkout, started (its output to ``log_path``)."""
    return processes.spawn(processes.python_command(module_args), log_path, env=checkout_env())


def flight_processes(out_dir, mission, **kwargs):
    """``companion.sitl.vehicles.flight_processes`` on this checkout."""
    return vehicles.flight_processes(out_dir, mission, env=checkout_env(), **kwargs)


def fly(out_dir, mission, **kwargs) -> dict:
    """``companion.demo.fly`` on this checkout."""
    return _demo.fly(out_dir, mission, env=checkout_env(), **kwargs)
