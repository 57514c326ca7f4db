"""deploy/: the example settings load and the systemd unit's command line is one `companion serve` accepts."""

from __future__ import annotations

import configparser
import shlex

from companion.cli import build_parser
from companion.config import load_settings
from support import REPO_ROOT

DEPLOY = REPO_ROOT / "deploy"


def unit() -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str
    parser.read_string((DEPLOY / "companion.service").read_text().replace("\\\n", " "))
    return parser


def test_the_example_settings_load_as_a_serial_helicopter_with_the_pilot_on_the_interlock():
    settings = load_settings(DEPLOY / "companion.toml", {})
    assert settings.link.connect.startswith("serial://") and settings.link.time_scale is None
    assert (settings.startup.vehicle, settings.startup.interlock) == ("helicopter", "pilot")
    assert settings.zenoh.connect and settings.adsb.enabled


def test_the_unit_runs_companion_serve_with_arguments_it_accepts():
    service = unit()["Service"]
    argv = shlex.split(service["ExecStart"])
    assert argv[0].endswith("/bin/companion") and argv[1] == "serve"
    args = build_parser().parse_args(argv[1:])
    assert args.config == "/etc/companion/companion.toml" and args.resume and args.record_dir and args.state_dir
    assert service["Restart"] == "always" and int(service["LimitRTPRIO"]) >= 10   # SCHED_FIFO priority 10
    assert service["KillSignal"] == "SIGTERM" and unit()["Install"]["WantedBy"] == "multi-user.target"
