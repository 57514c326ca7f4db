"""``companion plan`` through ``companion.cli.main``: JSON content, plot, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.cli import main
from companion.world import load_world

WORLD_TOML = """
[world]
name = "small"
bounds_min = [0, 0]
bounds_max = [40, 40]
margin_m = 0.5
start = [2, 2]
goal = [38, 38]

[[obstacles]]
type = "disc"
center = [20, 20]
radius = 6

[[obstacles]]
type = "box"
min = [5, 25]
max = [12, 35]
"""


@pytest.fixture()
def world_file(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(WORLD_TOML)
    return path


def test_gart_writes_json_with_a_free_path(world_file, tmp_path, capsys):
    out = tmp_path / "plan.json"
    rc = main(
        ["plan", "--world", str(world_file), "--seed", "3", "--budget", "1.0", "--json", str(out)]
    )  # a loaded machine too
    assert rc == 0
    assert "status: exact" in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["status"] == "exact" and data["planner"] == "gart" and data["seed"] == 3
    assert data["start"] == [2.0, 2.0] and data["goal"] == [38.0, 38.0]
    assert data["tree"]["nodes"] > 1 and data["tree"]["iterations"] > 0
    (entry,) = data["paths"]
    path = np.array(entry["path"])
    assert load_world(world_file).path_free(path)
    assert entry["length_m"] == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def test_mgart_with_smoothing_and_plot(world_file, tmp_path):
    out, png = tmp_path / "m.json", tmp_path / "m.png"
    rc = main(
        [
            "plan",
            "--world",
            str(world_file),
            "--planner",
            "mgart",
            "-k",
            "3",
            "--smooth",
            "g2",
            "--kappa-max",
            "0.3",
            "--budget",
            "2",
            "--start",
            "2,2",
            "--goal",
            "38,38",
            "--json",
            str(out),
            "--plot",
            str(png),
        ]
    )
    assert rc == 0
    data = json.loads(out.read_text())
    costs = [p["cost"] for p in data["paths"]]
    assert len(costs) == 3 and costs == sorted(costs)
    for p in data["paths"]:
        assert p["smoothed"]["max_curvature_1_m"] <= 0.3 * 1.001
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(
    "argv, text",
    [
        (["--start", "1,2,3"], "--start"),
        (["--goal", "a,b"], "--goal"),
        (["--goal", "100,100"], "goal"),
        (["--budget", "-1"], "--budget"),
        (["--kappa-max", "0"], "--kappa-max"),
    ],
)
def test_wrong_arguments_exit_2_with_one_line(world_file, capsys, argv, text):
    rc = main(["plan", "--world", str(world_file)] + argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and text in err and err.startswith("companion: error:")


def test_bad_world_file_exit_2_names_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        "[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'disc'\ncenter = [1, 1]\n"
    )
    assert main(["plan", "--world", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "obstacles[0].radius" in err


def test_smoothed_paths_are_timed_and_checked_on_the_closed_loop(world_file, tmp_path, capsys):
    """Issue 12: ``companion plan --json`` carries the feasibility figures; a timing too
    aggressive for the helicopter is stretched until it is feasible."""
    out = tmp_path / "f.json"
    rc = main(
        [
            "plan",
            "--world",
            str(world_file),
            "--smooth",
            "g2",
            "--kappa-max",
            "0.3",
            "--seed",
            "3",
            "--budget",
            "0.2",
            "--speed",
            "15",
            "--accel",
            "5",
            "--jerk",
            "20",
            "--json",
            str(out),
        ]
    )
    assert rc == 0
    assert "closed loop: feasible, stretch x" in capsys.readouterr().out
    smoothed = json.loads(out.read_text())["paths"][0]["smoothed"]
    f = smoothed["feasibility"]
    assert smoothed["limits"]["jerk_m_s3"] == 20.0 and smoothed["duration_s"] > 0
    assert f["initial_saturated"] and f["stretch"] > 1.0 and f["feasible"] and not f["saturated"]
    assert f["duration_s"] == pytest.approx(f["stretch"] * smoothed["duration_s"])
    assert f["max_abs_delta"] <= 0.8 and set(f["peak_abs_delta"]) == {
        "lateral_cyclic",
        "longitudinal_cyclic",
        "pedal",
        "collective",
    }
    assert 0 <= f["rms_tracking_error_m"] <= f["max_tracking_error_m"] <= 2.0 and f["check_s"] > 0
    rc = main(
        [
            "plan",
            "--world",
            str(world_file),
            "--smooth",
            "g2",
            "--kappa-max",
            "0.3",
            "--seed",
            "3",
            "--budget",
            "0.2",
            "--no-feasibility",
            "--json",
            str(out),
        ]
    )
    assert rc == 0 and json.loads(out.read_text())["paths"][0]["smoothed"]["feasibility"] is None
