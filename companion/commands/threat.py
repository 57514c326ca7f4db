"""``companion threat``: inject threats into a running companion over zenoh (DESIGN sections 6, 9).

``add`` / ``move`` PUT a version-1 JSON threat on ``uav/<sysid>/threats/<id>``, ``remove``
DELETEs it, ``list`` asks the companion for the threats it holds (or shows a scenario file's
events), ``play`` runs a scripted scenario (``mission_files/threats/*.toml``). Paper section 3.3.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time

from companion.errors import ThreatPayloadError
from heli_common.cli_args import add_shared_options

log = logging.getLogger(__name__)

EPILOG = """\
Examples:
  companion threat add --id p1 --pos 75,75,-20 --radius 5 --ttl 300
  companion threat add --id m1 --pos 44,30,-20 --vel -1,1,0 --radius 3      # moving at sqrt(2) m/s
  companion threat add --id g1 --lat 47.3984 --lon 8.5466 --alt 508 --radius 5
  companion threat move --id m1 --pos 40,34,-20 --vel 0,1.4,0
  companion threat remove --id m1
  companion threat list                                  # threats the companion holds now
  companion threat list --scenario mission_files/threats/demo.toml
  companion threat play mission_files/threats/demo.toml --time-scale 5
  companion threat add --id p1 --pos 75,75,-20 --radius 5 --sysid 2     # the companion of system 2
  companion threat add --id p1 --pos 75,75,-20 --radius 5 --sysid 2 --zenoh-connect tcp/10.0.0.5:7447
  companion threat --zenoh-config deploy/radar1.json5 add --id p1 --pos 75,75,-20 --radius 5
                                       # an authenticated source (companion keys init): key
                                       # uav/<sysid>/threats/radar1/p1

