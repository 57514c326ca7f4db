"""Options in the natural position: shared options before or after a command's action (issue 25)."""

from __future__ import annotations

import argparse

import pytest

from companion.cli import build_parser
from heli_common.cli_args import join_negative_values


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # argparse keeps no public list of them
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_strings(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions for s in a.option_strings if s not in ("-h", "--help")}


COMMANDS = _subparsers(build_parser())
WITH_ACTIONS = {name: p for name, p in COMMANDS.items() if _subparsers(p)}


def test_the_commands_with_actions_are_checked():
    assert {"threat", "keys", "campaign", "fleet"} <= set(WITH_ACTIONS)


@pytest.mark.parametrize("name", sorted(WITH_ACTIONS))
def test_an_option_of_every_action_is_an_option_of_the_command(name):
    actions = _subparsers(WITH_ACTIONS[name]).values()
    shared = set.intersection(*(_option_strings(a) for a in actions))
    assert shared <= _option_strings(WITH_ACTIONS[name]), f"companion {name}: only after the action: {shared}"


def _parse(argv: list[str]) -> dict:
    args = vars(build_parser().parse_args(argv))
    args.pop("func")
    return args


@pytest.mark.parametrize(
    "before, action, after",
    [
        (
            ["threat", "--zenoh-config", "deploy/gcs.json5"],
            ["add", "--id", "p1", "--pos", "75,75,-20", "--radius", "5"],
            [],
        ),
        (["threat", "--sysid", "2", "--wait", "0.5", "--source", "radar1"], ["remove", "--id", "p1"], []),
        (
            ["threat", "--zenoh-connect", "tcp/10.0.0.5:7447", "--zenoh-connect", "tcp/10.0.0.6:7447"],
            ["list"],
            ["--zenoh-connect", "tcp/10.0.0.5:7447", "tcp/10.0.0.6:7447"],
        ),
        (["threat", "--zenoh-listen", "tcp/0.0.0.0:7450"], ["play", "mission_files/threats/demo.toml"], []),
        (["keys", "--source", "radar1", "--observer", "gcs", "--sysid", "3", "--force"], ["init", "out/keys"], []),
        (["fleet", "--json", "--logs", "out/fleet"], ["status"], []),
        (["fleet", "--json"], ["up", "--vehicles", "2", "--mission-dir", "mission_files/fleet/headon2"], []),
    ],
)
def test_a_shared_option_parses_the_same_before_and_after_the_action(before, action, after):
    command, options = before[0], before[1:]
    assert _parse([command, *options, *action]) == _parse([command, *action, *(after or options)])


def test_fleet_status_needs_the_router_or_the_logs(capsys):
    from companion.cli import main

    assert main(["fleet", "status"]) == 2
    assert "--router/--logs" in capsys.readouterr().err
    assert main(["fleet", "--logs", "out/x", "status", "--router", "tcp/127.0.0.1:7447"]) == 2
    assert "both" in capsys.readouterr().err


def test_a_shared_option_after_the_action_wins():
    args = build_parser().parse_args(["threat", "--sysid", "2", "list", "--sysid", "3"])
    assert args.sysid == 3


def test_the_defaults_of_shared_options_hold_when_they_are_not_given():
    args = build_parser().parse_args(["threat", "list"])
    assert (args.sysid, args.wait, args.zenoh_config, args.zenoh_listen) == (1, 3.0, None, [])
    args = build_parser().parse_args(["keys", "init", "out/keys"])
    assert (args.sysid, args.days, args.observer, args.force) == (1, 825, [], False)


def test_threat_vectors_with_a_minus_sign_are_values():
    args = build_parser().parse_args(
        ["threat", "add", "--id", "m1", "--pos", "-5,3,-20", "--vel", "-.5,1,0", "--radius", "3", "--lat", "-33.8688"]
    )
    assert (args.pos, args.vel, args.lat) == ("-5,3,-20", "-.5,1,0", -33.8688)


@pytest.mark.parametrize(
    "argv, joined",
    [
        (["--home", "-33.8,151.2,20"], ["--home=-33.8,151.2,20"]),
        (["--home", "-.5,1,2", "-v"], ["--home=-.5,1,2", "-v"]),
        (["--home=-33.8,151.2,20"], ["--home=-33.8,151.2,20"]),
        (["--home", "33.8,151.2,20"], ["--home", "33.8,151.2,20"]),
        (["--home", "-v"], ["--home", "-v"]),  # an option stays an option
        (["--flag", "-3"], ["--flag", "-3"]),  # not an option taking a value
        (["--", "--home", "-3"], ["--", "--home", "-3"]),
        (["--home"], ["--home"]),
    ],
)
def test_join_negative_values(argv, joined):
    assert join_negative_values(argv, ["--home", "-o"]) == joined


def test_run_and_serve_have_no_test_only_options(capsys):
    for command in ("run", "serve"):
        with pytest.raises(SystemExit):
            build_parser().parse_args([command, "--help"])
        assert "--fleet-delay-ms" not in capsys.readouterr().out


@pytest.mark.parametrize("value, expected", [(None, None), ("", None), ("150", 0.15), ("0", 0.0)])
def test_the_injected_fleet_delay_comes_from_the_environment(value, expected):
    from companion.commands.run import injected_fleet_delay_s

    env = {} if value is None else {"HELI_COMPANION_TEST_FLEET_DELAY_MS": value}
    assert injected_fleet_delay_s(env) == expected


@pytest.mark.parametrize("value", ["-5", "x", "nan"])
def test_a_bad_injected_fleet_delay_names_the_variable(value):
    from companion.commands.run import injected_fleet_delay_s
    from companion.errors import ConfigError

    with pytest.raises(ConfigError, match="HELI_COMPANION_TEST_FLEET_DELAY_MS"):
        injected_fleet_delay_s({"HELI_COMPANION_TEST_FLEET_DELAY_MS": value})
