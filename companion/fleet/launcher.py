"""``companion fleet up``: N simulated helicopters and their companions through one zenoh router.

The fleet is real processes, as an operator would start them by hand (DESIGN 6: several
vehicles meet through a zenoh router and share their committed trajectories):

- one ``companion router --listen tcp/127.0.0.1:<free>``;
- for vehicle ``i`` (system id ``i + 1``) flying the ``i``-th mission file of a directory:
  ``sim-vehicle --instance i --home <the file's home>,<heading to its first waypoint> --port <free>
  --out 127.0.0.1:<companion port> --out <GCS> --speedup X --tlog LOGS/sim<i>.tlog`` and ``companion run --instance i
  --connect udpin://127.0.0.1:<companion port> --mission FILE --zenoh-connect <router>
  --zenoh-listen tcp/127.0.0.1:<free> --record LOGS/uav<i+1>.jsonl --time-scale X`` (with
  ``--no-fleet`` for the baseline without sharing, ``--fleet-delay-ms`` to delay the shared
  trajectories).

Each process writes its output to ``LOGS/<name>.log``; ``LOGS/fleet.json`` says where everything
is (router endpoint; per vehicle its system id, ports, process ids and files), for
``companion fleet status --logs LOGS`` and for people.

``Fleet`` is the Python API (tests and ``benchmarks/fleet.py`` use it; ``companion.commands.fleet``
is the argparse layer on top)::

    fleet = Fleet(select_missions("mission_files/fleet/crossing3", 3), logs_dir, speedup=2)
    fleet.start()
    result = fleet.wait(timeout_s=240)      # every companion has exited
    fleet.stop()                            # simulators and router; always (idempotent)

Stopping early (``stop()`` while companions fly, e.g. on SIGINT) interrupts the companions
first (SIGINT: each brings its vehicle to a safe stop, ``link.on_interrupt``), then stops the
simulators and the router, and kills whatever is left of the companions' planning workers:
no process is left behind. The children run in their own process groups so that a Ctrl-C in
the terminal reaches the launcher only, which stops them in that order; they get SIGTERM if
the launcher dies (``PR_SET_PDEATHSIG``).

Synchronised start (``sync_start``, the default): a fleet's companions get ready at different
times (each plans its mission with its own workers while the others do: seconds apart on a
shared machine), and vehicles meant to meet at a crossing would then miss each other. As a
ground operator holds a fleet's take-off until every crew is ready, the launcher holds every
vehicle's pre-arm checks failing (``SIM_PREARM_FAIL = 1`` from the simulator's start, its
``--config``) until every companion waits to arm (its vehicle in GUIDED, disarmed), then clears
them on all at once (PARAM_SET over MAVLink, as a ground station: ``StartGate``). How long a
companion waits for its vehicle's pre-arm checks depends on the vehicle:

- one that reports them in SYS_STATUS (``MAV_SYS_STATUS_PREARM_CHECK``, as ArduPilot does) is
  waited for up to ``startup.prearm_timeout_s`` (30 vehicle s; ``wait_prearm``), and the
  companions then arm within a SYS_STATUS period of each other;
- one that does not (``sim-vehicle`` today) is armed at once, and a refusal is retried
  ``startup.arm_attempts`` times ``retry_interval_s`` apart: the gate then holds at most
  ``HOLD_FRACTION`` of those retries, and the companions arm within one retry interval of each
  other (2 vehicle s).

The gate reads the vehicles' SYS_STATUS to tell which, and never holds a companion past its
budget: one that is not ready by then starts late, as without the gate.

The crossing missions of ``mission_files/fleet/`` and of the benchmark come from
``crossing_missions`` (homes on a circle, each flying through the centre to the far side and
back to its home at one altitude).
"""

from __future__ import annotations

import ctypes
import datetime
import json
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.errors import ConfigError, MissionError

__all__ = ["Fleet", "FleetResult", "FleetVehicle", "StartGate", "VehicleResult", "crossing_missions",
           "first_leg_heading_deg", "head_on_missions",
           "mission_home", "select_missions", "write_missions", "default_logs_dir", "MISSION_SUFFIXES"]

log = logging.getLogger(__name__)

