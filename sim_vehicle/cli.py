"""``sim-vehicle``: the SITL helicopter as a MAVLink vehicle on UDP (DESIGN sections 5 and 9).

Reads the settings (defaults, ``--config`` TOML, then command-line options), builds the model,
the autopilot and the MAVLink server, and runs until SIGINT or SIGTERM. A user mistake is one
line on stderr and exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import signal
import sys
from typing import NoReturn

from heli_common.cli_args import ArgumentParser

DEFAULT_HOME = (47.397742, 8.545594, 488.0, 0.0)
"""Default home: lat, lon (degrees), altitude AMSL (m), heading (degrees) - PX4's SITL field in Zurich."""

EPILOG = """\
examples:
  sim-vehicle                                   # instance 0: UDP port 14555, sysid 1,
                                                # telemetry to 127.0.0.1:14550 (GCS) and :14540 (companion)
  mavproxy.py --master=udpout:127.0.0.1:14555   # then: mode guided / arm throttle / takeoff 10
  sim-vehicle --speedup 5 --out 127.0.0.1:14560 # 5x faster, telemetry to one address only
  sim-vehicle --instance 1                      # a second vehicle: port 14565, sysid 2, telemetry
                                                # to :14550 and :14541 (companion run --instance 1)
  sim-vehicle --home 46.5197,6.6323,372,90 --wind-speed 5 --wind-dir 270 --gust 1 --tlog flight.tlog
  sim-vehicle --home -35.363261,149.165230,584,353   # ArduPilot SITL's Canberra (or --home=-35.36,...)
  sim-vehicle --origin 47.3970,8.5450,480 --adsb-traffic 3 --seed 7   # EKF origin away from home, traffic
  sim-vehicle --signing-key key.txt             # MAVLink 2 signing; MAVProxy: signing key PASSPHRASE

Any MAVLink client can also just send to the vehicle's port: it answers every peer heard in the
last 10 s. As ArduCopter, it sends nothing but HEARTBEAT until asked (SET_MESSAGE_INTERVAL,
REQUEST_DATA_STREAM). Like an ArduCopter helicopter it refuses to arm while the motor interlock
(RC8, or MAV_CMD_DO_AUX_FUNCTION 32) is engaged, which it is at start (RC8 1500 us): set it low,
arm, set it high (effective 2 s after arming), then take off; the rotor needs H_RSC_RUNUP_TIME
(10 s) to run up. MAVProxy: rc 8 1000 / arm throttle / rc 8 2000 / takeoff 10.
Modes are ArduCopter's (GUIDED 4, AUTO 3, LOITER 5, RTL 6, LAND 9, BRAKE 17).
"""

log = logging.getLogger("sim_vehicle")


