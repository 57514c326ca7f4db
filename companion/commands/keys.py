"""``companion keys init [DIR]``: a CA, identities and zenoh configurations for authenticated threats.

DIR defaults to ``$XDG_CONFIG_HOME/heli-companion/keys`` (``~/.config/heli-companion/keys``):
private keys do not belong in a repository's tracked folders.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from heli_common.cli_args import add_shared_options

log = logging.getLogger(__name__)

EPILOG = """\
Examples:
  companion keys init --source radar1 --source radar2 --observer gcs   # ~/.config/heli-companion/keys
  companion run --zenoh-config ~/.config/heli-companion/keys/companion.json5 --mission mission_files/exclusion_zones.plan
  companion threat --zenoh-config ~/.config/heli-companion/keys/radar1.json5 add --id p1 --pos 75,75,-20 --radius 5
  companion keys init /etc/companion --listen tls/0.0.0.0:7447 --connect tls/10.0.0.5:7447

Writes ca.key/ca.pem, and <name>.key (mode 0600), <name>.pem, <name>.json5 for the companion,
every source and every observer, and mavlink.key (a MAVLink 2 signing key: a random passphrase,
as MAVProxy's `signing setup PASSPHRASE` takes it; mode 0600; not with --no-mavlink-key), in DIR (default $XDG_CONFIG_HOME/heli-companion/keys, else
~/.config/heli-companion/keys; made mode 0700). DIR may hold other files; files of these names
are overwritten only with --force (the refusal names them). A source may only put and delete threats on
uav/<sysid>/threats/<its name>/<id>; observers only read status, events and path; anyone else
(no certificate, or a certificate not named in the companion's rules) is refused."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "keys",
        help="create certificates and zenoh configs for authenticated threat sources",
        description=__doc__,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION")
    sub.required = True
    sp = sub.add_parser(
        "init",
        help="create a CA, the identities and their zenoh configurations",
        description="Create a CA, the companion's, sources' and observers' keys and "
        "certificates, and a zenoh configuration (JSON5) for each.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sp.add_argument(
        "directory",
        nargs="?",
        default=None,
        help=f"output directory (default {default_dir_text()}); its files of the same names are refused unless --force",
    )
    sp.set_defaults(func=run)
    add_shared_options(p, [sp], _add_init_options)


def _add_init_options(p) -> None:
    """The options of ``keys init`` (``p.add_argument``), accepted before or after ``init``."""
    p.add_argument("--sysid", type=int, default=1, help="vehicle system id of the keys (default 1)")
    p.add_argument("--companion", default="companion", help="the companion's name (default companion)")
    p.add_argument(
        "--source", action="append", metavar="NAME", help="an authorised threat source (repeatable; default source1)"
    )
    p.add_argument(
        "--observer",
        action="append",
        metavar="NAME",
        default=[],
        help="a read-only identity: status, events and path (repeatable)",
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="the companion's endpoint (repeatable; default tls/0.0.0.0:7447)",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="the endpoint sources connect to (repeatable; default tls/localhost:7447)",
    )
    p.add_argument(
        "--host",
        action="append",
        metavar="NAME",
        default=[],
        help="another host name or IP address of the companion, for its certificate",
    )
    p.add_argument(
        "--no-mavlink-key",
        dest="mavlink_key",
        action="store_false",
        help="do not write mavlink.key, the MAVLink 2 signing key (keep the one the flight controller has)",
    )
    p.add_argument("--days", type=int, default=825, help="validity of the identities in days (default 825)")
    p.add_argument(
        "--force", action="store_true", help="overwrite the deployment's files that exist already (a new CA)"
    )


def default_dir_text() -> str:
    """The default directory as ``--help`` shows it (``~`` for the home directory)."""
    from companion.security.paths import default_keys_dir

    path = default_keys_dir()
    home = Path.home()
    return f"~/{path.relative_to(home)}" if path.is_relative_to(home) else str(path)


def run(args) -> int:
    from companion.extras import require
    from companion.security.deployment import init_deployment
    from companion.security.paths import default_keys_dir

    require("keys", "cryptography")  # before any file is written

    directory = args.directory if args.directory is not None else default_keys_dir()
    dep = init_deployment(
        directory,
        sysid=args.sysid,
        companion=args.companion,
        sources=args.source or ["source1"],
        observers=args.observer,
        listen=args.listen or ["tls/0.0.0.0:7447"],
        connect=args.connect or ["tls/localhost:7447"],
        hosts=args.host,
        days=args.days,
        mavlink_key=args.mavlink_key,
        force=args.force,
    )
    print(f"CA: {dep.ca_cert} (key {dep.ca_key}: keep it offline)")
    for name in [dep.companion, *dep.sources, *dep.observers]:
        role = "companion" if name == dep.companion else ("source" if name in dep.sources else "observer")
        print(f"{role:9s} {name}: {dep.configs[name]} ({dep.certs[name].name}, {dep.keys[name].name})")
    if dep.mavlink_key is not None:
        print(
            f"MAVLink signing key: {dep.mavlink_key} (link.signing_key_file; give the flight controller "
            f"the same over USB: MAVProxy `signing setup <the file's passphrase>`)"
        )
    print(f"start: companion run --zenoh-config {dep.configs[dep.companion]} ...")
    print(
        f"       companion threat --zenoh-config {dep.configs[dep.sources[0]]} add --id p1 --pos 75,75,-20 --radius 5"
    )
    return 0
