"""``companion fleet``: fly several simulated helicopters through one zenoh router, and watch them.

``fleet up`` starts a router, N ``sim-vehicle`` and N ``companion run`` (``companion.fleet.launcher``)
and waits for every mission; ``fleet status`` listens to the companions' status and events
through the router and prints one row per vehicle (``companion.fleet.status_view``).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

from companion.errors import ConfigError
from heli_common.cli_args import add_shared_options

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  companion fleet up --vehicles 3 --mission-dir mission_files/fleet/crossing3 --speedup 2
  companion fleet up --vehicles 2 --mission-dir mission_files/fleet/headon2 --no-share --logs out/headon
  companion fleet status --logs out/headon          # while it flies (another terminal)
  companion fleet status --router tcp/127.0.0.1:7447 --seconds 5 --json"""

UP_EPILOG = """\
examples:
  companion fleet up --vehicles 3 --mission-dir mission_files/fleet/crossing3 --speedup 2
  companion fleet up --vehicles 2 --mission-dir mission_files/fleet/headon2 --no-share   # baseline
  companion fleet up --vehicles 3 --mission-dir mission_files/fleet/crossing3 --trajectory-delay-ms 150

Vehicle i (system id i+1) flies the i-th mission file of DIR (*.plan, *.waypoints, sorted by
name) from that file's home. The vehicles start together: their pre-arm checks are held
failing until every companion is ready to arm (--no-sync-start: each goes when ready), each
parked facing its first waypoint. Logs, tlogs (sim<i>.tlog: the vehicles' own tracks), flight
records (uav<sysid>.jsonl), fleet.json and summary.json go to --logs (default
out/fleet-<UTC time>). Ctrl-C interrupts the companions (each brings its vehicle to a safe stop),
then stops the simulators and the router. Exit status 0 when every mission completed, 1
otherwise, 2 for bad arguments, 130 when interrupted."""

STATUS_EPILOG = """\
examples:
  companion fleet status --logs out/fleet-20261201-101500
  companion fleet status --router tcp/127.0.0.1:7447 --seconds 5 --json

Positions are north,east,down metres about the home of the lowest system id heard; "nearest" is
the distance to the nearest other vehicle (3D). Decisions: with --logs every decision of the
flight records so far; with --router only those heard while listening. Exit status 1 when no
vehicle was heard."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "fleet",
        help="fly several simulated vehicles through one zenoh router; watch them",
        description="Fly several simulated helicopters, each with its companion, through "
        "one zenoh router (up), and watch them (status).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="fleet_command", metavar="SUBCOMMAND")
    sub.required = True

    up = sub.add_parser(
        "up",
        help="start a router, N sim-vehicle and N companion run; wait for the missions",
        description="Start one zenoh router, N SITL helicopters (sim-vehicle) and their "
        "companions (companion run), each flying one mission file of --mission-dir from that "
        "file's home; wait until every companion exits and print a summary.",
        epilog=UP_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    up.add_argument("--vehicles", type=int, required=True, metavar="N", help="number of vehicles (>= 1)")
    up.add_argument(
        "--mission-dir",
        required=True,
        metavar="DIR",
        help="directory of mission files (*.plan, *.waypoints); the first N by name are flown",
    )
    up.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        metavar="X",
        help="simulation speed-up (sim-vehicle --speedup, companion --time-scale; default 1)",
    )
    up.add_argument(
        "--no-share",
        action="store_true",
        dest="no_share",
        help="companions do not share trajectories (companion run --no-fleet): the baseline",
    )
    up.add_argument(
        "--trajectory-delay-ms",
        type=float,
        metavar="MS",
        dest="trajectory_delay_ms",
        help="fault injection: every companion holds each trajectory message MS ms before publishing it "
        "(the experiment of a slow network; $HELI_COMPANION_TEST_FLEET_DELAY_MS of the companions)",
    )
    up.add_argument("--seed", type=int, metavar="S", help="seed: vehicle i gets S+i (simulator and companion)")
    up.add_argument(
        "--gcs",
        default="127.0.0.1:14550",
        metavar="HOST:PORT",
        help="every simulator also sends telemetry here (a ground station; default "
        "127.0.0.1:14550; 'none' for no ground station)",
    )
    up.add_argument(
        "--no-sync-start",
        action="store_false",
        dest="sync_start",
        help="let each vehicle take off as soon as its companion is ready (default: hold every "
        "vehicle's pre-arm checks until all companions are ready, then start them together)",
    )
    up.add_argument("--timeout", type=float, metavar="S", help="stop the fleet after S wall seconds")
    up.set_defaults(func=run_up)

    st = sub.add_parser(
        "status",
        help="one row per vehicle from the companions' zenoh status and events",
        description="Connect to the fleet's zenoh router as a client, listen to uav/*/status "
        "and uav/*/events for --seconds and print one row per vehicle: mode, leg, outcome, "
        "position, separation to the nearest other vehicle, decisions.",
        epilog=STATUS_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    st.add_argument(
        "--router", metavar="ENDPOINT", help="the zenoh router, e.g. tcp/127.0.0.1:7447 (or --logs, not both)"
    )
    st.add_argument("--seconds", type=float, default=2.0, metavar="S", help="listen this long (default 2)")
    st.set_defaults(func=run_status)
    add_shared_options(p, [up, st], _add_shared)


def _add_shared(p) -> None:
    """The options of both actions (``p.add_argument``), accepted before or after the action."""
    p.add_argument(
        "--logs",
        metavar="DIR",
        help="up: the output directory (default out/fleet-<UTC time>); "
        "status: a `fleet up` output directory, whose fleet.json names the router",
    )
    p.add_argument("--json", action="store_true", help="print the summary (up) or the rows (status) as JSON")


# ------------------------------------------------------------------------------------ up
def check_up_args(args: argparse.Namespace) -> None:
    """One-line errors naming the option (``ConfigError``)."""
    if args.vehicles < 1:
        raise ConfigError(f"--vehicles: expected an integer >= 1, got {args.vehicles}")
    if not Path(args.mission_dir).is_dir():
        raise ConfigError(f"--mission-dir: {args.mission_dir} is not a directory")
    if not (math.isfinite(args.speedup) and args.speedup > 0):
        raise ConfigError(f"--speedup: expected a number > 0, got {args.speedup:g}")
    if args.trajectory_delay_ms is not None and not (
        math.isfinite(args.trajectory_delay_ms) and args.trajectory_delay_ms >= 0
    ):
        raise ConfigError(f"--trajectory-delay-ms: expected a number >= 0, got {args.trajectory_delay_ms:g}")
    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0):
        raise ConfigError(f"--timeout: expected a number of seconds > 0, got {args.timeout:g}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")


def run_up(args: argparse.Namespace) -> int:
    import signal
    import threading

    from companion.fleet.launcher import Fleet, default_logs_dir
    from companion.fleet.missions import select_missions

    check_up_args(args)
    missions = select_missions(args.mission_dir, args.vehicles)
    logs = Path(args.logs) if args.logs else default_logs_dir()
    gcs = None if str(args.gcs).lower() == "none" else args.gcs
    fleet = Fleet(
        missions,
        logs,
        speedup=args.speedup,
        share=not args.no_share,
        trajectory_delay_ms=args.trajectory_delay_ms,
        seed=args.seed,
        gcs_out=gcs,
        sync_start=args.sync_start,
    )
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    interrupted = False
    try:
        fleet.start()
        print(
            f"fleet: {len(missions)} vehicles, router {fleet.router_endpoint}, logs {logs} "
            f"(companion fleet status --logs {logs})",
            flush=True,
        )
        try:
            fleet.wait(args.timeout, stop_event=stop)
        except TimeoutError as exc:
            interrupted = True
            print(f"fleet: stopping ({'interrupted' if stop.is_set() else exc})", file=sys.stderr, flush=True)
    finally:
        result = fleet.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    (logs / "summary.json").write_text(json.dumps(result.as_dict(), indent=2) + "\n")
    print(json.dumps(result.as_dict()) if args.json else result.table(), flush=True)
    if interrupted and stop.is_set():
        return 130
    return 0 if result.completed else 1


# ------------------------------------------------------------------------------------ status
def router_of(args: argparse.Namespace) -> str:
    """The router endpoint: --router, or fleet.json's of --logs (exactly one of them given)."""
    if bool(args.router) == bool(args.logs):
        raise ConfigError(
            "--router/--logs: give one of them (the router's endpoint, or a `fleet up` "
            f"directory), got {'both' if args.router else 'neither'}"
        )
    if args.router:
        return args.router
    path = Path(args.logs) / "fleet.json"
    try:
        desc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"--logs: {path} does not exist (is {args.logs} a `companion fleet up` directory?)") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--logs: cannot read {path}: {exc}") from None
    router = desc.get("router") if isinstance(desc, dict) else None
    if not router:
        raise ConfigError(f"--logs: {path} names no router")
    return router


