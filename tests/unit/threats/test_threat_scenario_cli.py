"""Threat scenario files and the ``companion threat`` argument checks (no zenoh needed)."""

from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.threats.scenario import ScenarioError, load_scenario, scenario_from_dict

REPO = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("path", sorted((REPO / "mission_files" / "threats").glob("*.toml")))
def test_shipped_scenarios_load(path):
    scenario = load_scenario(path)
    assert scenario.events and scenario.description
    assert [e.at_s for e in scenario.events] == sorted(e.at_s for e in scenario.events)


def test_fig8_scenario_moves_at_sqrt2():
    scenario = load_scenario(REPO / "mission_files" / "threats" / "fig8_moving.toml")
    speed = np.linalg.norm(scenario.events[0].threat.velocity_ned_m_s)
    assert speed == pytest.approx(np.sqrt(2.0))


def test_move_without_pos_continues_from_where_the_threat_went():
    s = scenario_from_dict(
        {
            "event": [
                {
                    "at_s": 1.0,
                    "action": "add",
                    "id": "m",
                    "pos": [0.0, 0.0, -20.0],
                    "vel": [1.0, 0.0, 0.0],
                    "radius_m": 2.0,
                },
                {"at_s": 4.0, "action": "move", "id": "m", "vel": [0.0, 2.0, 0.0]},
                {"at_s": 5.0, "action": "remove", "id": "m"},
            ]
        }
    )
    moved = s.events[1].threat
    assert moved.position == (3.0, 0.0, -20.0) and moved.velocity_ned_m_s == (0.0, 2.0, 0.0)
    assert moved.radius_m == 2.0 and s.events[2].threat is None


@pytest.mark.parametrize(
    "event, where",
    [
        ({"at_s": 1.0, "action": "add", "id": "a", "pos": [0, 0, 0]}, "event[0].radius_m"),
        ({"at_s": 1.0, "action": "fly", "id": "a"}, "event[0].action"),
        ({"at_s": -1.0, "action": "remove", "id": "a"}, "event[0].at_s"),
        ({"at_s": 1.0, "action": "move", "id": "a", "pos": [0, 0, 0]}, "event[0].id"),
        ({"at_s": 1.0, "action": "add", "id": "a/b", "pos": [0, 0, 0], "radius_m": 1}, "event[0].id"),
        ({"at_s": 1.0, "action": "add", "id": "a", "pos": [0, 0], "radius_m": 1}, "event[0].pos"),
        ({"at_s": 1.0, "action": "add", "id": "a", "pos": [0, 0, 0], "radius_m": -1}, "radius_m"),
        ({"at_s": 1.0, "action": "add", "id": "a", "lat": 47.0, "radius_m": 1}, "event[0].lon"),
        ({"at_s": 1.0, "action": "add", "id": "a", "pos": [0, 0, 0], "radius_m": 1, "colour": 1}, "event[0].colour"),
    ],
)
def test_scenario_errors_name_the_event_and_key(event, where):
    with pytest.raises(ScenarioError, match=where.replace("[", r"\[").replace("]", r"\]")):
        scenario_from_dict({"event": [event]}, "s.toml")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["threat", "add", "--id", "a/b", "--pos", "1,2,3", "--radius", "2"], "--id"),
        (["threat", "add", "--id", "a", "--pos", "1,2", "--radius", "2"], "--pos"),
        (["threat", "add", "--id", "a", "--pos", "1,2,3", "--radius", "0"], "--radius"),
        (["threat", "add", "--id", "a", "--pos", "1,2,3", "--radius", "2", "--ttl", "-1"], "--ttl"),
        (["threat", "add", "--id", "a", "--lat", "47", "--radius", "2"], "--lat/--lon/--alt"),
        (["threat", "add", "--id", "a", "--pos", "-5,3,-20", "--vel", "-1,x,0", "--radius", "2"], "--vel"),
        (["threat", "play", "/nonexistent/s.toml"], "no such file"),
        (["threat", "list", "--scenario", "/nonexistent/s.toml"], "no such file"),
    ],
)
def test_cli_user_errors_are_one_line_exit_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("companion: error:") and message in err[0]


def test_cli_lists_a_scenario(capsys):
    assert main(["threat", "list", "--scenario", str(REPO / "mission_files/threats/demo.toml")]) == 0
    out = capsys.readouterr().out
    assert "add    popup1: popup r=5.0 m" in out and "remove mover1" in out
