"""``companion run``: fly the mission (the daemon, DESIGN section 1)."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from companion.commands.mission_io import add_signing_argument
from companion.errors import ConfigError

log = logging.getLogger(__name__)

#: Exit statuses of ``companion run`` (2, bad input, comes from ``companion.cli``).
EXIT_REFUSED = 3
EXIT_ABORTED = 4

EPILOG = """examples:
  sim-vehicle --speedup 4 &                      # a SITL helicopter sending to udp 14540
  companion run --mission mission_files/exclusion_zones.plan --time-scale 4 --record out/flight.jsonl
  companion run                                  # fly the mission already stored on the vehicle
  companion run --config my.toml --zenoh-connect tcp/192.168.1.10:7447
  companion run --connect udpin://0.0.0.0:14540 --mission mission_files/exclusion_zones.plan \\
      --time-scale 8                             # ArduPilot's arducopter-heli SITL at --speedup 8
  companion run --connect serial:///dev/ttyAMA0:921600 --interlock pilot --adsb   # a real helicopter
  companion run --state-dir /var/lib/companion --resume   # take over after a crash, threats kept
  companion run --record out/flight.mcap --foxglove 8765 --tlog out/flight.tlog   # watch it in Foxglove

start-up: a helicopter (H_RSC_* parameters) is armed with its motor interlock low, the interlock
is engaged after the arming delay (--interlock command, default; or by the pilot's RC switch,
--interlock pilot) and the rotor run-up (H_RSC_RUNUP_TIME) awaited before the takeoff; a vehicle
already armed and flying is joined where it is (no arming, no takeoff).

exit status: 0 mission completed; 2 bad input or no vehicle (nothing flown); 3 the vehicle
refused (arming, mode, interlock or takeoff: it is left disarmed on the ground); 4 flight aborted
(the vehicle holds in the air, or was left disarmed on the ground); 130 interrupted (the vehicle
is held, landed or returned per link.on_interrupt).

crash and restart: a companion killed in flight leaves the vehicle hovering (GUIDED setpoints
stop: it brakes after GUID_TIMEOUT). `companion run --resume` takes it over: the vehicle's
mission from its current item (the companion sets it at every leg), planned from where it
hovers, and the threats of the snapshot in --state-dir (written whenever they change) with
their remaining TTL. --resume refuses (status 2) a vehicle without a mission or not flying."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run",
        help="fly a mission: plan, smooth, stream setpoints, answer threats",
        description="Connect to the vehicle, take the mission (--mission FILE, else the one "
        "stored on the vehicle), plan every leg around the exclusion zones (GART), smooth it "
        "(G2 by default), take off and fly it in GUIDED by 50 Hz setpoints; answer zenoh "
        "threats by replanning or switching; land or RTL as the mission says.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_flight_arguments(p)
    p.add_argument("--mission", help=".plan or QGC WPL 110 file to upload and fly")
    p.add_argument(
        "--record",
        metavar="FILE",
        help="write the flight record here: MCAP (Foxglove opens it) when FILE ends in .mcap, else JSON Lines",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="take over a vehicle already flying its mission after a companion crash: "
        "fly on from its current mission item, with the threats of the --state-dir snapshot",
    )
    p.set_defaults(func=run)