#: Mission files the fleet takes from a directory (sorted by name).
MISSION_SUFFIXES = (".plan", ".waypoints")
#: A ground station's port (QGroundControl's default); every vehicle also sends it telemetry.
DEFAULT_GCS_OUT = "127.0.0.1:14550"
#: How long the router may take to listen (wall s).
ROUTER_START_S = 30.0
#: How long an interrupted companion may take to bring its vehicle to a safe stop (wall s).
COMPANION_STOP_S = 45.0
#: How long a simulator or the router may take to stop on SIGTERM (wall s).
PROCESS_STOP_S = 10.0
#: How long a companion's planning workers may take to exit after it (wall s).
LEFTOVER_GRACE_S = 5.0
PR_SET_PDEATHSIG = 1
#: The start gate releases the vehicles after this fraction of a companion's pre-arm wait
#: (``StartupSettings.prearm_timeout_s``, vehicle s) even if not every companion waits yet.
HOLD_FRACTION = 0.5
#: MAV_SYS_STATUS_PREARM_CHECK (common.xml MAV_SYS_STATUS_SENSOR).
PREARM_CHECK_BIT = 0x10000000
#: The simulators' settings while the start is held: pre-arm checks failing.
HOLD_CONFIG = ("# written by companion fleet up: pre-arm checks fail until the start gate opens\n"
               "[flight]\nprearm_fail = 1\n")


# ------------------------------------------------------------------------------------ missions
def select_missions(mission_dir: str | Path, count: int) -> list[Path]:
    """The first ``count`` mission files (``*.plan``, ``*.waypoints``, sorted) of ``mission_dir``.

    Raises
    ------
    ConfigError
        ``count`` < 1, no such directory, or fewer files than ``count`` (naming the directory and
        how many it has).
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ConfigError(f"--vehicles: expected an integer >= 1, got {count!r}")
    directory = Path(mission_dir)
    if not directory.is_dir():
        raise ConfigError(f"--mission-dir: {directory} is not a directory")
    files = sorted(p for p in directory.iterdir() if p.is_file() and p.suffix.lower() in MISSION_SUFFIXES)
    if len(files) < count:
        raise ConfigError(f"--mission-dir: {directory} has {len(files)} mission file(s) (*.plan, *.waypoints), "
                          f"fewer than --vehicles {count}")
    return files[:count]


def mission_home(path: str | Path) -> tuple[float, float, float]:
    """The home (lat deg, lon deg, alt m AMSL) a mission file plans from: a ``.plan``'s
    ``mission.plannedHomePosition``, a ``QGC WPL 110`` file's item 0.

    Raises
    ------
    MissionError
        The file is invalid or gives no home (naming the file).
    """
    from companion.mission import load_mission_file

    plan = load_mission_file(path)
    if plan.planned_home is None:
        raise MissionError(f"{path}: the mission gives no home (plannedHomePosition, or item 0 of a "
                           f"QGC WPL file): the fleet starts each vehicle at its mission's home")
    return plan.planned_home


def first_leg_heading_deg(path: str | Path) -> float:
    """Bearing (degrees from north, 0-360) from a mission's home to its first waypoint away from
    home (more than 1 m horizontally); 0 when there is none. The fleet parks each vehicle
    facing it."""
    from companion.mission import load_mission_file, mission_to_local

    local = mission_to_local(load_mission_file(path), home_lla=mission_home(path))
    for w in local.waypoints:
        n, e = float(w.pos_ned_m[0]), float(w.pos_ned_m[1])
        if math.hypot(n, e) > 1.0:
            return math.degrees(math.atan2(e, n)) % 360.0
    return 0.0


def _mission_plan(home_lla, waypoints_ned_m, *, alt_m: float, speed_m_s: float):
    """A ``MissionPlan``: takeoff to ``alt_m`` above home, the speed, the waypoints (NED about
    home, flown at ``alt_m`` above home), RTL."""
    from companion.geo import LocalFrame
    from companion.mission.model import (MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_RETURN_TO_LAUNCH,
                                         MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT, MAV_FRAME_MISSION,
                                         MissionItem, MissionPlan)

    frame = LocalFrame(*home_lla)
    items = [MissionItem(MAV_CMD_NAV_TAKEOFF, alt_m=float(alt_m)),
             MissionItem(MAV_CMD_DO_CHANGE_SPEED, frame=MAV_FRAME_MISSION, param1=1.0, param2=float(speed_m_s),
                         param3=-1.0)]
    for n, e in waypoints_ned_m:
        lat, lon, _ = frame.to_lla(n, e, 0.0)
        items.append(MissionItem(MAV_CMD_NAV_WAYPOINT, param2=2.0, lat_deg=round(float(lat), 8),
                                 lon_deg=round(float(lon), 8), alt_m=float(alt_m)))
    items.append(MissionItem(MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=MAV_FRAME_MISSION))
    return MissionPlan(items=tuple(items), planned_home=tuple(float(v) for v in home_lla),
                       cruise_speed_m_s=float(speed_m_s), hover_speed_m_s=5.0)


def crossing_missions(count: int, *, centre_lla=(47.397742, 8.545594, 488.0), radius_m: float = 70.0,
                      beyond_m: float = 30.0, alt_m: float = 15.0, speed_m_s: float = 7.0,
                      first_bearing_deg: float = 0.0) -> list:
    """``count`` missions whose legs cross at one point at about the same time.

    Vehicle ``i``'s home is ``radius_m`` from ``centre_lla`` at bearing ``first_bearing_deg +
    360 i / count``; it takes off to ``alt_m`` above home, flies through the centre to
    ``beyond_m`` past it at ``speed_m_s`` and returns home (RTL: back through the centre). Every
    home is at the centre's altitude, so all fly at one altitude: they truly conflict.

    Returns
    -------
    list of companion.mission.MissionPlan
    """
    from companion.geo import LocalFrame

    if count < 1:
        raise ConfigError(f"count: expected >= 1, got {count}")
    centre = LocalFrame(*centre_lla)
    plans = []
    for i in range(count):
        bearing = math.radians(first_bearing_deg + 360.0 * i / count)
        u = np.array([math.cos(bearing), math.sin(bearing)])
        home_ne = radius_m * u
        lat, lon, _ = centre.to_lla(home_ne[0], home_ne[1], 0.0)
        home = (round(float(lat), 8), round(float(lon), 8), float(centre_lla[2]))
        far_ne = -beyond_m * u - home_ne                     # about the vehicle's home
        plans.append(_mission_plan(home, [far_ne], alt_m=alt_m, speed_m_s=speed_m_s))
    return plans


def head_on_missions(*, centre_lla=(47.397742, 8.545594, 488.0), half_length_m: float = 60.0,
                     alt_m: float = 15.0, speed_m_s: float = 7.0, bearing_deg: float = 90.0) -> list:
    """Two missions along one corridor, head-on: each flies from its home to the other's and back
    (RTL), at one altitude. Returns two ``MissionPlan``."""
    return crossing_missions(2, centre_lla=centre_lla, radius_m=half_length_m, beyond_m=half_length_m,
                             alt_m=alt_m, speed_m_s=speed_m_s, first_bearing_deg=bearing_deg)


def write_missions(plans, out_dir: str | Path, stem: str = "uav") -> list[Path]:
    """Write ``plans`` as ``out_dir/<stem><k>.plan`` (k from 1); returns the paths in order."""
    from companion.mission import write_plan_file

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, plan in enumerate(plans, start=1):
        path = out / f"{stem}{k}.plan"
        write_plan_file(plan, path)
        paths.append(path)
    return paths


def planned_length_m(path: str | Path) -> float:
    """Length (m, 3D) of a mission flown in straight lines from its home on the ground: the
    climb, the legs and, when it ends with RTL or LAND, the descent to the ground; what a flown
    track's length is compared with (its extra path)."""
    from companion.mission import load_mission_file, mission_to_local

    plan = load_mission_file(path)
    local = mission_to_local(plan, home_lla=mission_home(path))
    points = [np.zeros(3)] + [np.asarray(w.pos_ned_m, dtype=float) for w in local.waypoints]
    if local.end_action == "rtl":
        points.append(np.zeros(3))
    elif local.end_action == "land":
        points.insert(-1, np.array([points[-1][0], points[-1][1], points[-2][2]]))
    return float(sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:])))


