"""``companion router``: a zenoh router in a Python process (issue 11; the fleet will use it).

Companions (``companion run --zenoh-connect ENDPOINT``, peer or client mode) and threat sources
(``companion threat ... --zenoh-connect ENDPOINT``) meet through it instead of connecting to each
other. It only routes: it keeps no threats and answers no query itself. When it stops and comes
back on the same endpoint, the sessions connected to it reconnect by themselves (zenoh's
``connect/retry``, ``companion.threats.transport.bus.session_config``) and redeclare their subscriptions:
a companion flies on meanwhile on the threats it already holds.
"""

from __future__ import annotations

import argparse
import logging

log = logging.getLogger(__name__)

EPILOG = """examples:
  companion router --listen tcp/0.0.0.0:7447
  companion run --zenoh-connect tcp/127.0.0.1:7447 ...   # listens on 7447 + sysid as well

It runs until SIGINT or SIGTERM."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "router",
        help="run a zenoh router (companions and threat sources connect to it)",
        description="Open a zenoh session in router mode listening on ENDPOINT (repeatable), "
        "multicast scouting off, and route until SIGINT or SIGTERM.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        required=True,
        help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)",
    )
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", default=[], help="another router to connect to (repeatable)"
    )
    p.set_defaults(func=run)


def open_router(listen, connect=()):
    """Open and return a zenoh router session (``ThreatBusError`` when it cannot listen)."""
    import zenoh

    from companion.errors import ThreatBusError
    from companion.threats.transport.bus import session_config

    config = session_config(mode="router", listen=listen, connect=connect)
    try:
        return zenoh.open(config)
    except Exception as exc:  # zenoh.ZError: port in use ...
        raise ThreatBusError(f"zenoh router (listen {list(listen)}): {exc}") from None


def run(args: argparse.Namespace) -> int:
    import signal
    import threading

    session = open_router(args.listen, args.connect)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    log.warning("zenoh router %s listening on %s", session.zid(), ", ".join(args.listen))
    print(f"zenoh router listening on {', '.join(args.listen)}", flush=True)
    try:
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    return 0
