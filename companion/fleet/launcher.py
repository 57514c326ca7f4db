"""``companion fleet up``: N simulated helicopters and their companions through one zenoh router.

The fleet is real processes, as an operator would start them by hand (DESIGN 6: several
vehicles meet through a zenoh router and share their committed trajectories):

- one ``companion router --listen tcp/127.0.0.1:<free>``;
- for vehicle ``i`` (system id ``i + 1``) flying the ``i``-th mission file of a directory:
  ``sim-vehicle --instance i --home <the file's home>,<heading to its first waypoint> --port <free>
  --out 127.0.0.1:<companion port> --out <GCS> --speedup X --tlog LOGS/sim<i>.tlog`` and ``companion run --instance i
  --connect udpin://127.0.0.1:<companion port> --mission FILE --zenoh-connect <router>
  --zenoh-listen tcp/127.0.0.1:<free> --record LOGS/uav<i+1>.jsonl --time-scale X`` (with
  ``--no-fleet`` for the baseline without sharing, ``$HELI_COMPANION_TEST_FLEET_DELAY_MS`` to delay the shared
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
the launcher dies (``PR_SET_PDEATHSIG``): ``companion.sitl.processes`` starts and stops them.

Synchronised start (``sync_start``, the default): every vehicle's pre-arm checks are held failing
until every companion waits to arm, then cleared on all at once (``companion.fleet.start_gate``),
so that vehicles meant to meet at a crossing do. Each vehicle is parked facing its first
waypoint (``face_first_leg``). The missions (choosing them, their homes, the crossing missions of
``mission_files/fleet/``) are ``companion.fleet.missions``; the children's command lines
``companion.sitl.vehicles``; how the flight ended ``companion.fleet.results``.
"""

from __future__ import annotations

import datetime
import json
import logging
import math
import os
import signal
import socket
import time
from dataclasses import dataclass
from pathlib import Path

from companion.errors import ConfigError
from companion.fleet.missions import first_leg_heading_deg, mission_home
from companion.fleet.results import FleetResult, VehicleResult, last_json_line
from companion.fleet.settings import FLEET_DELAY_ENV
from companion.fleet.start_gate import HOLD_CONFIG, StartGate
from companion.sitl.processes import Escalation, ManagedProcess, ProcessGroup, python_command, spawn
from companion.sitl.vehicles import companion_run_args, home_arg, sim_vehicle_args
from heli_common.ports import free_port

__all__ = ["Fleet", "FleetVehicle", "default_logs_dir", "DEFAULT_GCS_OUT"]

log = logging.getLogger(__name__)

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
#: Interrupted companions: SIGINT, then SIGTERM and SIGKILL if one does not stop in time.
COMPANION_ESCALATION = Escalation(
    ((signal.SIGINT, COMPANION_STOP_S), (signal.SIGTERM, 5.0)), leftover_grace_s=LEFTOVER_GRACE_S
)
#: The simulators and the router: SIGTERM, then SIGKILL.
PROCESS_ESCALATION = Escalation(((signal.SIGTERM, PROCESS_STOP_S),), leftover_grace_s=LEFTOVER_GRACE_S)