# ------------------------------------------------------------------------------------ processes
def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A loopback port that is free now (UDP by default)."""
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def default_logs_dir() -> Path:
    """``out/fleet-<UTC timestamp>``."""
    return Path("out") / f"fleet-{datetime.datetime.now(datetime.timezone.utc).strftime('%Y%m%d-%H%M%S')}"


def _die_with_parent() -> None:        # preexec_fn: runs in the child before exec
    os.setpgid(0, 0)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):   # not Linux: the launcher's stop() still ends them
        pass


def _start_time(pid: int) -> int | None:
    """The process's start time in clock ticks since boot (identifies it beyond pid reuse)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return int(fh.read().rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return None


def _state(pid: int) -> str | None:
    """The process's state letter (``R``, ``S``, ``Z`` ...), None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def descendants(pid: int) -> list[int]:
    """Every descendant process of ``pid`` (``/proc/<pid>/task/*/children``; empty off Linux)."""
    out, todo = [], [pid]
    while todo:
        parent = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{parent}/task/{tid}/children", encoding="ascii") as fh:
                    kids = [int(v) for v in fh.read().split()]
            except OSError:
                continue
            out += kids
            todo += kids
    return out


@dataclass
class FleetVehicle:
    """One vehicle of the fleet: its mission, ports, files and processes."""

    instance: int
    mission: Path
    home_lla: tuple[float, float, float]
    heading_deg: float
    sim_port: int
    companion_port: int
    zenoh_listen: str
    sim_log: Path
    companion_log: Path
    tlog: Path
    record: Path
    sim: subprocess.Popen | None = None
    companion: subprocess.Popen | None = None
    worker_pids: dict = field(default_factory=dict)     # pid -> start time: the companion's children seen

    @property
    def sysid(self) -> int:
        return self.instance + 1

    def describe(self) -> dict:
        return {"instance": self.instance, "sysid": self.sysid, "mission": str(self.mission),
                "home_lla": list(self.home_lla), "heading_deg": self.heading_deg, "sim_port": self.sim_port,
                "companion_port": self.companion_port, "zenoh_listen": self.zenoh_listen,
                "pids": {"sim": self.sim.pid if self.sim else None,
                         "companion": self.companion.pid if self.companion else None},
                "files": {"sim_log": str(self.sim_log), "companion_log": str(self.companion_log),
                          "tlog": str(self.tlog), "record": str(self.record)}}


@dataclass(frozen=True)
class VehicleResult:
    """How one vehicle's companion ended: exit code and its JSON summary's outcome and legs."""

    sysid: int
    mission: str
    exit_code: int | None
    outcome: str
    legs_reached: int | None
    legs_planned: int | None
    summary: dict | None

    @property
    def completed(self) -> bool:
        return self.exit_code == 0 and self.outcome == "completed"

    def as_dict(self) -> dict:
        return {"sysid": self.sysid, "mission": self.mission, "exit_code": self.exit_code, "outcome": self.outcome,
                "legs_reached": self.legs_reached, "legs_planned": self.legs_planned, "completed": self.completed}


@dataclass(frozen=True)
class FleetResult:
    """The fleet's end: one ``VehicleResult`` per vehicle; ``completed`` iff every mission was."""

    vehicles: tuple[VehicleResult, ...]
    wall_s: float

    @property
    def completed(self) -> bool:
        return bool(self.vehicles) and all(v.completed for v in self.vehicles)

    def as_dict(self) -> dict:
        return {"completed": self.completed, "wall_s": round(self.wall_s, 1),
                "vehicles": [v.as_dict() for v in self.vehicles]}

    def table(self) -> str:
        """One line per vehicle, for people."""
        lines = [f"{'sysid':>5}  {'exit':>4}  {'legs':>5}  outcome"]
        for v in self.vehicles:
            legs = "-" if v.legs_planned is None else f"{v.legs_reached}/{v.legs_planned}"
            code = "-" if v.exit_code is None else str(v.exit_code)
            lines.append(f"{v.sysid:>5}  {code:>4}  {legs:>5}  {v.outcome}")
        lines.append(f"{'all missions completed' if self.completed else 'NOT all missions completed'} "
                     f"({self.wall_s:.0f} s)")
        return "\n".join(lines)


def last_json_line(path: Path) -> dict | None:
    """The last line of ``path`` that is a JSON object (``companion run``'s summary), or None."""
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return None
    for line in reversed(text.splitlines()):
        if line.startswith("{"):
            try:
                value = json.loads(line)
            except json.JSONDecodeError:
                return None
            return value if isinstance(value, dict) else None
    return None


class StartGate:
    """Holds the fleet's start until every companion waits to arm, then releases all at once
    (see the module docstring). A thread speaking MAVLink to each simulator's port as a ground
    station (system 255, component 190).

    Parameters
    ----------
    vehicles : sequence of (sysid, sim port, still_running: callable () -> bool)
    speedup : float
        Vehicle seconds per wall second (the hold's limit is in vehicle seconds).
    """

    GUIDED = 4
    ARMED_FLAG = 128

    def __init__(self, vehicles, speedup: float) -> None:
        from companion.link.startup import StartupSettings

        startup = StartupSettings()
        self.vehicles = list(vehicles)
        #: wall s a companion waits while its vehicle reports pre-arm checks failing ...
        self.prearm_hold_s = HOLD_FRACTION * startup.prearm_timeout_s / speedup
        #: ... and while its arming is refused by one that does not report them (0.3 s after
        #: each refusal, then the retry interval in vehicle s)
        self.retry_hold_s = HOLD_FRACTION * (startup.arm_attempts - 1) * (0.3 + startup.retry_interval_s / speedup)
        self.reports_prearm: dict[int, bool] = {}             # sysid -> SYS_STATUS has the pre-arm bit
        self.state: dict[int, tuple[int, bool]] = {}          # sysid -> (custom mode, armed)
        self.confirmed: set[int] = set()
        self.released_wall_s: float | None = None
        self.first_waiting_s: float | None = None
        self.waiting_at_release: list[int] = []
        self.held_s: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fleet-start-gate", daemon=True)

    def start(self) -> "StartGate":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)

    def waiting(self) -> list[int]:
        """System ids whose vehicle is in GUIDED and disarmed: its companion waits to arm."""
        return [sysid for sysid, (mode, armed) in self.state.items() if mode == self.GUIDED and not armed]

    @property
    def max_hold_s(self) -> float:
        """How long the gate may hold (wall s): the shorter budget unless every vehicle is known
        to report its pre-arm checks."""
        known = [self.reports_prearm.get(sysid) for sysid, _, _ in self.vehicles]
        return self.prearm_hold_s if known and all(known) else self.retry_hold_s

    def describe(self) -> dict:
        return {"released": self.released_wall_s is not None, "held_s": self.held_s,
                "waiting_at_release": self.waiting_at_release, "confirmed": sorted(self.confirmed),
                "max_hold_s": round(self.max_hold_s, 1), "vehicles_report_prearm": self.reports_prearm}

    def _run(self) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.05)
        mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        mav.robust_parsing = True
        ports = {sysid: port for sysid, port, _ in self.vehicles}
        last_beat = last_set = 0.0
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now - last_beat >= 1.0:           # a peer the simulators answer (heard in 10 s)
                    beat = mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                    for sysid, port in ports.items():
                        _send(sock, beat.pack(mav), port)
                        if sysid not in self.reports_prearm:      # SYS_STATUS on this link, 2 Hz
                            ask = mav.command_long_encode(sysid, 1, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                          mavlink2.MAVLINK_MSG_ID_SYS_STATUS, 500000, 0, 0, 0, 0, 0)
                            _send(sock, ask.pack(mav), port)
                    last_beat = now
                self._read(sock, mav)
                live = [sysid for sysid, _, running in self.vehicles if running()]
                if self.released_wall_s is None:
                    waiting = self.waiting()
                    if waiting and self.first_waiting_s is None:
                        self.first_waiting_s = now
                    everyone = bool(live) and all(sysid in waiting for sysid in live)
                    too_long = self.first_waiting_s is not None and now - self.first_waiting_s > self.max_hold_s
                    if everyone or too_long:
                        self.released_wall_s = now
                        self.held_s = round(now - self.first_waiting_s, 2)
                        self.waiting_at_release = sorted(waiting)
                        log.info("start gate: releasing %s after %.1f s (waiting: %s)", sorted(ports),
                                 self.held_s, sorted(waiting))
                if self.released_wall_s is not None:
                    pending = [s for s in ports if s not in self.confirmed]
                    if not pending or now - self.released_wall_s > 10.0:
                        if pending:
                            log.warning("start gate: no PARAM_VALUE SIM_PREARM_FAIL = 0 from %s", pending)
                        return
                    if now - last_set >= 0.3:
                        for sysid in pending:
                            msg = mav.param_set_encode(sysid, 1, b"SIM_PREARM_FAIL", 0.0,
                                                       mavlink2.MAV_PARAM_TYPE_INT8)
                            _send(sock, msg.pack(mav), ports[sysid])
                        last_set = now
                if not live:
                    return
        finally:
            sock.close()

    def _read(self, sock, mav) -> None:
        try:
            data, _ = sock.recvfrom(65535)
        except (socket.timeout, OSError):
            return
        for msg in mav.parse_buffer(data) or []:
            kind = msg.get_type()
            if msg.get_srcComponent() != 1:
                continue
            if kind == "HEARTBEAT":
                self.state[msg.get_srcSystem()] = (msg.custom_mode, bool(msg.base_mode & self.ARMED_FLAG))
            elif kind == "SYS_STATUS":
                self.reports_prearm[msg.get_srcSystem()] = bool(msg.onboard_control_sensors_present
                                                                & PREARM_CHECK_BIT)
            elif kind == "PARAM_VALUE" and self.released_wall_s is not None:
                name = msg.param_id.decode() if isinstance(msg.param_id, bytes) else msg.param_id
                if name.rstrip("\x00") == "SIM_PREARM_FAIL" and msg.param_value == 0.0:
                    self.confirmed.add(msg.get_srcSystem())


def _send(sock, data: bytes, port: int) -> None:
    try:
        sock.sendto(data, ("127.0.0.1", port))
    except OSError:
        pass


class Fleet:
    """A zenoh router, N ``sim-vehicle`` and N ``companion run`` (see the module docstring).

    Parameters
    ----------
    missions : sequence of path
        One mission file per vehicle (vehicle ``i`` flies ``missions[i]`` from its home).
    logs_dir : path
        Where the logs, tlogs, records and ``fleet.json`` go (created).
    speedup : float
        The simulators' ``--speedup`` and the companions' ``--time-scale``.
    share : bool
        False: ``companion run --no-fleet`` (the baseline without trajectory sharing).
    trajectory_delay_ms : float, optional
        ``companion run --fleet-delay-ms``.
    seed : int, optional
        Vehicle ``i``: ``sim-vehicle --seed seed + i``, ``companion run --seed seed + i``.
    gcs_out : str or None
        Another ``--out`` of every simulator (a ground station; default UDP 14550).
    env : dict, optional
        The children's environment (default: this process's).
    companion_args, sim_args : sequence of str
        More arguments of every ``companion run`` / ``sim-vehicle`` (with ``sync_start`` the
        simulators' ``--config`` is the launcher's).
    sync_start : bool
        Hold every vehicle's start until every companion is ready (``StartGate``).
    face_first_leg : bool
        Park each vehicle facing its first waypoint (``sim-vehicle --home ...,YAW``), so that
        none spends longer than the others turning before its first leg (a helicopter turns to
        its direction of travel at its yaw rate); else every vehicle faces north.
    """

    def __init__(self, missions, logs_dir, *, speedup: float = 1.0, share: bool = True,
                 trajectory_delay_ms: float | None = None, seed: int | None = None,
                 gcs_out: str | None = DEFAULT_GCS_OUT, env: dict | None = None,
                 companion_args=(), sim_args=(), sync_start: bool = True, face_first_leg: bool = True) -> None:
        if not (isinstance(speedup, (int, float)) and math.isfinite(speedup) and speedup > 0):
            raise ConfigError(f"--speedup: expected a number > 0, got {speedup!r}")
        if trajectory_delay_ms is not None and not (math.isfinite(trajectory_delay_ms) and trajectory_delay_ms >= 0):
            raise ConfigError(f"--trajectory-delay-ms: expected a number >= 0, got {trajectory_delay_ms!r}")
        missions = [Path(m) for m in missions]
        if not missions:
            raise ConfigError("--vehicles: expected at least one mission")
        self.logs_dir = Path(logs_dir)
        self.speedup = float(speedup)
        self.share = bool(share)
        self.trajectory_delay_ms = trajectory_delay_ms
        self.seed = seed
        self.gcs_out = gcs_out
        self.env = env
        self.companion_args = tuple(companion_args)
        self.sim_args = tuple(sim_args)
        self.sync_start = bool(sync_start)
        self.gate: StartGate | None = None
        self.face_first_leg = bool(face_first_leg)
        self.router: subprocess.Popen | None = None
        self.router_endpoint = ""
        self.vehicles = [self._vehicle(i, m) for i, m in enumerate(missions)]
        self._started_s: float | None = None
        self._result: FleetResult | None = None
        self._stopped = False

    def _vehicle(self, i: int, mission: Path) -> FleetVehicle:
        d = self.logs_dir
        heading = first_leg_heading_deg(mission) if self.face_first_leg else 0.0
        return FleetVehicle(instance=i, mission=mission.resolve(), home_lla=mission_home(mission),
                            heading_deg=round(heading, 1),
                            sim_port=0, companion_port=0, zenoh_listen="",
                            sim_log=d / f"sim{i}.log", companion_log=d / f"uav{i + 1}.log",
                            tlog=d / f"sim{i}.tlog", record=d / f"uav{i + 1}.jsonl")

    # -------------------------------------------------------------------------- paths
    @property
    def paths(self) -> dict:
        """Where things are: ``logs``, ``fleet_json``, ``router_log`` and per vehicle (by
        sysid) its ``tlog``, ``record``, ``sim_log``, ``companion_log``."""
        return {"logs": self.logs_dir, "fleet_json": self.logs_dir / "fleet.json",
                "router_log": self.logs_dir / "router.log",
                "vehicles": {v.sysid: {"tlog": v.tlog, "record": v.record, "sim_log": v.sim_log,
                                       "companion_log": v.companion_log} for v in self.vehicles}}

    def describe(self) -> dict:
        """What ``fleet.json`` holds."""
        return {"router": self.router_endpoint, "router_pid": self.router.pid if self.router else None,
                "speedup": self.speedup, "share": self.share, "trajectory_delay_ms": self.trajectory_delay_ms,
                "seed": self.seed, "launcher_pid": os.getpid(), "sync_start": self.sync_start,
                "start_gate": self.gate.describe() if self.gate is not None else None,
                "vehicles": [v.describe() for v in self.vehicles]}

    # -------------------------------------------------------------------------- start
    def _spawn(self, module_args: list[str], log_path: Path) -> subprocess.Popen:
        with open(log_path, "wb") as fh:
            return subprocess.Popen([sys.executable, "-m", *module_args], stdout=fh, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, env=self.env, preexec_fn=_die_with_parent)

    def sim_command(self, v: FleetVehicle) -> list[str]:
        home = (",".join(f"{x:.8f}".rstrip("0").rstrip(".") for x in v.home_lla[:2])
                + f",{v.home_lla[2]:g},{v.heading_deg:g}")
        args = ["sim_vehicle.cli", "--instance", str(v.instance), "--home", home, "--port", str(v.sim_port),
                "--out", f"127.0.0.1:{v.companion_port}"]
        if self.gcs_out:
            args += ["--out", self.gcs_out]
        args += ["--speedup", f"{self.speedup:g}", "--tlog", str(v.tlog)]
        if self.seed is not None:
            args += ["--seed", str(self.seed + v.instance)]
        if self.sync_start:
            args += ["--config", str(self.hold_config)]
        return args + list(self.sim_args)

    @property
    def hold_config(self) -> Path:
        """The simulators' settings while the start is held (``sync_start``)."""
        return self.logs_dir / "sim_hold_start.toml"

    def companion_command(self, v: FleetVehicle) -> list[str]:
        args = ["companion.cli", "run", "--instance", str(v.instance),
                "--connect", f"udpin://127.0.0.1:{v.companion_port}", "--mission", str(v.mission),
                "--zenoh-connect", self.router_endpoint, "--zenoh-listen", v.zenoh_listen,
                "--record", str(v.record), "--time-scale", f"{self.speedup:g}"]
        if not self.share:
            args.append("--no-fleet")
        if self.trajectory_delay_ms is not None:
            args += ["--fleet-delay-ms", f"{self.trajectory_delay_ms:g}"]
        if self.seed is not None:
            args += ["--seed", str(self.seed + v.instance)]
        return args + list(self.companion_args)

    def start(self) -> "Fleet":
        """Start the router (and wait until it listens), then every simulator and companion;
        write ``fleet.json``. On a failure everything started is stopped."""
        if self._started_s is not None:
            raise ConfigError("this fleet was started already")
        self.logs_dir.mkdir(parents=True, exist_ok=True)
        self._started_s = time.monotonic()
        try:
            self._start_router()
            if self.sync_start:
                self.hold_config.write_text(HOLD_CONFIG)
            for v in self.vehicles:
                v.sim_port, v.companion_port = free_port(), free_port()
                v.zenoh_listen = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
                v.sim = self._spawn(self.sim_command(v), v.sim_log)
                v.companion = self._spawn(self.companion_command(v), v.companion_log)
                log.info("vehicle %d: sim-vehicle pid %d, companion pid %d, mission %s", v.sysid, v.sim.pid,
                         v.companion.pid, v.mission.name)
            if self.sync_start:
                self.gate = StartGate([(v.sysid, v.sim_port, _running(v)) for v in self.vehicles],
                                      self.speedup).start()
            self.write_description()
        except BaseException:
            self.stop()
            raise
        return self

    def _start_router(self) -> None:
        self.router_endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
        router_log = self.logs_dir / "router.log"
        self.router = self._spawn(["companion.cli", "router", "--listen", self.router_endpoint], router_log)
        deadline = time.monotonic() + ROUTER_START_S
        while "zenoh router listening" not in router_log.read_text(errors="replace"):
            if self.router.poll() is not None:
                raise ConfigError(f"the zenoh router on {self.router_endpoint} exited with status "
                                  f"{self.router.returncode}; see {router_log}")
            if time.monotonic() > deadline:
                raise ConfigError(f"the zenoh router on {self.router_endpoint} did not listen within "
                                  f"{ROUTER_START_S:.0f} s; see {router_log}")
            time.sleep(0.1)
        log.info("zenoh router pid %d listening on %s", self.router.pid, self.router_endpoint)

    def write_description(self) -> Path:
        path = self.logs_dir / "fleet.json"
        path.write_text(json.dumps(self.describe(), indent=2) + "\n")
        return path

    # -------------------------------------------------------------------------- run
    def running(self) -> list[int]:
        """System ids of the vehicles whose companion still runs."""
        return [v.sysid for v in self.vehicles if v.companion is not None and v.companion.poll() is None]

    def poll(self) -> FleetResult | None:
        """The result once every companion has exited, else None (and note their workers)."""
        for v in self.vehicles:
            self._note_workers(v)
        if self.running():
            return None
        return self.result()

    def _note_workers(self, v: FleetVehicle) -> None:
        if v.companion is None or v.companion.poll() is not None:
            return
        for pid in descendants(v.companion.pid):
            if pid not in v.worker_pids:
                start = _start_time(pid)
                if start is not None:
                    v.worker_pids[pid] = start

    def wait(self, timeout_s: float | None = None, *, stop_event=None) -> FleetResult:
        """Wait until every companion has exited; the result.

        Raises
        ------
        TimeoutError
            Still running after ``timeout_s`` wall seconds (or ``stop_event`` set): nothing is
            stopped; call ``stop()``.
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            result = self.poll()
            if result is not None:
                return result
            if stop_event is not None and stop_event.is_set():
                raise TimeoutError("interrupted")
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"companions of vehicles {self.running()} still running after {timeout_s} s")
            time.sleep(0.2)

    def result(self) -> FleetResult:
        """Every vehicle's end as known now (exit code None: still running)."""
        out = []
        for v in self.vehicles:
            code = v.companion.poll() if v.companion is not None else None
            summary = last_json_line(v.companion_log) if code is not None else None
            outcome = (summary or {}).get("outcome") or ("running" if code is None and v.companion else
                                                         "not started" if v.companion is None else
                                                         f"exited {code} without a summary")
            out.append(VehicleResult(v.sysid, v.mission.name, code, str(outcome),
                                     (summary or {}).get("legs_reached"), (summary or {}).get("legs_planned"),
                                     summary))
        wall = 0.0 if self._started_s is None else time.monotonic() - self._started_s
        return FleetResult(tuple(out), wall)

    # -------------------------------------------------------------------------- stop
    def stop(self) -> FleetResult:
        """Interrupt the companions still running (SIGINT; SIGKILL after ``COMPANION_STOP_S``),
        then stop the simulators and the router (SIGTERM, then SIGKILL) and any planning worker
        left behind. Idempotent; returns the result."""
        if self._stopped:
            return self._result or self.result()
        if self.gate is not None:
            self.gate.stop()
        for v in self.vehicles:
            self._note_workers(v)
        live = [v for v in self.vehicles if v.companion is not None and v.companion.poll() is None]
        for v in live:
            log.warning("interrupting the companion of vehicle %d (pid %d)", v.sysid, v.companion.pid)
            _signal(v.companion, signal.SIGINT)
        deadline = time.monotonic() + COMPANION_STOP_S
        for v in live:
            _wait_or_kill(v.companion, max(deadline - time.monotonic(), 0.1))
        self._result = self.result()
        procs = [v.sim for v in self.vehicles if v.sim is not None] + ([self.router] if self.router else [])
        for proc in procs:
            if proc.poll() is None:
                _signal(proc, signal.SIGTERM)
        deadline = time.monotonic() + PROCESS_STOP_S
        for proc in procs:
            _wait_or_kill(proc, max(deadline - time.monotonic(), 0.1))
        self._end_leftovers()
        self._stopped = True
        if self._started_s is not None and self.logs_dir.is_dir():
            self.write_description()            # with the start gate's account
        return self._result

    def _end_leftovers(self) -> None:
        """The companions' children still alive (workers exit on their own once their companion
        has: given ``LEFTOVER_GRACE_S``), SIGKILLed."""
        def alive() -> list[tuple[int, int]]:
            return [(v.sysid, pid) for v in self.vehicles for pid, start in v.worker_pids.items()
                    if _start_time(pid) == start and _state(pid) not in ("Z", "X", None)]

        deadline = time.monotonic() + LEFTOVER_GRACE_S
        while alive() and time.monotonic() < deadline:
            time.sleep(0.1)
        for sysid, pid in alive():
            log.warning("killing a process left behind by the companion of vehicle %d: pid %d", sysid, pid)
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass

    def __enter__(self) -> "Fleet":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _running(v: FleetVehicle):
    return lambda: v.companion is not None and v.companion.poll() is None


def _signal(proc: subprocess.Popen, sig: int) -> None:
    try:
        proc.send_signal(sig)
    except OSError:
        pass


def _wait_or_kill(proc: subprocess.Popen, timeout_s: float) -> None:
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        log.warning("pid %d did not stop within %.0f s: SIGKILL", proc.pid, timeout_s)
        proc.kill()
        proc.wait()