def listen_fleet(router: str, seconds: float):
    """Listen to ``uav/*/status`` and ``uav/*/events`` through ``router`` for ``seconds``; the
    ``FleetView``."""
    import time

    from companion.fleet.status_view import FleetView
    from companion.threats.transport.bus import ThreatBus

    view = FleetView()
    with ThreatBus(255, listen=(), connect=(router,), mode="client") as bus:
        session = bus.session
        subs = [
            session.declare_subscriber("uav/*/status", _json_handler(view.on_status)),
            session.declare_subscriber("uav/*/events", _json_handler(view.on_event)),
        ]
        time.sleep(seconds)
        for sub in subs:
            sub.undeclare()
    return view


def _json_handler(callback):
    def on_sample(sample) -> None:
        try:
            msg = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        callback(str(sample.key_expr), msg)

    return on_sample


def decisions_of_records(logs: Path) -> dict:
    """sysid -> the decisions in the flight records named by ``logs/fleet.json`` (JSON Lines)."""
    from companion.fleet.status_view import record_decisions

    try:
        desc = json.loads((logs / "fleet.json").read_text())
        vehicles = [(int(v["sysid"]), Path(v["files"]["record"])) for v in desc.get("vehicles", [])]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return {sysid: record_decisions(path) for sysid, path in vehicles if path.suffix == ".jsonl" and path.exists()}


def run_status(args: argparse.Namespace) -> int:
    from companion.fleet.status_view import format_table, rows_json, vehicle_rows

    if not (math.isfinite(args.seconds) and args.seconds > 0):
        raise ConfigError(f"--seconds: expected a number > 0, got {args.seconds:g}")
    router = router_of(args)
    view = listen_fleet(router, args.seconds)
    statuses, decisions = view.snapshot()
    if args.logs:  # every decision so far, from the flight records
        decisions.update(decisions_of_records(Path(args.logs)))
    rows = vehicle_rows(statuses, decisions)
    if args.json:
        print(json.dumps({"router": router, "vehicles": rows_json(rows)}))
    else:
        print(format_table(rows))
    return 0 if rows else 1