Positions are local NED metres about the vehicle's home (north,east,down: -20 is 20 m up) or
WGS-84 --lat/--lon/--alt (altitude AMSL, m). The companion of system N (`companion run`)
listens on tcp/127.0.0.1:<7447+N> by default (7448 for system 1); this command connects there
for --sysid N (default 1), or to --zenoh-connect (another machine, a zenoh router). With
--zenoh-config (a source's file from `companion keys init`) it connects over mutual TLS and puts
on uav/<sysid>/threats/<source>/<id>, <source> being its certificate's name. The options
--sysid, --zenoh-connect, --zenoh-listen, --zenoh-config, --source and --wait go before or
after the action (after it wins when given twice)."""

SUBCOMMAND_HELP = {
    "add": "PUT a new threat (replaces one with the same id)",
    "move": "PUT a new position and/or velocity for a threat (the rest as the companion holds it)",
    "remove": "DELETE a threat",
    "list": "show the threats the companion holds (a zenoh query), or a scenario file's events",
    "play": "play a scripted scenario file (TOML [[event]] tables with at_s, action, ...)",
}


def _vector(text: str, option: str) -> tuple:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ThreatPayloadError(f"{option}: expected three numbers N,E,D, got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ThreatPayloadError(f"{option}: expected three finite numbers N,E,D, got {text!r}")
    return values


def _add_bus_options(p) -> None:
    """The options of every action: which bus, which identity, how long to wait (``p.add_argument``)."""
    p.add_argument("--sysid", type=int, default=1, help="vehicle system id: key prefix uav/<sysid> (default 1)")
    p.add_argument(
        "--zenoh-connect",
        dest="zenoh_connect",
        nargs="+",
        metavar="ENDPOINT",
        help="zenoh endpoints to connect to (default tcp/127.0.0.1:<7447 + --sysid>, the companion's own default)",
    )
    p.add_argument(
        "--zenoh-listen",
        dest="zenoh_listen",
        nargs="+",
        metavar="ENDPOINT",
        default=[],
        help="zenoh endpoints to listen on as well (default none)",
    )
    p.add_argument(
        "--zenoh-config",
        dest="zenoh_config",
        metavar="FILE",
        help="zenoh configuration file (JSON5, e.g. a source's from `companion keys init`): "
        "TLS certificate and endpoints; --zenoh-connect/--zenoh-listen replace its endpoints",
    )
    p.add_argument(
        "--source",
        metavar="NAME",
        help="put and delete on uav/<sysid>/threats/NAME/<id> (default: the common name of "
        "the --zenoh-config certificate, else the plain uav/<sysid>/threats/<id>)",
    )
    p.add_argument(
        "--wait",
        type=float,
        default=3.0,
        metavar="S",
        help="how long to wait for the companion's subscriber or reply (default 3 s)",
    )


def _add_threat_options(p, required: bool) -> None:
    p.add_argument("--id", required=True, help="threat id: 1-64 of A-Z a-z 0-9 _ - .")
    p.add_argument("--pos", help="position N,E,D in local NED metres")
    p.add_argument("--lat", type=float, help="latitude (deg, WGS-84), with --lon and --alt")
    p.add_argument("--lon", type=float, help="longitude (deg)")
    p.add_argument("--alt", type=float, help="altitude AMSL (m)")
    p.add_argument("--vel", help="velocity VN,VE,VD in m/s (default 0,0,0)")
    p.add_argument("--radius", type=float, required=required, help="radius in m")
    p.add_argument("--ttl", type=float, help="lifetime in s (default: until removed)")
    p.add_argument(
        "--kind", choices=("popup", "moving"), help="popup (static) or moving (default: moving when --vel is non-zero)"
    )


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "threat",
        help="inject pop-up and moving threats over zenoh",
        description="Inject threats into a running companion over zenoh (keys uav/<sysid>/threats/<id>, "
        "JSON version 1): add, move, remove, list, or play a scripted scenario.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="threat_command", metavar="ACTION")
    sub.required = True
    actions = []
    for name in ("add", "move", "remove", "list", "play"):
        # NED vectors start with a minus sign (-1,1,0): heli_common.cli_args takes them as values
        sp = sub.add_parser(
            name,
            help=SUBCOMMAND_HELP[name],
            description=SUBCOMMAND_HELP[name],
            epilog=EPILOG,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        actions.append(sp)
        if name in ("add", "move"):
            _add_threat_options(sp, required=name == "add")
        elif name == "remove":
            sp.add_argument("--id", required=True, help="threat id")
        elif name == "list":
            sp.add_argument("--scenario", help="list this scenario file's events instead (no zenoh)")
            sp.add_argument("--json", action="store_true", help="print the threats as JSON lines")
        else:
            sp.add_argument("scenario", help="scenario TOML file (see mission_files/threats/)")
            sp.add_argument(
                "--time-scale",
                dest="time_scale",
                type=float,
                default=1.0,
                help="scenario seconds per wall-clock second (set to sim-vehicle --speedup)",
            )
        sp.set_defaults(func=run)
    add_shared_options(p, actions, _add_bus_options)


# ---------------------------------------------------------------------------- building threats
def _position(args):
    has_global = any(v is not None for v in (args.lat, args.lon, args.alt))
    if args.pos is not None and has_global:
        raise ThreatPayloadError("--pos: give either --pos or --lat/--lon/--alt, not both")
    if args.pos is not None:
        return "local_ned", _vector(args.pos, "--pos")
    if has_global:
        if None in (args.lat, args.lon, args.alt):
            raise ThreatPayloadError("--lat/--lon/--alt: give all three")
        return "global", (args.lat, args.lon, args.alt)
    return None


def threat_from_args(args, previous=None):
    """The threat described by ``add`` / ``move`` options (``previous``: what ``move`` changes)."""
    from dataclasses import replace

    from companion.threats.model import Threat
    from companion.threats.transport import codec

    codec.check_id(args.id, "--id")
    position = _position(args)
    vel = _vector(args.vel, "--vel") if args.vel is not None else None
    if previous is None:
        if position is None:
            raise ThreatPayloadError("--pos: missing (give --pos N,E,D or --lat/--lon/--alt)")
        vel = vel or (0.0, 0.0, 0.0)
        kind = args.kind or ("moving" if any(vel) else "popup")
        threat = Threat(args.id, kind, position[0], position[1], vel, args.radius, args.ttl, 0.0)
    else:
        threat = previous
        if position is not None:
            threat = replace(threat, frame=position[0], position=position[1])
        if vel is not None:
            threat = replace(threat, velocity_ned_m_s=vel)
        if args.radius is not None:
            threat = replace(threat, radius_m=args.radius)
        if args.ttl is not None:
            threat = replace(threat, ttl_s=args.ttl)
        kind = args.kind or ("moving" if any(threat.velocity_ned_m_s) else threat.kind)
        threat = replace(threat, kind=kind)
    try:
        codec.encode(threat)
    except ThreatPayloadError as exc:
        option = {
            "radius_m": "--radius",
            "ttl_s": "--ttl",
            "velocity_ned_m_s": "--vel",
            "position": "--pos",
            "kind": "--kind",
        }.get(exc.field.split("[")[0].split(".")[0], exc.field)
        raise ThreatPayloadError(f"{option}: {exc}") from None
    return threat


def describe(threat) -> str:
    """One line about ``threat`` for the terminal."""
    if threat.frame == "global":
        where = f"lat {threat.position[0]:.7f} lon {threat.position[1]:.7f} alt {threat.position[2]:.1f} m"
    else:
        where = "NED " + ",".join(f"{x:.1f}" for x in threat.position) + " m"
    speed = math.sqrt(sum(v * v for v in threat.velocity_ned_m_s))
    ttl = "until removed" if threat.ttl_s is None else f"ttl {threat.ttl_s:.0f} s"
    vel = ",".join(f"{v:.2f}" for v in threat.velocity_ned_m_s)
    return f"{threat.uid}: {threat.kind} r={threat.radius_m:.1f} m at {where}, vel {vel} m/s ({speed:.2f}), {ttl}"


# ---------------------------------------------------------------------------- commands
def _open_bus(args):
    from companion.threats.transport.bus import ThreatBus

    if getattr(args, "zenoh_config", None):
        return ThreatBus(
            args.sysid,
            listen=args.zenoh_listen or None,
            connect=args.zenoh_connect or None,
            zenoh_config=args.zenoh_config,
            source=args.source,
        ).open()
    from companion.threats.settings import default_listen

    connect = (
        args.zenoh_connect if args.zenoh_connect else ([] if args.zenoh_listen else list(default_listen(args.sysid)))
    )
    return ThreatBus(args.sysid, listen=args.zenoh_listen, connect=connect, source=args.source).open()


def _wait_subscriber(bus, args, threat_id: str) -> bool:
    if bus.client.wait_for_subscriber(args.wait, threat_id):
        return True
    hint = " or does its access control refuse this identity?" if bus.security is not None else ""
    print(
        f"companion threat: warning: no subscriber of {bus.key(bus.client.threat_leaf(threat_id))} within "
        f"{args.wait:g} s (is `companion run` listening{hint}); sending anyway",
        file=sys.stderr,
    )
    return False


def run(args) -> int:
    if args.sysid is not None and not 1 <= args.sysid <= 255:
        raise ThreatPayloadError(f"--sysid: must be in 1..255, got {args.sysid}")
    if args.wait < 0 or not math.isfinite(args.wait):
        raise ThreatPayloadError(f"--wait: must be >= 0, got {args.wait}")
    action = args.threat_command
    if action == "list" and args.scenario:
        return list_scenario(args)
    if action == "play":
        from companion.threats.scenario import load_scenario

        if not (math.isfinite(args.time_scale) and args.time_scale > 0):
            raise ThreatPayloadError(f"--time-scale: must be > 0, got {args.time_scale}")
        scenario = load_scenario(args.scenario)
    elif action == "add":
        threat = threat_from_args(args)
    with _open_bus(args) as bus:
        if action == "add":
            ok = _wait_subscriber(bus, args, threat.id)
            bus.client.put_threat(threat)
            print(f"PUT {bus.key(bus.client.threat_leaf(threat.id))}: {describe(threat)}")
            return 0 if ok else 1
        if action == "move":
            previous = None
            if args.radius is None or _position(args) is None:
                held = {t.uid: t for t in bus.client.list_threats(args.wait)}
                uid = args.id if bus.client.source is None else f"{bus.client.source}/{args.id}"
                previous = held.get(uid)
                if previous is None:
                    raise ThreatPayloadError(
                        f"--id: the companion holds no threat {args.id!r} (add it first, or give --pos and --radius)"
                    )
            threat = threat_from_args(args, previous) if previous is not None else _full_move(args)
            ok = _wait_subscriber(bus, args, threat.id)
            bus.client.put_threat(threat)
            print(f"PUT {bus.key(bus.client.threat_leaf(threat.id))}: {describe(threat)}")
            return 0 if ok else 1
        if action == "remove":
            from companion.threats.transport import codec

            codec.check_id(args.id, "--id")
            ok = _wait_subscriber(bus, args, args.id)
            bus.client.delete_threat(args.id)
            print(f"DELETE {bus.key(bus.client.threat_leaf(args.id))}")
            return 0 if ok else 1
        if action == "list":
            return list_held(bus, args)
        return play(bus, scenario, args)


def _full_move(args):
    """``move`` with --pos and --radius: a complete threat, no query needed."""
    return threat_from_args(args)


def list_held(bus, args) -> int:
    import json

    from companion.threats.transport import codec

    threats = bus.client.list_threats(args.wait)
    if args.json:
        for t in threats:
            print(json.dumps({**codec.to_dict(t), "source": t.source}))
        return 0
    if not threats:
        print(f"no threats held by a companion on uav/{args.sysid} (or none answered within {args.wait:g} s)")
        return 0
    for t in threats:
        print(describe(t))
    return 0


def list_scenario(args) -> int:
    from companion.threats.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if scenario.description:
        print(" ".join(scenario.description.split()))
    for ev in scenario.events:
        what = describe(ev.threat) if ev.threat is not None else ev.threat_id
        print(f"t+{ev.at_s:7.2f} s  {ev.action:6s} {what}")
    return 0


def play(bus, scenario, args) -> int:
    """Send the scenario's events at their times (scaled by ``--time-scale``)."""
    first = next((e.threat_id for e in scenario.events), "probe")
    _wait_subscriber(bus, args, first)
    t0 = time.monotonic()
    for ev in scenario.events:
        delay = t0 + ev.at_s / args.time_scale - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        if ev.action == "remove":
            bus.client.delete_threat(ev.threat_id)
            print(f"t+{ev.at_s:7.2f} s  DELETE {bus.key(bus.client.threat_leaf(ev.threat_id))}", flush=True)
        else:
            bus.client.put_threat(ev.threat)
            print(f"t+{ev.at_s:7.2f} s  PUT    {describe(ev.threat)}", flush=True)
    return 0
