"""``companion demo`` reads its mission from the package, not from the repository."""

from __future__ import annotations

import ast
from pathlib import Path

from flight_support import DEMO_MISSION

from companion import demo
from companion.mission import load_mission_file


def test_the_demo_mission_is_package_data():
    with demo.demo_mission() as path:
        assert path.is_file()
        assert Path(demo.__file__).resolve().parent / "data" in path.resolve().parents
        plan = load_mission_file(path)
        assert len(plan.items) >= 2
        assert path.read_bytes() == DEMO_MISSION.read_bytes()  # mission_files/ links to it


def test_the_demo_module_does_not_reach_for_the_repository():
    source = Path(demo.__file__).read_text()
    tree = ast.parse(source)
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert "REPO_ROOT" not in names and "PYTHONPATH" not in source and '"mission_files"' not in source
