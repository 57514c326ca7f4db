"""``companion`` command line: one argparse subcommand per module in ``companion.commands``.

Each command module defines ``register(subparsers)`` which adds its parser and sets
``func(args) -> int``. Command modules import heavy dependencies (mavsdk, zenoh, control,
matplotlib) inside their ``func`` so that ``companion --help`` stays fast.

A user mistake (a ``CompanionError``) is printed as one line ``companion: error: ...`` and the
exit status is 2; no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from companion.errors import CompanionError
from companion.extras import MissingExtra
from companion.geo import GeoError
from heli_common.cli_args import ArgumentParser

COMMAND_MODULES = (
    "run",
    "serve",
    "mission_io",
    "plan",
    "threat",
    "keys",
    "router",
    "report",
    "demo",
    "fleet",
    "campaign",
)

log = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    """The ``companion`` parser: every command of ``COMMAND_MODULES`` that imports.

    Its class (``heli_common.cli_args.ArgumentParser``, inherited by every subcommand's parser)
    takes option values beginning with a minus sign (``--pos -5,3,-20``).
    """
    parser = ArgumentParser(
        prog="companion",
        description="MAVLink companion for an unmanned helicopter: plans (GART/M-GART), smooths "
        "(G1/G2 Bezier) and flies missions, and answers zenoh threats by replanning or switching.",
        epilog="Example: companion plan --world mission_files/worlds/paper_2d.toml "
        "--start 0,0 --goal 99,99 --smooth g2 --plot out/plan.png",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-vv: debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"companion.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"companion.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def configure_logging(verbosity: int) -> None:
    level = logging.WARNING - 10 * verbosity if verbosity < 3 else logging.DEBUG
    logging.basicConfig(level=max(level, logging.DEBUG), format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose + 1)
    try:
        return int(args.func(args) or 0)
    except MissingExtra as exc:  # an optional package: one line naming its extra
        print(f"companion {args.command}: {exc}", file=sys.stderr)
        return 2
    except (CompanionError, GeoError) as exc:  # GeoError: heli_common's, a ValueError
        print(f"companion: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
