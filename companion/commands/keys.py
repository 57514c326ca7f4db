"""``companion keys init DIR``: a CA, identities and zenoh configurations for authenticated threats."""

from __future__ import annotations

import argparse
import logging

log = logging.getLogger(__name__)

EPILOG = """\
Examples:
  companion keys init deploy --source radar1 --source radar2 --observer gcs
  companion run --zenoh-config deploy/companion.json5 --mission mission_files/exclusion_zones.plan
  companion threat add --zenoh-config deploy/radar1.json5 --id p1 --pos 75,75,-20 --radius 5
  companion keys init deploy --force --listen tls/0.0.0.0:7447 --connect tls/10.0.0.5:7447

Writes ca.key/ca.pem, and <name>.key (mode 0600), <name>.pem, <name>.json5 for the companion,
every source and every observer. A source may only put and delete threats on
uav/<sysid>/threats/<its name>/<id>; observers only read status, events and path; anyone else
(no certificate, or a certificate not named in the companion's rules) is refused."""


def register(subparsers) -> None:
    p = subparsers.add_parser("keys", help="create certificates and zenoh configs for authenticated threat sources",
                              description=__doc__, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION")
    sub.required = True
    sp = sub.add_parser("init", help="create a CA, the identities and their zenoh configurations",
                        description="Create a CA, the companion's, sources' and observers' keys and "
                        "certificates, and a zenoh configuration (JSON5) for each.",
                        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sp.add_argument("directory", help="output directory (refused if not empty, unless --force)")
    sp.add_argument("--sysid", type=int, default=1, help="vehicle system id of the keys (default 1)")
    sp.add_argument("--companion", default="companion", help="the companion's name (default companion)")
    sp.add_argument("--source", action="append", metavar="NAME",
                    help="an authorised threat source (repeatable; default source1)")
    sp.add_argument("--observer", action="append", metavar="NAME", default=[],
                    help="a read-only identity: status, events and path (repeatable)")
    sp.add_argument("--listen", action="append", metavar="ENDPOINT",
                    help="the companion's endpoint (repeatable; default tls/0.0.0.0:7447)")
    sp.add_argument("--connect", action="append", metavar="ENDPOINT",
                    help="the endpoint sources connect to (repeatable; default tls/localhost:7447)")
    sp.add_argument("--host", action="append", metavar="NAME", default=[],
                    help="another host name or IP address of the companion, for its certificate")
    sp.add_argument("--days", type=int, default=825, help="validity of the identities in days (default 825)")
    sp.add_argument("--force", action="store_true", help="overwrite the files in a non-empty directory")
    sp.set_defaults(func=run)


def run(args) -> int:
    from companion.extras import require
    from companion.security.deployment import init_deployment

    require("keys", "cryptography")           # before any file is written

    dep = init_deployment(args.directory, sysid=args.sysid, companion=args.companion,
                          sources=args.source or ["source1"], observers=args.observer,
                          listen=args.listen or ["tls/0.0.0.0:7447"],
                          connect=args.connect or ["tls/localhost:7447"], hosts=args.host,
                          days=args.days, force=args.force)
    print(f"CA: {dep.ca_cert} (key {dep.ca_key}: keep it offline)")
    for name in [dep.companion, *dep.sources, *dep.observers]:
        role = "companion" if name == dep.companion else ("source" if name in dep.sources else "observer")
        print(f"{role:9s} {name}: {dep.configs[name]} ({dep.certs[name].name}, {dep.keys[name].name})")
    print(f"start: companion run --zenoh-config {dep.configs[dep.companion]} ...")
    print(f"       companion threat add --zenoh-config {dep.configs[dep.sources[0]]} --id p1 --pos 75,75,-20 --radius 5")
    return 0
