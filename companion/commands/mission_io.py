"""``companion upload FILE`` and ``companion download FILE``: mission + fence + rally, like a
ground station (DESIGN.md section 9).

``upload`` reads and validates the whole file first (a broken file, an unsupported command or
a waypoint inside an exclusion zone uploads nothing), then sends
the mission (ArduPilot convention: home at seq 0), the geofence and the rally points with the
MAVLink mission protocol; a failed transfer restores the lists already replaced.
``download`` writes ``.plan`` (mission, fence, rally, home) or ``.waypoints`` (QGC WPL 110:
mission and home only) by the file's extension.
"""

from __future__ import annotations

import argparse
import asyncio
import logging

from companion.errors import LinkError

log = logging.getLogger(__name__)

DEFAULT_CONNECT = "udpin://0.0.0.0:14540"


def register(subparsers) -> None:
    upload = subparsers.add_parser(
        "upload",
        help="upload a .plan or QGC WPL 110 mission (mission, fence, rally)",
        description="Validate a mission file and upload its mission, geofence and rally points "
        "to the vehicle, like a ground station. A broken file uploads nothing.",
        epilog="Example: companion upload mission_files/exclusion_zones.plan --connect udpout://127.0.0.1:14555",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    upload.add_argument("file", help="mission file: .plan (QGroundControl) or .waypoints (QGC WPL 110)")
    add_link_arguments(upload)
    upload.set_defaults(func=run_upload)

    download = subparsers.add_parser(
        "download",
        help="download the vehicle's mission (and fence, rally) to a file",
        description="Download the vehicle's mission, geofence and rally points and write them "
        "as .plan, or the mission alone as .waypoints (QGC WPL 110), by extension.",
        epilog="Example: companion download out/onboard.plan --connect udpout://127.0.0.1:14555",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    download.add_argument("file", help="output file: .plan or .waypoints")
    add_link_arguments(download)
    download.set_defaults(func=run_download)


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--connect",
        default=DEFAULT_CONNECT,
        metavar="URL",
        help="MAVSDK connection URL: udpin://HOST:PORT (listen), "
        "udpout://HOST:PORT (send to the vehicle), tcpout://HOST:PORT, "
        f"serial:///dev/ttyUSB0:57600 (default {DEFAULT_CONNECT})",
    )
    parser.add_argument(
        "--timeout", type=float, default=15.0, metavar="S", help="seconds to wait for the vehicle (default 15)"
    )
    add_signing_argument(parser)


def add_signing_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--signing-key",
        metavar="FILE",
        help="MAVLink 2 signing key file: 64 hex digits (the 32-byte key) or a "
        "passphrase (its SHA-256, as MAVProxy's signing commands take it); "
        "sign everything sent, accept only frames signed with it",
    )


def signing_key(path: str | None):
    from companion.link.gate import SigningKey

    return SigningKey.from_file(path)  # None without --signing-key


def run_upload(args) -> int:
    from companion.link.vehicle import check_url
    from companion.mission import load_mission_file

    check_url(args.connect)
    plan = load_mission_file(args.file)  # validates everything before connecting
    asyncio.run(upload_plan(plan, args.connect, args.timeout, signing_key(args.signing_key)))
    print(
        f"uploaded {args.file}: {len(plan.items)} mission items, "
        f"{len(plan.polygons)} fence polygons, {len(plan.circles)} fence circles, "
        f"{len(plan.rally)} rally points"
    )
    return 0


def run_download(args) -> int:
    from companion.link.vehicle import check_url
    from companion.mission import mission_file_kind, save_mission_file

    check_url(args.connect)
    kind = mission_file_kind(args.file)  # bad extension: error before connecting
    plan = asyncio.run(download_plan(args.connect, args.timeout, signing_key(args.signing_key)))
    if kind == "wpl" and (plan.polygons or plan.circles or plan.rally):
        print(
            f"note: {args.file} is QGC WPL 110, which holds no geofence or rally points; use a .plan file to keep them"
        )
    save_mission_file(plan, args.file)
    print(
        f"downloaded {len(plan.items)} mission items, {len(plan.polygons)} fence polygons, "
        f"{len(plan.circles)} fence circles, {len(plan.rally)} rally points to {args.file}"
    )
    return 0


def check_flyable(plan, home_lla) -> None:
    """Reject missions the companion cannot fly (unreachable waypoints) before any upload."""
    from companion.mission import mission_to_local

    if home_lla is None:
        log.warning(
            "no home position (neither in the file nor from the vehicle): the "
            "waypoints were not checked against the exclusion zones"
        )
        return
    mission_to_local(plan, home_lla)


async def upload_plan(plan, url: str, timeout_s: float, key=None) -> None:
    from companion.link.vehicle import VehicleLink

    if plan.planned_home is not None:
        check_flyable(plan, plan.planned_home)  # before connecting: fail fast
    link = VehicleLink(role="gcs", signing_key=key)
    await link.connect(url, timeout_s=timeout_s)
    try:
        home = await home_or_none(link)
        if plan.planned_home is None:
            check_flyable(plan, home)
        await asyncio.wait_for(
            link.missions.upload_plan(plan, home_lla=plan.planned_home or home), timeout=max(timeout_s, 30.0)
        )
    except TimeoutError:
        raise LinkError("the upload did not finish in time; the vehicle keeps its previous lists") from None
    finally:
        await link.aclose()


async def download_plan(url: str, timeout_s: float, key=None):
    from companion.link.vehicle import VehicleLink

    link = VehicleLink(role="gcs", signing_key=key)
    await link.connect(url, timeout_s=timeout_s)
    try:
        return await asyncio.wait_for(link.missions.download_plan(), timeout=max(timeout_s, 30.0))
    except TimeoutError:
        raise LinkError("the download did not finish in time") from None
    finally:
        await link.aclose()


async def home_or_none(link, timeout_s: float = 2.0):
    """The vehicle's home if it reports one soon (used for the mission's seq 0)."""
    try:
        return await link.waits.wait_home(timeout_s)
    except LinkError:
        return None
