"""World files: the samples load, round-trip, and every mistake names its key or line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from companion.errors import WorldError
from companion.world import Cylinder, Prism, load_world, read_world_file, world_from_dict, world_to_dict
from companion.world.io import dumps_world_toml

WORLDS = Path(__file__).resolve().parents[3] / "mission_files" / "worlds"


@pytest.mark.parametrize("name, dim", [("paper_2d.toml", 2), ("city_3d.toml", 3)])
def test_sample_worlds_load_with_free_start_and_goal(name, dim):
    wf = read_world_file(WORLDS / name)
    assert wf.world.dim == dim
    assert wf.world.is_free([wf.start, wf.goal]).all()
    assert not wf.world.segment_free(wf.start, wf.goal)  # the straight line is blocked


def test_toml_json_round_trip(tmp_path):
    world = load_world(WORLDS / "city_3d.toml")
    (tmp_path / "w.json").write_text(json.dumps(world_to_dict(world)))
    (tmp_path / "w.toml").write_text(dumps_world_toml(world))
    pts = np.random.default_rng(1).uniform(world.bounds_min, world.bounds_max, (500, 3))
    for path in (tmp_path / "w.json", tmp_path / "w.toml"):
        again = load_world(path)
        assert np.allclose(again.clearance_m(pts), world.clearance_m(pts), atol=1e-5)


def test_altitudes_map_to_down_limits():
    data = {
        "world": {"bounds_min": [0, 0, -50], "bounds_max": [50, 50, 0]},
        "obstacles": [
            {"type": "cylinder", "center": [10, 10], "radius": 2, "alt_min": 5, "alt_max": 30},
            {"type": "prism", "vertices": [[0, 0], [5, 0], [0, 5]], "down_min": -20},
        ],
    }
    cyl, prism = world_from_dict(data).world.obstacles
    assert isinstance(cyl, Cylinder) and (cyl.down_min_m, cyl.down_max_m) == (-30.0, -5.0)
    assert isinstance(prism, Prism) and prism.down_min_m == -20.0 and prism.down_max_m == np.inf


@pytest.mark.parametrize(
    "text, key",
    [
        ("[world]\nbounds_min = [0, 0]\n", "world.bounds_max"),
        ("[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\ncolour = 1\n", "world.colour"),
        ("[world]\nbounds_min = [0, 0]\nbounds_max = [10, 0]\n", "world.bounds_max"),
        ("[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\nmargin_m = -1\n", "world.margin_m"),
        (
            "[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'disc'\ncenter = [1, 1]\n",
            r"obstacles\[0\].radius",
        ),
        (
            "[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'disc'\ncenter = [1, 1]\n"
            "radius = 1\n[[obstacles]]\ntype = 'disc'\ncenter = [1, 1, 3]\nradius = 1\n",
            r"obstacles\[1\].center",
        ),
        ("[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'blob'\n", r"obstacles\[0\].type"),
        (
            "[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'disc'\ncenter = [1, 1]\n"
            "radius = 0\n",
            r"obstacles\[0\]",
        ),
        (
            "[world]\nbounds_min = [0, 0]\nbounds_max = [10, 10]\n[[obstacles]]\ntype = 'sphere'\ncenter = [1, 1, 1]\n"
            "radius = 1\n",
            r"obstacles\[0\]: Sphere",
        ),
        ("[world]\nbounds_min = = 3\n", "line 2"),
    ],
)
def test_mistakes_name_the_key_or_line(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(WorldError, match=key):
        load_world(path)


def test_json_syntax_error_names_the_line(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"world": {\n  "bounds_min": [0, 0],,\n}}')
    with pytest.raises(WorldError, match="line 2"):
        load_world(path)


def test_missing_file_is_a_world_error(tmp_path):
    with pytest.raises(WorldError, match="cannot read"):
        load_world(tmp_path / "nope.toml")