def add_flight_arguments(p) -> None:
    """The options ``companion run`` and ``companion serve`` share (vehicle, zenoh, view, planners)."""
    p.add_argument("--connect", help="MAVSDK URL of the vehicle (default udpin://0.0.0.0:14540)")
    p.add_argument(
        "--instance",
        type=int,
        metavar="N",
        help="the companion of `sim-vehicle --instance N` (as PX4 SITL numbers them): "
        "--connect udpin://0.0.0.0:<14540+N>, zenoh prefix uav/<N+1> and endpoint "
        "tcp/127.0.0.1:<7448+N> (--connect and the --zenoh options still win)",
    )
    p.add_argument("--config", help="settings file (TOML); see --print-config")
    add_signing_argument(p)
    p.add_argument(
        "--world",
        help="world file with extra obstacles: .toml/.json in local NED about home, "
        "or a .geojson/.kml map converted about home",
    )
    p.add_argument(
        "--zenoh-listen",
        action="append",
        metavar="ENDPOINT",
        default=None,
        help="zenoh endpoint to listen on (repeatable; default tcp/127.0.0.1:<7447+sysid>), e.g. tcp/0.0.0.0:7448",
    )
    p.add_argument(
        "--zenoh-connect",
        action="append",
        metavar="ENDPOINT",
        default=None,
        help="zenoh endpoint to connect to (repeatable)",
    )
    p.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="zenoh configuration file (JSON5, e.g. from `companion keys init`): mutual TLS "
        "and access control; its endpoints replace the default ones",
    )
    p.add_argument("--no-zenoh", action="store_true", help="fly without zenoh (no threats, no status)")
    p.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the flight live to Foxglove (WebSocket; host 127.0.0.1 unless given): "
        "3D scene, map, decisions, threats (view.foxglove)",
    )
    p.add_argument(
        "--tlog",
        metavar="FILE",
        help="record the MAVLink traffic with the vehicle, both ways, to this .tlog (link.tlog_file)",
    )
    p.add_argument("--seed", type=int, help="random seed of the planners (default from settings)")
    p.add_argument(
        "--time-scale",
        type=float,
        metavar="X",
        help="vehicle seconds per wall-clock second (default: read from the vehicle, its SIM_SPEEDUP; 1 without it)",
    )
    p.add_argument("--smooth", choices=("g1", "g2", "none"), help="smoother (default g2)")
    p.add_argument(
        "--vehicle",
        choices=("helicopter", "multirotor"),
        help="vehicle profile (default helicopter: motor interlock and rotor run-up "
        "when the vehicle has them; multirotor: none)",
    )
    p.add_argument(
        "--interlock",
        choices=("command", "pilot"),
        help="who engages a helicopter's motor interlock: the companion (DO_AUX_FUNCTION, "
        "default) or the safety pilot's RC switch",
    )
    p.add_argument("--adsb", action="store_true", help="treat ADS-B traffic (ADSB_VEHICLE) as moving threats")
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="keep the threat snapshot here (state.dir): written as threats change, read by --resume",
    )
    p.add_argument(
        "--no-fleet",
        action="store_true",
        dest="no_fleet",
        help="neither share this vehicle's trajectory nor avoid the others' (fleet.enabled = false)",
    )
    p.add_argument(
        "--no-feasibility",
        action="store_true",
        dest="no_feasibility",
        help="do not check the legs on the helicopter's closed loop (feasibility.enabled = false)",
    )
    p.add_argument(
        "--print-config",
        nargs="?",
        const="toml",
        choices=("toml", "json"),
        metavar="FORMAT",
        help="print the effective settings and exit, as TOML that --config reads back (default) or as JSON",
    )


def instance_overrides(instance: int) -> dict:
    """The settings of the companion of ``sim-vehicle --instance N``: its UDP port 14540 + N,
    system id N + 1 (the zenoh prefix ``uav/<N+1>``; the zenoh endpoint follows it)."""
    if not 0 <= instance <= 200:
        raise ConfigError(f"--instance: expected 0..200, got {instance}")
    from heli_common.ports import companion_port

    return {"link": {"connect": f"udpin://0.0.0.0:{companion_port(instance)}"}, "zenoh": {"sysid": instance + 1}}


