"""Helpers for the tests against ArduPilot's own helicopter firmware (``arducopter-heli`` SITL).

``start_ardupilot`` runs ``../shared/ardupilot/arducopter-heli`` in a temporary directory on
free ports: SERIAL0 sends MAVLink to the companion's UDP port, SERIAL2 to the test's own
``VehicleObserver`` (an independent pymavlink connection that asks for its own streams, as a
ground station would). With ``adsb_count`` the SITL's simulated ADS-B traffic is on (ArduPilot's
SITL then uses SERIAL1 for its ADS-B receiver). ``ardupilot_unavailable`` says why the binary
cannot run here (the tests are skipped with that reason).

``VehicleObserver`` records the vehicle's own track (LOCAL_POSITION_NED, GLOBAL_POSITION_INT),
armed state, mode and STATUSTEXTs, and can act as the ground crew or the safety pilot: wait
until the vehicle is ready to arm, move its home (DO_SET_HOME), arm, engage the interlock and
take off.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import queue
import random
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from support import REPO_ROOT

from companion.errors import ProcessError
from companion.sitl.processes import ManagedProcess
from heli_common.mavlink_ids import COPTER_MODES
from heli_common.ports import free_port

ARDUPILOT_DIR = REPO_ROOT.parent / "shared" / "ardupilot"
ARDUPILOT_BIN = ARDUPILOT_DIR / "arducopter-heli"
ARDUPILOT_PARAMS = ARDUPILOT_DIR / "copter-heli.parm"
MAV_SYS_STATUS_PREARM_CHECK = 1 << 28
GUIDED = COPTER_MODES["GUIDED"]


def ardupilot_unavailable() -> str | None:
    """Why ``arducopter-heli`` cannot run here, or None when it can."""
    if not ARDUPILOT_BIN.is_file():
        return f"{ARDUPILOT_BIN} is not there (ArduPilot's helicopter SITL, see its README)"
    if not os.access(ARDUPILOT_BIN, os.X_OK):
        return f"{ARDUPILOT_BIN} is not executable"
    if not ARDUPILOT_PARAMS.is_file():
        return f"{ARDUPILOT_PARAMS} is not there"
    try:
        result = subprocess.run([str(ARDUPILOT_BIN), "--help"], capture_output=True, timeout=20)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"{ARDUPILOT_BIN} cannot run here: {exc}"
    if b"--speedup" not in result.stdout + result.stderr:
        return f"{ARDUPILOT_BIN} --help did not answer as ArduPilot's SITL (exit {result.returncode})"
    return None


def _port_free(kind: int, port: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as sock:
        try:
            sock.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def free_instance() -> int:
    """A SITL instance number whose own ports (TCP 5760-5763 and UDP 5501 + 10 x N) are free."""
    for _ in range(200):
        n = random.randint(20, 400)
        if all(_port_free(socket.SOCK_STREAM, 5760 + 10 * n + k) for k in range(4)) and _port_free(
            socket.SOCK_DGRAM, 5501 + 10 * n
        ):
            return n
    raise RuntimeError("no free ArduPilot SITL instance number")


@dataclasses.dataclass
class ArduPilotSitl:
    """A running ``arducopter-heli``: ``companion_port`` is where it sends MAVLink for the
    companion (``udpin://127.0.0.1:<port>``); ``observer`` watches it on its own port."""

    proc: ManagedProcess  # its log: directory / "sitl.log"
    directory: Path
    companion_port: int
    observer: VehicleObserver
    speedup: float
    home: tuple

    def log_tail(self, lines: int = 40) -> str:
        return self.proc.log_tail(lines)


@contextlib.contextmanager
def start_ardupilot(
    directory,
    *,
    speedup: float = 8.0,
    home=(47.397742, 8.545594, 488.0, 0.0),
    adsb_count: int = 0,
    adsb_radius_m: float = 400.0,
    adsb_alt_m: float = 900.0,
) -> Iterator[ArduPilotSitl]:
    """Start ``arducopter-heli`` (fresh parameters in ``directory``) and its observer."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    defaults = [str(ARDUPILOT_PARAMS)]
    if adsb_count:
        extra = directory / "adsb.parm"
        extra.write_text(
            f"ADSB_TYPE 1\nSIM_ADSB_COUNT {adsb_count}\nSIM_ADSB_RADIUS {adsb_radius_m:g}\n"
            f"SIM_ADSB_ALT {adsb_alt_m:g}\n"
        )
        defaults.append(str(extra))
    companion_port = free_port()
    observer = VehicleObserver()
    cmd = [
        str(ARDUPILOT_BIN),
        "--model",
        "heli",
        "--speedup",
        f"{speedup:g}",
        "--defaults",
        ",".join(defaults),
        "-I",
        str(free_instance()),
        "--home",
        ",".join(f"{v:.7f}" for v in home),
        "--serial0",
        f"udpclient:127.0.0.1:{companion_port}",
        "--serial2",
        f"udpclient:127.0.0.1:{observer.port}",
    ]
    proc = ManagedProcess(cmd, directory / "sitl.log", name="arducopter-heli", cwd=directory)
    sitl = ArduPilotSitl(proc, directory, companion_port, observer, speedup, tuple(home[:3]))
    with proc:
        try:
            observer.start()
            try:
                proc.wait_ready(lambda: observer.wait_heartbeat(0.2), 30.0, "heartbeat", poll_s=0.0)
            except ProcessError as exc:
                raise RuntimeError(f"{exc}; log:\n{sitl.log_tail()}") from None
            observer.request_streams()
            yield sitl
        finally:
            observer.stop()


class VehicleObserver:
    """An independent pymavlink connection to the vehicle (a ground station / safety pilot).

    Attributes
    ----------
    track : list of (time_boot_s, north, east, down)
        LOCAL_POSITION_NED (the vehicle's EKF-origin frame).
    global_track : list of (time_boot_s, lat_deg, lon_deg, alt_m AMSL, rel_alt_m)
        GLOBAL_POSITION_INT.
    armed, mode : bool / int or None
    statustexts : list of (monotonic_s, text)
    home, origin : (lat, lon, alt AMSL) or None
    """

    def __init__(self) -> None:
        from pymavlink import mavutil

        self.port = free_port()
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}", source_system=253, source_component=190)
        self.mavlink = mavutil.mavlink
        self.track: list[tuple] = []
        self.clock: list[tuple[float, float]] = []  # (monotonic_s, time_boot_s)
        self.global_track: list[tuple] = []
        self.armed: bool | None = None
        self.mode: int | None = None
        self.landed_state: int | None = None
        self.rpm: float | None = None
        self.boot_s = 0.0
        self.statustexts: list[tuple[float, str]] = []
        self.adsb: list = []
        self.home: tuple | None = None
        self.origin: tuple | None = None
        self.prearm_ok = False
        self._acks: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="vehicle-observer")
        self._heard = threading.Event()

    # ------------------------------------------------------------------ receiving
    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.conn.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.conn.recv_match(blocking=True, timeout=0.2)
            except (OSError, ValueError):
                continue
            if msg is None or msg.get_srcSystem() != 1:
                continue
            kind = msg.get_type()
            if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.armed = bool(msg.base_mode & self.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                self.mode = msg.custom_mode
                self._heard.set()
            elif kind == "LOCAL_POSITION_NED":
                self.boot_s = msg.time_boot_ms / 1000.0
                self.track.append((self.boot_s, msg.x, msg.y, msg.z))
                self.clock.append((time.monotonic(), self.boot_s))
            elif kind == "GLOBAL_POSITION_INT":
                self.global_track.append(
                    (msg.time_boot_ms / 1000.0, msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3, msg.relative_alt / 1e3)
                )
            elif kind == "COMMAND_ACK":
                self._acks.put(msg)
            elif kind == "STATUSTEXT":
                self.statustexts.append((time.monotonic(), msg.text))
            elif kind == "SYS_STATUS":
                self.prearm_ok = bool(msg.onboard_control_sensors_health & MAV_SYS_STATUS_PREARM_CHECK)
            elif kind == "HOME_POSITION":
                self.home = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
            elif kind == "GPS_GLOBAL_ORIGIN":
                self.origin = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
            elif kind == "EXTENDED_SYS_STATE":
                self.landed_state = msg.landed_state
            elif kind == "RPM":
                self.rpm = msg.rpm1
            elif kind == "ADSB_VEHICLE":
                self.adsb.append(msg)

    def wait_heartbeat(self, timeout_s: float) -> bool:
        return self._heard.wait(timeout_s)

    def wait_until(self, predicate, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
            time.sleep(0.05)

    def wait_vehicle_s(self, seconds: float) -> None:
        """Sleep ``seconds`` of vehicle time (time_boot_ms)."""
        end = self.boot_s + seconds
        self.wait_until(lambda: self.boot_s >= end, 10.0 + seconds, f"{seconds:g} s of vehicle time")

    # ------------------------------------------------------------------ commands
    def command(self, command: int, *params: float, timeout_s: float = 3.0):
        """COMMAND_LONG; returns the MAV_RESULT (None: no ack)."""
        while not self._acks.empty():
            self._acks.get_nowait()
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, 1, command, 0, *p)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                ack = self._acks.get(timeout=0.1)
            except queue.Empty:
                continue
            if ack.command == command:
                return ack.result
        return None

    def request_streams(self) -> None:
        """This connection's own streams (ArduPilot's rates are per link)."""
        m = self.mavlink
        for msg_id, hz in (
            (m.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 10),
            (m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 10),
            (m.MAVLINK_MSG_ID_SYS_STATUS, 2),
            (m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 2),
            (m.MAVLINK_MSG_ID_HOME_POSITION, 1),
            (m.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 1),
            (m.MAVLINK_MSG_ID_RPM, 4),
        ):
            self.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def wait_ready_to_arm(self, timeout_s: float = 120.0) -> None:
        """The ground crew's check: interlock switch low, then wait until the pre-arm checks
        pass (EKF, GPS, IMU consistency) and home and the EKF origin are known."""
        m = self.mavlink
        deadline = time.monotonic() + timeout_s
        while not (self.prearm_ok and self.home is not None and self.origin is not None):
            if time.monotonic() > deadline:
                raise AssertionError(f"the vehicle is not ready to arm after {timeout_s:g} s: {self.statustexts[-3:]}")
            # the switch is read again when the RC input starts: say it again until it holds
            self.command(m.MAV_CMD_DO_AUX_FUNCTION, 32, 0)
            time.sleep(1.0)

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """MAV_CMD_DO_SET_HOME (COMMAND_INT, exact) and wait to see it in HOME_POSITION."""
        m = self.mavlink
        while not self._acks.empty():
            self._acks.get_nowait()
        self.conn.mav.command_int_send(
            1,
            1,
            m.MAV_FRAME_GLOBAL,
            m.MAV_CMD_DO_SET_HOME,
            0,
            0,
            0,
            0,
            0,
            0,
            int(round(lat_deg * 1e7)),
            int(round(lon_deg * 1e7)),
            float(alt_m),
        )
        self.wait_until(
            lambda: self.home is not None and abs(self.home[0] - lat_deg) < 1e-6 and abs(self.home[1] - lon_deg) < 1e-6,
            10.0,
            "the new home",
        )

    def take_off_and_hover(self, alt_m: float, runup_s: float = 12.0) -> None:
        """The safety pilot: GUIDED, arm, engage the interlock after the arming delay, wait
        for the rotor, take off to ``alt_m`` and leave the helicopter hovering in GUIDED."""
        m = self.mavlink
        assert self.command(m.MAV_CMD_DO_AUX_FUNCTION, 32, 0) == 0
        assert self.command(m.MAV_CMD_DO_SET_MODE, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED) == 0
        for _ in range(5):
            if self.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0:
                break
            self.wait_vehicle_s(2.0)
        self.wait_until(lambda: self.armed, 10.0, "armed")
        self.wait_vehicle_s(2.5)
        assert self.command(m.MAV_CMD_DO_AUX_FUNCTION, 32, 2) == 0
        self.wait_vehicle_s(runup_s)
        assert self.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt_m) == 0
        self.wait_until(
            lambda: bool(self.track) and -self.track[-1][3] > alt_m - 0.7, 60.0, f"the pilot's takeoff to {alt_m} m"
        )

    # ------------------------------------------------------------------ the record
    def local_positions(self, since_boot_s: float = 0.0) -> np.ndarray:
        """(K, 3) LOCAL_POSITION_NED positions since ``since_boot_s`` (EKF-origin frame)."""
        rows = [p[1:] for p in list(self.track) if p[0] >= since_boot_s]
        return np.array(rows, dtype=float).reshape(-1, 3)

    def positions_about(self, frame, since_boot_s: float = 0.0) -> np.ndarray:
        """(K, 3) NED positions about ``frame`` (a ``companion.geo.LocalFrame``) from
        GLOBAL_POSITION_INT: judged without the companion's own frame conversion."""
        rows = np.array([g[1:4] for g in list(self.global_track) if g[0] >= since_boot_s], dtype=float).reshape(-1, 3)
        if not len(rows):
            return rows
        return frame.to_ned_array(rows)

    def speedup_between(self, t0_monotonic_s: float, t1_monotonic_s: float) -> float:
        """The vehicle seconds per wall-clock second it achieved between two instants."""
        rows = [c for c in list(self.clock) if t0_monotonic_s <= c[0] <= t1_monotonic_s]
        if len(rows) < 2 or rows[-1][0] <= rows[0][0]:
            return float("nan")
        return (rows[-1][1] - rows[0][1]) / (rows[-1][0] - rows[0][0])

    def speedup_profile(self, t0_monotonic_s: float, t1_monotonic_s: float, step_s: float = 2.0) -> list[float]:
        """Achieved speed-up over consecutive ``step_s`` windows."""
        out, t = [], t0_monotonic_s
        while t + step_s <= t1_monotonic_s:
            out.append(round(self.speedup_between(t, t + step_s), 2))
            t += step_s
        return out

    def texts_since(self, t_monotonic_s: float) -> list[str]:
        return [text for t, text in list(self.statustexts) if t >= t_monotonic_s]
