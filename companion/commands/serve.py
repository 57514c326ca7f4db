"""``companion serve``: the companion-computer service (``companion.service.serve``)."""

from __future__ import annotations

import argparse

from companion.commands.run import add_flight_arguments, cancel_on_signals, flight_settings

EPILOG = """examples:
  companion serve --connect serial:///dev/ttyAMA0:921600 --record-dir /var/lib/companion/flights
  companion serve --connect udpin://127.0.0.1:14540 --zenoh-listen tcp/127.0.0.1:7450   # with sim-vehicle
  # then, from any ground station linked to the vehicle:
  #   MAVProxy:  set target_component 191
  #              long MISSION_START
  #   pymavlink: command_long_send(sysid, 191, MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
  #   zenoh:    put uav/<sysid>/command '{"command": "mission_start"}'

The service waits for the vehicle (and for it again after a reboot), is a component of its
MAVLink system (system id of the vehicle, component 191, HEARTBEAT ONBOARD_CONTROLLER: STANDBY
when ready, ACTIVE when flying), says "companion ready" by STATUSTEXT, and flies the vehicle's
stored mission on each MISSION_START addressed to it, as `companion run` would fly it; a
pilot's mode change ends a flight at once. Each flight's summary is printed as one JSON line.
deploy/ has a systemd unit and an example settings file.

exit status: 0 after --flights flights or on SIGTERM/SIGINT (a flight in progress is ended as
link.on_interrupt says: hold, land or RTL); 2 bad input."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "serve",
        help="the long-running companion service: fly the stored mission on MISSION_START",
        description="Wait for the vehicle, then fly its stored mission each time a ground station "
        "sends MAV_CMD_MISSION_START to the companion component (191), or zenoh's "
        "uav/<sysid>/command asks; report readiness by HEARTBEAT and STATUSTEXT.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_flight_arguments(p)
    p.add_argument(
        "--record-dir", metavar="DIR", help="write each flight's MCAP record here (flight-<n>-<UTC time>.mcap)"
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="on start, take over a vehicle left hovering in GUIDED (the companion crashed "
        "or was restarted mid-flight): fly on from its current item, threats from --state-dir",
    )
    p.add_argument(
        "--flights", type=positive_int, metavar="N", help="exit after N flights (default: serve until stopped)"
    )
    p.set_defaults(func=serve)


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of flights, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1 flight, got {value}")
    return value


def serve(args: argparse.Namespace) -> int:
    import asyncio

    from companion.service.serve import CompanionService

    settings = flight_settings(args)
    if settings is None:
        return 0
    service = CompanionService(
        settings, world_path=args.world, record_dir=args.record_dir, max_flights=args.flights, resume=args.resume
    )

    async def main() -> int:
        cancel_on_signals()
        try:
            await service.run()
        except asyncio.CancelledError:
            pass  # stopped: a clean exit for systemd
        return 0

    return asyncio.run(main())
