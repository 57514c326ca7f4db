"""``companion run``: fly the mission (the daemon, DESIGN section 1)."""

from __future__ import annotations

import argparse
import json
import logging

log = logging.getLogger(__name__)

EPILOG = """examples:
  sim-vehicle --speedup 4 &                      # a SITL helicopter sending to udp 14540
  companion run --mission mission_files/exclusion_zones.plan --time-scale 4 --record out/flight.jsonl
  companion run                                  # fly the mission already stored on the vehicle
  companion run --config my.toml --zenoh-connect tcp/192.168.1.10:7447

exit status: 0 mission completed, 1 flight aborted (the vehicle is held), 2 bad input (nothing
flown), 130 interrupted (the vehicle is held, landed or returned per link.on_interrupt)."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help="fly a mission: plan, smooth, stream setpoints, answer threats",
        description="Connect to the vehicle, take the mission (--mission FILE, else the one "
        "stored on the vehicle), plan every leg around the exclusion zones (GART), smooth it "
        "(G2 by default), take off and fly it in GUIDED by 50 Hz setpoints; answer zenoh "
        "threats by replanning or switching; land or RTL as the mission says.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", help="MAVSDK URL of the vehicle (default udpin://0.0.0.0:14540)")
    p.add_argument("--config", help="settings file (TOML); see --print-config")
    p.add_argument("--mission", help=".plan or QGC WPL 110 file to upload and fly")
    p.add_argument("--world", help="world file with extra obstacles (local NED about home)")
    p.add_argument("--zenoh-listen", action="append", metavar="ENDPOINT", default=None,
                   help="zenoh endpoint to listen on (repeatable), e.g. tcp/0.0.0.0:7447")
    p.add_argument("--zenoh-connect", action="append", metavar="ENDPOINT", default=None,
                   help="zenoh endpoint to connect to (repeatable)")
    p.add_argument("--no-zenoh", action="store_true", help="fly without zenoh (no threats, no status)")
    p.add_argument("--record", metavar="FILE", help="write the flight record (JSON Lines) here")
    p.add_argument("--seed", type=int, help="random seed of the planners (default from settings)")
    p.add_argument("--time-scale", type=float, metavar="X",
                   help="vehicle seconds per wall-clock second: sim-vehicle's --speedup")
    p.add_argument("--smooth", choices=("g1", "g2", "none"), help="smoother (default g2)")
    p.add_argument("--print-config", action="store_true",
                   help="print the effective settings as JSON and exit")
    p.set_defaults(func=run)


def settings_overrides(args: argparse.Namespace) -> dict:
    """The command-line options as a nested settings mapping."""
    out: dict = {}
    if args.connect:
        out.setdefault("link", {})["connect"] = args.connect
    if args.time_scale is not None:
        out.setdefault("link", {})["time_scale"] = args.time_scale
    if args.seed is not None:
        out["seed"] = args.seed
    if args.smooth:
        out.setdefault("smoothing", {})["method"] = args.smooth
    if args.zenoh_listen is not None:
        out.setdefault("zenoh", {})["listen"] = args.zenoh_listen
    if args.zenoh_connect is not None:
        out.setdefault("zenoh", {})["connect"] = args.zenoh_connect
    if args.no_zenoh:
        out.setdefault("zenoh", {})["enabled"] = False
    return out


def run(args: argparse.Namespace) -> int:
    import asyncio
    import signal

    from companion.config import load_settings, settings_to_dict
    from companion.daemon import CompanionDaemon, FlightAborted

    settings = load_settings(args.config, settings_overrides(args))
    if args.print_config:
        print(json.dumps(settings_to_dict(settings), indent=2))
        return 0
    daemon = CompanionDaemon(settings, mission_path=args.mission, world_path=args.world,
                             record_path=args.record)

    async def main() -> int:
        task = asyncio.current_task()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, task.cancel)
        try:
            await daemon.run()
            status = 0
        except asyncio.CancelledError:
            status = 130
        except FlightAborted as exc:
            log.error("%s", exc)
            status = 1
        print(json.dumps(daemon.summary.as_dict()))      # the last line: the flight's summary
        return status

    return asyncio.run(main())