def injected_fleet_delay_s(environ=None) -> float | None:
    """The injected trajectory delay of ``$HELI_COMPANION_TEST_FLEET_DELAY_MS``, in s (None: unset).

    Parameters
    ----------
    environ : mapping, optional
        The environment (default ``os.environ``).

    Raises
    ------
    ConfigError
        The variable is not a number >= 0 (the message names it).
    """
    import math
    import os

    from companion.fleet.settings import FLEET_DELAY_ENV

    text = (os.environ if environ is None else environ).get(FLEET_DELAY_ENV, "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"{FLEET_DELAY_ENV}: expected a number of ms >= 0, got {text!r}")
    return value / 1000.0


def settings_overrides(args: argparse.Namespace) -> dict:
    """The command-line options as a nested settings mapping."""
    out: dict = {}
    if getattr(args, "instance", None) is not None:
        out.update(instance_overrides(args.instance))
    if args.connect:
        out.setdefault("link", {})["connect"] = args.connect
    if args.signing_key:
        out.setdefault("link", {})["signing_key_file"] = args.signing_key
    if args.time_scale is not None:
        out.setdefault("link", {})["time_scale"] = args.time_scale
    if args.seed is not None:
        out["seed"] = args.seed
    if args.smooth:
        out.setdefault("smoothing", {})["method"] = args.smooth
    if getattr(args, "vehicle", None):
        out.setdefault("startup", {})["vehicle"] = args.vehicle
    if getattr(args, "no_feasibility", False):
        out.setdefault("feasibility", {})["enabled"] = False
    if getattr(args, "no_fleet", False):
        out.setdefault("fleet", {})["enabled"] = False
    delay_s = injected_fleet_delay_s()
    if delay_s is not None:
        out.setdefault("fleet", {})["inject_delay_s"] = delay_s
    if getattr(args, "interlock", None):
        out.setdefault("startup", {})["interlock"] = args.interlock
    if getattr(args, "adsb", False):
        out.setdefault("adsb", {})["enabled"] = True
    if args.zenoh_listen is not None:
        out.setdefault("zenoh", {})["listen"] = args.zenoh_listen
    if args.zenoh_connect is not None:
        out.setdefault("zenoh", {})["connect"] = args.zenoh_connect
    if getattr(args, "zenoh_config", None):
        out.setdefault("zenoh", {})["config"] = args.zenoh_config
    if getattr(args, "state_dir", None):
        out.setdefault("state", {})["dir"] = args.state_dir
    if getattr(args, "foxglove", None):
        out.setdefault("view", {})["foxglove"] = args.foxglove
    if getattr(args, "tlog", None):
        out.setdefault("link", {})["tlog_file"] = args.tlog
    if args.no_zenoh:
        out.setdefault("zenoh", {})["enabled"] = False
    return out


def flight_settings(args: argparse.Namespace):
    """The settings of ``args`` (a zenoh configuration file checked); None when
    ``--print-config`` printed them instead."""
    from companion.config import load_settings, settings_to_dict, settings_to_toml

    settings = load_settings(args.config, settings_overrides(args))
    if args.print_config:
        text = (
            json.dumps(settings_to_dict(settings), indent=2)
            if args.print_config == "json"
            else settings_to_toml(settings)
        )
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        return None
    if settings.zenoh.enabled and settings.zenoh.config:  # a bad file: refused before any flight
        from companion.threats.transport.access import load_config

        load_config(settings.zenoh.config)
    return settings


def cancel_on_signals() -> None:
    """SIGINT and SIGTERM cancel the running task (call it from that task)."""
    import asyncio
    import signal

    task, loop = asyncio.current_task(), asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, task.cancel)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from companion.daemon import CompanionDaemon
    from companion.errors import FlightAborted, VehicleRefused

    settings = flight_settings(args)
    if settings is None:
        return 0
    daemon = CompanionDaemon(
        settings, mission_path=args.mission, world_path=args.world, record_path=args.record, resume=args.resume
    )

    async def main() -> int:
        cancel_on_signals()
        try:
            await daemon.run()
            status = 0
        except asyncio.CancelledError:
            status = 130
        except VehicleRefused as exc:
            print(f"companion: error: {exc}", file=sys.stderr)
            status = EXIT_REFUSED
        except FlightAborted as exc:
            print(f"companion: error: flight aborted: {exc}", file=sys.stderr)
            status = EXIT_ABORTED
        print(json.dumps(daemon.summary.as_dict()))  # the last line: the flight's summary
        return status

    return asyncio.run(main())
