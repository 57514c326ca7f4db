"""The command lines of a simulated helicopter (``sim-vehicle``) and its companion
(``companion run``), and the two started together on free loopback ports (``flight_processes``).

The command lines are module arguments (``python_command`` makes them ``python -m ...`` of this
interpreter): ``sim-vehicle`` is started as a process, never imported. ``companion demo``, the
fleet launcher, the integration tests and the SITL benchmarks build them here.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from companion.sitl.processes import ManagedProcess, python_command
from heli_common.ports import free_port

__all__ = [
    "FlightProcesses",
    "SIM_VEHICLE_MODULE",
    "COMPANION_MODULE",
    "companion_run_args",
    "flight_processes",
    "home_arg",
    "sim_vehicle_args",
]

SIM_VEHICLE_MODULE = "sim_vehicle.cli"
COMPANION_MODULE = "companion.cli"


def home_arg(home_lla: Sequence[float], heading_deg: float) -> str:
    """``sim-vehicle --home``'s ``LAT,LON,ALT,YAW`` (degrees to 8 places, no trailing zeros)."""
    lat_lon = ",".join(f"{x:.8f}".rstrip("0").rstrip(".") for x in home_lla[:2])
    return f"{lat_lon},{home_lla[2]:g},{heading_deg:g}"


def sim_vehicle_args(
    port: int,
    *,
    outs: Sequence[str] = (),
    speedup: float = 1.0,
    instance: int | None = None,
    home: str | None = None,
    tlog=None,
    seed: int | None = None,
    config=None,
    default_outs: bool = True,
    extra: Sequence[str] = (),
) -> list[str]:
    """``sim_vehicle.cli`` and its arguments.

    Parameters
    ----------
    port : int
        The UDP port it binds (``--port``).
    outs : sequence of str
        ``HOST:PORT`` telemetry destinations (``--out`` each).
    speedup : float
        ``--speedup``.
    instance, home, tlog, seed, config : optional
        ``--instance``, ``--home`` (``home_arg``), ``--tlog``, ``--seed``, ``--config``.
    default_outs : bool
        False: ``--no-default-out`` when ``outs`` is empty (no telemetry to 14550 / 14540).
    extra : sequence of str
        More arguments, last.
    """
    args = [SIM_VEHICLE_MODULE]
    if instance is not None:
        args += ["--instance", str(instance)]
    if home is not None:
        args += ["--home", home]
    args += ["--port", str(port)]
    for address in outs:
        args += ["--out", address]
    if not outs and not default_outs:
        args.append("--no-default-out")
    args += ["--speedup", f"{speedup:g}"]
    for option, value in (("--tlog", tlog), ("--seed", seed), ("--config", config)):
        if value is not None:
            args += [option, str(value)]
    return args + list(extra)


def companion_run_args(
    connect: str,
    *,
    mission=None,
    instance: int | None = None,
    zenoh_connect: str | None = None,
    zenoh_listen: str | None = None,
    record=None,
    time_scale: float | None = None,
    seed: int | None = None,
    extra: Sequence[str] = (),
) -> list[str]:
    """``companion.cli run`` and its arguments: ``--connect`` (e.g. ``udpin://127.0.0.1:PORT``),
    then ``--instance``, ``--mission``, ``--zenoh-connect``, ``--zenoh-listen``, ``--record``,
    ``--time-scale``, ``--seed`` when given, then ``extra``."""
    args = [COMPANION_MODULE, "run"]
    if instance is not None:
        args += ["--instance", str(instance)]
    args += ["--connect", connect]
    for option, value in (
        ("--mission", mission),
        ("--zenoh-connect", zenoh_connect),
        ("--zenoh-listen", zenoh_listen),
        ("--record", record),
    ):
        if value is not None:
            args += [option, str(value)]
    if time_scale is not None:
        args += ["--time-scale", f"{time_scale:g}"]
    if seed is not None:
        args += ["--seed", str(seed)]
    return args + list(extra)


@dataclass
class FlightProcesses:
    """A ``sim-vehicle`` and a ``companion run`` flying together (see ``flight_processes``)."""

    sim: ManagedProcess
    companion: ManagedProcess
    vehicle_port: int  # the vehicle's UDP port (another ground station can talk to it)
    endpoint: str  # the companion's zenoh listen endpoint
    record: Path  # its flight record
    log: Path  # its log (stdout and stderr; the last line is the JSON summary)


@contextlib.contextmanager
def flight_processes(
    out_dir: Path,
    mission: Path,
    *,
    speedup: float = 4.0,
    gcs_out: str | None = None,
    extra_args: Sequence[str] = (),
    sim_args: Sequence[str] = (),
    env: Mapping[str, str] | None = None,
    record_name: str = "flight.jsonl",
    companion_prefix: Sequence[str] = (),
) -> Iterator[FlightProcesses]:
    """Start ``sim-vehicle`` and ``companion run --mission`` on free loopback ports.

    Parameters
    ----------
    out_dir : path
        Where the logs (``sim_vehicle.log``, ``companion.log``) and the record go (created).
    mission : path
    speedup : float
        The vehicle's ``--speedup`` (the companion takes its time scale from the vehicle).
    gcs_out : str, optional
        Another ``--out`` of the vehicle (a ground station, a track listener).
    extra_args, sim_args : sequence of str
        More arguments of ``companion run`` / ``sim-vehicle`` (e.g. wind).
    env : mapping, optional
        The processes' environment (default: this one's).
    record_name : str
        The record is ``out_dir/record_name`` (``.mcap``: MCAP).
    companion_prefix : sequence of str
        Module arguments that run the companion's module (``["cProfile", "-o", FILE, "-m"]``).

    Yields
    ------
    FlightProcesses
        On exit the companion is stopped, then the vehicle (SIGINT, SIGTERM, SIGKILL).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    mav_port, vehicle_port, zenoh_port = free_port(), free_port(), free_port(socket.SOCK_STREAM)
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    outs = [f"127.0.0.1:{mav_port}"] + ([gcs_out] if gcs_out else [])
    sim = ManagedProcess(
        python_command(sim_vehicle_args(vehicle_port, outs=outs, speedup=speedup, extra=sim_args)),
        out_dir / "sim_vehicle.log",
        name="sim-vehicle",
        env=env,
    )
    record, log_path = out_dir / record_name, out_dir / "companion.log"
    companion = ManagedProcess(
        python_command(
            [
                *companion_prefix,
                *companion_run_args(
                    f"udpin://127.0.0.1:{mav_port}",
                    mission=mission,
                    zenoh_listen=endpoint,
                    record=record,
                    extra=extra_args,
                ),
            ]
        ),
        log_path,
        name="companion",
        env=env,
    )
    with sim, companion:  # leaves in reverse: the companion stops first
        yield FlightProcesses(sim, companion, vehicle_port, endpoint, record, log_path)