def default_logs_dir() -> Path:
    """``out/fleet-<UTC timestamp>``."""
    return Path("out") / f"fleet-{datetime.datetime.now(datetime.UTC).strftime('%Y%m%d-%H%M%S')}"


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
    sim: ManagedProcess | None = None
    companion: ManagedProcess | None = None

    @property
    def sysid(self) -> int:
        return self.instance + 1

    def describe(self) -> dict:
        return {
            "instance": self.instance,
            "sysid": self.sysid,
            "mission": str(self.mission),
            "home_lla": list(self.home_lla),
            "heading_deg": self.heading_deg,
            "sim_port": self.sim_port,
            "companion_port": self.companion_port,
            "zenoh_listen": self.zenoh_listen,
            "pids": {
                "sim": self.sim.pid if self.sim else None,
                "companion": self.companion.pid if self.companion else None,
            },
            "files": {
                "sim_log": str(self.sim_log),
                "companion_log": str(self.companion_log),
                "tlog": str(self.tlog),
                "record": str(self.record),
            },
        }


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
        ``$HELI_COMPANION_TEST_FLEET_DELAY_MS`` of the companions, not a ``companion run`` option.
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

    def __init__(
        self,
        missions,
        logs_dir,
        *,
        speedup: float = 1.0,
        share: bool = True,
        trajectory_delay_ms: float | None = None,
        seed: int | None = None,
        gcs_out: str | None = DEFAULT_GCS_OUT,
        env: dict | None = None,
        companion_args=(),
        sim_args=(),
        sync_start: bool = True,
        face_first_leg: bool = True,
    ) -> None:
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
        self.router: ManagedProcess | None = None
        self.router_endpoint = ""
        self.companions = ProcessGroup(COMPANION_ESCALATION)
        self.others = ProcessGroup(PROCESS_ESCALATION)  # the simulators and the router
        self.vehicles = [self._vehicle(i, m) for i, m in enumerate(missions)]
        self._started_s: float | None = None
        self._result: FleetResult | None = None
        self._stopped = False

    def _vehicle(self, i: int, mission: Path) -> FleetVehicle:
        d = self.logs_dir
        heading = first_leg_heading_deg(mission) if self.face_first_leg else 0.0
        return FleetVehicle(
            instance=i,
            mission=mission.resolve(),
            home_lla=mission_home(mission),
            heading_deg=round(heading, 1),
            sim_port=0,
            companion_port=0,
            zenoh_listen="",
            sim_log=d / f"sim{i}.log",
            companion_log=d / f"uav{i + 1}.log",
            tlog=d / f"sim{i}.tlog",
            record=d / f"uav{i + 1}.jsonl",
        )

    # -------------------------------------------------------------------------- paths
    @property
    def paths(self) -> dict:
        """Where things are: ``logs``, ``fleet_json``, ``router_log`` and per vehicle (by
        sysid) its ``tlog``, ``record``, ``sim_log``, ``companion_log``."""
        return {
            "logs": self.logs_dir,
            "fleet_json": self.logs_dir / "fleet.json",
            "router_log": self.logs_dir / "router.log",
            "vehicles": {
                v.sysid: {"tlog": v.tlog, "record": v.record, "sim_log": v.sim_log, "companion_log": v.companion_log}
                for v in self.vehicles
            },
        }

    def describe(self) -> dict:
        """What ``fleet.json`` holds."""
        return {
            "router": self.router_endpoint,
            "router_pid": self.router.pid if self.router else None,
            "speedup": self.speedup,
            "share": self.share,
            "trajectory_delay_ms": self.trajectory_delay_ms,
            "seed": self.seed,
            "launcher_pid": os.getpid(),
            "sync_start": self.sync_start,
            "start_gate": self.gate.describe() if self.gate is not None else None,
            "vehicles": [v.describe() for v in self.vehicles],
        }

    # -------------------------------------------------------------------------- start
    def _spawn(self, module_args: list[str], log_path: Path, env=None) -> ManagedProcess:
        """``python -m <module_args>`` in the children's environment (or ``env``), ending with the launcher."""
        return spawn(python_command(module_args), log_path, env=self.env if env is None else env)

    def companion_env(self) -> dict | None:
        """The companions' environment: the children's, with the injected trajectory delay
        (``companion.fleet.settings.FLEET_DELAY_ENV``) when ``trajectory_delay_ms`` is set."""
        if self.trajectory_delay_ms is None:
            return self.env
        return {**(os.environ if self.env is None else self.env), FLEET_DELAY_ENV: f"{self.trajectory_delay_ms:g}"}

    def sim_command(self, v: FleetVehicle) -> list[str]:
        outs = [f"127.0.0.1:{v.companion_port}"] + ([self.gcs_out] if self.gcs_out else [])
        return sim_vehicle_args(
            v.sim_port,
            outs=outs,
            speedup=self.speedup,
            instance=v.instance,
            home=home_arg(v.home_lla, v.heading_deg),
            tlog=v.tlog,
            seed=None if self.seed is None else self.seed + v.instance,
            config=self.hold_config if self.sync_start else None,
            extra=self.sim_args,
        )

    @property
    def hold_config(self) -> Path:
        """The simulators' settings while the start is held (``sync_start``)."""
        return self.logs_dir / "sim_hold_start.toml"

    def companion_command(self, v: FleetVehicle) -> list[str]:
        fleet_args = [] if self.share else ["--no-fleet"]
        return companion_run_args(
            f"udpin://127.0.0.1:{v.companion_port}",
            instance=v.instance,
            mission=v.mission,
            zenoh_connect=self.router_endpoint,
            zenoh_listen=v.zenoh_listen,
            record=v.record,
            time_scale=self.speedup,
            seed=None if self.seed is None else self.seed + v.instance,
            extra=[*fleet_args, *self.companion_args],
        )

    def start(self) -> Fleet:
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
                v.sim = self.others.add(self._spawn(self.sim_command(v), v.sim_log))
                v.companion = self.companions.add(
                    self._spawn(self.companion_command(v), v.companion_log, env=self.companion_env())
                )
                log.info(
                    "vehicle %d: sim-vehicle pid %d, companion pid %d, mission %s",
                    v.sysid,
                    v.sim.pid,
                    v.companion.pid,
                    v.mission.name,
                )
            if self.sync_start:
                self.gate = StartGate([(v.sysid, v.sim_port, _running(v)) for v in self.vehicles], self.speedup).start()
            self.write_description()
        except BaseException:
            self.stop()
            raise
        return self

    def _start_router(self) -> None:
        self.router_endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
        router_log = self.logs_dir / "router.log"
        self.router = self.others.add(
            self._spawn(["companion.cli", "router", "--listen", self.router_endpoint], router_log)
        )
        self.router.name = f"the zenoh router on {self.router_endpoint}"
        self.router.wait_ready(
            self.router.log_contains("zenoh router listening"), ROUTER_START_S, "'zenoh router listening'"
        )
        log.info("zenoh router pid %d listening on %s", self.router.pid, self.router_endpoint)

    def write_description(self) -> Path:
        path = self.logs_dir / "fleet.json"
        path.write_text(json.dumps(self.describe(), indent=2) + "\n")
        return path

    # -------------------------------------------------------------------------- run
    def running(self) -> list[int]:
        """System ids of the vehicles whose companion still runs."""
        return [v.sysid for v in self.vehicles if v.companion is not None and v.companion.is_running()]

    def poll(self) -> FleetResult | None:
        """The result once every companion has exited, else None (and note their workers)."""
        self.companions.note_descendants()
        if self.running():
            return None
        return self.result()

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
            outcome = (summary or {}).get("outcome") or (
                "running"
                if code is None and v.companion
                else "not started"
                if v.companion is None
                else f"exited {code} without a summary"
            )
            out.append(
                VehicleResult(
                    v.sysid,
                    v.mission.name,
                    code,
                    str(outcome),
                    (summary or {}).get("legs_reached"),
                    (summary or {}).get("legs_planned"),
                    summary,
                )
            )
        wall = 0.0 if self._started_s is None else time.monotonic() - self._started_s
        return FleetResult(tuple(out), wall)

    # -------------------------------------------------------------------------- stop
    def stop(self) -> FleetResult:
        """Interrupt the companions still running (``COMPANION_ESCALATION``: SIGINT, then
        SIGTERM and SIGKILL if one is still running after ``COMPANION_STOP_S``), then stop the
        simulators and the router (``PROCESS_ESCALATION``: SIGTERM, then SIGKILL); any planning
        worker left behind is killed after ``LEFTOVER_GRACE_S``. Idempotent; returns the result."""
        if self._stopped:
            return self._result or self.result()
        if self.gate is not None:
            self.gate.stop()
        for v in self.vehicles:
            if v.companion is not None and v.companion.is_running():
                log.warning("interrupting the companion of vehicle %d (pid %d)", v.sysid, v.companion.pid)
        self.companions.stop()
        self._result = self.result()
        self.others.stop()
        self._stopped = True
        if self._started_s is not None and self.logs_dir.is_dir():
            self.write_description()  # with the start gate's account
        return self._result

    def __enter__(self) -> Fleet:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _running(v: FleetVehicle):
    return lambda: v.companion is not None and v.companion.is_running()