class _Parser(ArgumentParser):
    """``sim-vehicle``'s parser: values such as a southern ``--home -33.8688,151.2093,20,0``
    (``heli_common.cli_args``), and an error line that points to ``--help``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _home(text: str) -> tuple[float, float, float, float]:
    parts = text.split(",")
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT[,YAW], got {text!r}")
    try:
        values = [float(p) for p in parts] + ([0.0] if len(parts) == 3 else [])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers LAT,LON,ALT[,YAW], got {text!r}") from None
    lat, lon, alt, yaw = values
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    if not -90.0 <= lat <= 90.0 or not -180.0 <= lon <= 180.0:
        raise argparse.ArgumentTypeError(f"latitude must be -90..90 and longitude -180..180, got {text!r}")
    if not -500.0 <= alt <= 9000.0:
        raise argparse.ArgumentTypeError(f"altitude must be -500..9000 m AMSL, got {alt:g}")
    return lat, lon, alt, yaw % 360.0


def _origin(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT, got {text!r}")
    lat, lon, alt, _ = _home(text)
    return lat, lon, alt


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 0 <= value <= 100:
        raise argparse.ArgumentTypeError(f"expected 0..100, got {value}")
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def _address(text: str) -> str:
    from sim_vehicle.config import parse_host_port

    try:
        parse_host_port(text, "--out")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sim-vehicle",
        description="Software-in-the-loop helicopter that speaks MAVLink like an ArduPilot helicopter "
        "(ArduCopter modes, missions, parameters) over UDP. Its flight controller is the paper's LQI "
        "on the 13-state hover model.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--instance",
        type=int,
        default=0,
        metavar="N",
        help="vehicle number: system id 1+N, default port 14555+10*N, telemetry to "
        "127.0.0.1:14550 and the companion's 127.0.0.1:<14540+N> (default 0)",
    )
    parser.add_argument(
        "--home",
        type=_home,
        default=None,
        metavar="LAT,LON,ALT,YAW",
        help="home: degrees, metres AMSL, heading in degrees (default 47.397742,8.545594,488,0: PX4's SITL field)",
    )
    parser.add_argument(
        "--origin",
        type=_origin,
        default=None,
        metavar="LAT,LON,ALT",
        help="EKF origin (GPS_GLOBAL_ORIGIN), the frame of LOCAL_POSITION_NED and "
        "SET_POSITION_TARGET_LOCAL_NED (default: the home)",
    )
    parser.add_argument(
        "--adsb-traffic",
        type=_count,
        default=None,
        metavar="N",
        help="simulate N aircraft crossing the area around home, reported as ADSB_VEHICLE when "
        "asked (SIM_ADSB_COUNT; default 0)",
    )
    parser.add_argument(
        "--speedup",
        type=_positive,
        default=None,
        metavar="X",
        help="run X times faster than real time (heartbeats stay at 1 Hz wall clock; default 1)",
    )
    parser.add_argument(
        "--out",
        type=_address,
        action="append",
        default=None,
        metavar="HOST:PORT",
        help="send telemetry to this address (repeatable; replaces the defaults "
        "127.0.0.1:14550 and 127.0.0.1:<14540+instance>)",
    )
    parser.add_argument(
        "--no-default-out",
        action="store_true",
        help="no --out addresses at all: only peers that send to the vehicle get telemetry",
    )
    parser.add_argument("--port", type=int, default=None, metavar="N", help="UDP port to bind (default 14555+10*N)")
    parser.add_argument("--bind", default=None, metavar="HOST", help="address to bind (default 0.0.0.0)")
    parser.add_argument("--profile", default=None, metavar="FILE", help="vehicle profile TOML (default: R-50-class)")
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        metavar="N",
        help="random seed of the wind gusts and the ADS-B traffic (default 0)",
    )
    parser.add_argument("--tlog", default=None, metavar="FILE", help="record all MAVLink traffic to a .tlog file")
    parser.add_argument("--wind-speed", type=_non_negative, default=None, metavar="M_S", help="steady wind speed, m/s")
    parser.add_argument(
        "--wind-dir",
        type=float,
        default=None,
        metavar="DEG",
        help="direction the wind blows FROM, degrees clockwise from north",
    )
    parser.add_argument(
        "--gust", type=_non_negative, default=None, metavar="M_S", help="gust standard deviation per axis, m/s"
    )
    parser.add_argument(
        "--physics-rate",
        type=_positive,
        default=None,
        metavar="HZ",
        help="physics rate in simulated Hz (default 400; a multiple of the 100 Hz control rate)",
    )
    parser.add_argument(
        "--signing-key",
        default=None,
        metavar="FILE",
        help="MAVLink 2 signing: the key file (64 hex digits, or a passphrase whose SHA-256 is the "
        "key, as MAVProxy's 'signing key PASSPHRASE'); sign everything sent, drop what is not "
        "signed with the key (RADIO_STATUS excepted)",
    )
    parser.add_argument(
        "--accept-signing-setup",
        action="store_true",
        help="take SETUP_SIGNING while there is no key (with a key it must be signed with it)",
    )
    parser.add_argument("--config", default=None, metavar="FILE", help="settings TOML (see sim_vehicle/config.py)")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-v debug)")
    parser.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    return parser


def _settings_from_args(args: argparse.Namespace):
    from sim_vehicle.config import LinkSettings, instance_out, load_settings, replace_path

    settings = load_settings(args.config)
    if args.speedup is not None:
        settings = replace_path(settings, "timing.speedup", args.speedup)
    if args.physics_rate is not None:
        settings = replace_path(settings, "timing.physics_rate_hz", args.physics_rate)
    if args.seed is not None:
        settings = dataclasses.replace(settings, seed=args.seed)
    if args.adsb_traffic is not None:
        settings = replace_path(settings, "adsb.count", args.adsb_traffic)
    if args.out is not None or args.no_default_out:
        settings = replace_path(settings, "link.out", tuple(args.out or ()))
    elif args.instance and settings.link.out == LinkSettings.out:  # the defaults, not a file's
        settings = replace_path(settings, "link.out", instance_out(args.instance))
    if args.bind is not None:
        settings = replace_path(settings, "link.bind_host", args.bind)
    if args.wind_speed is not None or args.wind_dir is not None or args.gust is not None:
        wind = settings.wind
        settings = dataclasses.replace(
            settings,
            wind=dataclasses.replace(
                wind,
                enabled=True,
                speed_m_s=wind.speed_m_s if args.wind_speed is None else args.wind_speed,
                from_deg=wind.from_deg if args.wind_dir is None else args.wind_dir,
                gust_m_s=wind.gust_m_s if args.gust is None else args.gust,
            ),
        )
    return settings


def _configure_logging(args: argparse.Namespace) -> None:
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose else logging.INFO)
    logging.basicConfig(level=level, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def _signing_key(path: str | None) -> bytes | None:
    """The key of ``--signing-key FILE`` (None without it); a bad file is a user mistake naming it."""
    if path is None:
        return None
    from mavlink_signing import SigningKeyError, load_key
    from sim_vehicle.config import SimConfigError

    try:
        return load_key(path)
    except SigningKeyError as exc:
        raise SimConfigError(f"--signing-key: {exc}") from None


def run(args: argparse.Namespace) -> int:
    """Build the vehicle from parsed arguments and fly until a signal arrives."""
    import numpy as np

    from heli_model.model import HeliModel, ModelError
    from sim_vehicle.adsb import TrafficModel
    from sim_vehicle.autopilot import Autopilot
    from sim_vehicle.config import SimConfigError
    from sim_vehicle.mavlink import MavlinkServer
    from sim_vehicle.realtime import RealtimeLoop

    if not 0 <= args.instance <= 200:
        raise SimConfigError(f"--instance: expected 0..200, got {args.instance}")
    signing_key = _signing_key(args.signing_key)
    try:
        settings = _settings_from_args(args)
    except ValueError as exc:
        raise SimConfigError(str(exc)) from None
    try:
        model = HeliModel.from_toml(args.profile) if args.profile else HeliModel.default()
    except ModelError as exc:
        raise SimConfigError(f"--profile: {exc}") from None
    port = args.port if args.port is not None else (settings.link.port or 14555 + 10 * args.instance)
    if not 1 <= port <= 65535:
        raise SimConfigError(f"--port: expected 1..65535, got {port}")
    home = args.home or DEFAULT_HOME
    sysid = 1 + args.instance
    if args.tlog:
        try:
            open(args.tlog, "ab").close()
        except OSError as exc:
            raise SimConfigError(f"--tlog: cannot write {args.tlog} ({exc.strerror or exc})") from None
    origin = args.origin or home[:3]
    vehicle = Autopilot(model, settings, home, np.random.default_rng(settings.seed), origin_lla=origin)
    traffic = TrafficModel(settings.adsb, np.random.default_rng([settings.seed, 0xAD5B]))
    try:
        server = MavlinkServer(
            vehicle,
            settings,
            sysid,
            port,
            tlog_path=args.tlog,
            traffic=traffic,
            signing_key=signing_key,
            accept_signing_setup=args.accept_signing_setup,
        )
    except OSError as exc:
        raise SimConfigError(f"cannot use UDP port {port} ({exc.strerror or exc}); pick another with --port") from None
    loop = RealtimeLoop(server)

    def on_signal(signum: int, frame: object) -> None:
        log.info("signal %d: shutting down", signum)
        loop.stop()

    signal.signal(signal.SIGINT, on_signal)  # from now on a signal ends the main loop cleanly
    signal.signal(signal.SIGTERM, on_signal)
    log.info(
        "vehicle '%s', home %.6f,%.6f,%.1f m, heading %.0f deg, seed %d, physics %g Hz, control %g Hz",
        model.name,
        home[0],
        home[1],
        home[2],
        home[3],
        settings.seed,
        settings.timing.physics_rate_hz,
        settings.timing.control_rate_hz,
    )
    if args.origin is not None:
        log.info(
            "EKF origin %.6f,%.6f,%.1f m: home is N %.1f E %.1f D %.1f m from it",
            *origin,
            *vehicle.frames.home_local_ned_m,
        )
    if settings.adsb.count:
        log.info(
            "ADS-B traffic: %d aircraft crossing %g m around home at %g +- %g m",
            settings.adsb.count,
            settings.adsb.radius_m,
            settings.adsb.alt_m,
            settings.adsb.alt_spread_m,
        )
    try:
        loop.run()
    finally:
        server.close()
    log.info("stopped after %.1f s of simulated time", vehicle.time_s)
    return 0


def _stop_during_startup(signum: int, frame: object) -> None:
    raise KeyboardInterrupt  # SIGTERM before the vehicle runs: leave as quietly as SIGINT does


def main(argv: list[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _stop_during_startup)
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging(args)
    from sim_vehicle.config import SimConfigError

    try:
        return run(args)
    except SimConfigError as exc:
        print(f"sim-vehicle: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        log.info("stopped during startup")
        return 0


if __name__ == "__main__":
    sys.exit(main())
