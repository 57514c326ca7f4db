"""deploy/ and docs/OPERATIONS.md: the example settings load, the systemd units' command lines are ones
`companion serve` accepts, the service never resumes by itself nor loops on a configuration error, and
the install steps parse with the CLI's own parser and make the keys the settings name before enabling."""

from __future__ import annotations

import configparser
import re
import shlex
from pathlib import Path

import pytest
from support import REPO_ROOT

from companion.cli import build_parser
from companion.config import load_settings

DEPLOY = REPO_ROOT / "deploy"


def unit(name: str = "companion.service") -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str
    parser.read_string((DEPLOY / name).read_text().replace("\\\n", " "))
    return parser


def serve_args(name: str):
    argv = shlex.split(unit(name)["Service"]["ExecStart"])
    assert argv[0] == "/opt/companion/bin/companion" and argv[1] == "serve"
    return build_parser().parse_args(argv[1:])


def install_steps() -> list[str]:
    """The commands of docs/OPERATIONS.md's install block, one per line."""
    text = (REPO_ROOT / "docs" / "OPERATIONS.md").read_text()
    section = text.split("## Install", 1)[1]
    block = re.search(r"```sh\n(.*?)```", section, re.S).group(1)
    return [line.split("#")[0].strip() for line in block.splitlines() if line.split("#")[0].strip()]


def companion_steps() -> list[list[str]]:
    return [shlex.split(line)[1:] for line in install_steps() if line.startswith("/opt/companion/bin/companion ")]


def test_the_example_settings_load_as_a_serial_helicopter_with_the_pilot_on_the_interlock():
    settings = load_settings(DEPLOY / "companion.toml", {})
    assert settings.link.connect.startswith("serial://") and settings.link.time_scale is None
    assert (settings.startup.vehicle, settings.startup.interlock) == ("helicopter", "pilot")
    assert settings.zenoh.connect and settings.adsb.enabled


def test_the_unit_runs_companion_serve_with_arguments_it_accepts():
    args = serve_args("companion.service")
    assert args.config == "/etc/companion/companion.toml" and args.record_dir and args.state_dir
    service = unit()["Service"]
    assert int(service["LimitRTPRIO"]) >= 10  # SCHED_FIFO priority 10
    assert service["KillSignal"] == "SIGTERM" and unit()["Install"]["WantedBy"] == "multi-user.target"


def test_the_service_never_resumes_by_itself():
    assert not serve_args("companion.service").resume
    assert "--resume" not in unit()["Service"]["ExecStart"]


def test_a_configuration_error_does_not_restart_the_service():
    service = unit()["Service"]
    assert service["Restart"] == "always"
    assert "2" in service["RestartPreventExitStatus"].split()


def test_resuming_is_one_explicit_start_of_the_resume_unit():
    resume = unit("companion-resume.service")
    args = serve_args("companion-resume.service")
    assert args.resume and args.flights == 1
    assert (args.config, args.state_dir) == (
        serve_args("companion.service").config,
        serve_args("companion.service").state_dir,
    )
    assert resume["Service"]["Restart"] == "no" and "Install" not in resume  # never enabled
    assert "companion.service" in resume["Unit"]["Conflicts"].split()
    assert "companion.service" in resume["Unit"]["After"].split()
    assert resume["Unit"]["OnSuccess"] == resume["Unit"]["OnFailure"] == "companion.service"
    assert "companion-resume.service" in unit()["Unit"]["Conflicts"].split()


def test_the_install_steps_parse_with_the_cli_parser():
    steps = companion_steps()
    assert steps, "no companion command in docs/OPERATIONS.md's install block"
    for argv in steps:
        build_parser().parse_args(argv)


def test_the_install_makes_the_keys_before_enabling_the_service():
    lines = install_steps()
    keys_at = next(i for i, line in enumerate(lines) if " keys init /etc/companion" in line)
    enable_at = next(i for i, line in enumerate(lines) if line.startswith("systemctl enable"))
    assert keys_at < enable_at
    assert any("deploy/companion-resume.service" in line for line in lines[:enable_at])


def test_the_install_keys_are_the_files_the_settings_name(tmp_path):
    """Run the install's `keys init` in a scratch /etc/companion: the settings' key files exist."""
    from companion.cli import main
    from mavlink_signing import load_key

    argv = next(a for a in companion_steps() if a[:2] == ["keys", "init"])
    etc = tmp_path / "etc-companion"
    etc.mkdir()
    (etc / "companion.toml").write_text((DEPLOY / "companion.toml").read_text())  # other files are fine
    assert main([arg.replace("/etc/companion", str(etc)) for arg in argv]) == 0
    settings = load_settings(DEPLOY / "companion.toml", {})
    key_file = Path(settings.link.signing_key_file)
    assert key_file.parent == Path("/etc/companion")
    assert len(load_key(etc / key_file.name)) == 32
    for line in install_steps():
        if line.startswith(("chgrp", "chmod")):
            for path in re.findall(r"/etc/companion/\S+", line):
                assert (etc / Path(path).name).is_file(), path


@pytest.mark.parametrize("name", ["companion.service", "companion-resume.service"])
def test_the_units_point_to_the_operations_page(name):
    assert "docs/OPERATIONS.md" in (DEPLOY / name).read_text()
