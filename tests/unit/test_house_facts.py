"""tools/check_facts.py: each shared fact (modes, MAV_CMDs, polygon test, local frame, mission
item record) is defined once, and sim_vehicle never imports companion (issue 12)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_check_facts_passes():
    out = subprocess.run([sys.executable, str(ROOT / "tools" / "check_facts.py")], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_check_facts_finds_duplicates(tmp_path):
    """The checks fail on a tree with the old duplicates."""
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import check_facts
    finally:
        sys.path.pop(0)
    (tmp_path / "sim_vehicle").mkdir()
    (tmp_path / "companion").mkdir()
    (tmp_path / "sim_vehicle" / "autopilot.py").write_text(
        "from companion.geo import LocalFrame\nGUIDED = 4\nCMD_NAV_TAKEOFF = 22\n"
        "def point_in_polygon(p, q):\n    return False\n")
    (tmp_path / "companion" / "vehicle.py").write_text(
        'COPTER_MODES = {"GUIDED": 4}\nMAV_CMD_NAV_LAND = 21\nMAV_FRAME_LOCAL_NED = 1\n'
        "def point_in_polygon(p, q):\n    return False\nclass LocalFrame:\n    pass\n")
    results = {name: ok for name, ok, _ in check_facts.check(tmp_path)}
    assert not results["sim_vehicle and heli_common never import companion"]
    assert not results["no hand-written ArduCopter mode numbers"]
    assert not results["def point_in_polygon defined once"]
    assert not results["no hand-written MAV_CMD/MAV_FRAME/MAV_RESULT/MSG_ID integers"]
    assert results["local-frame class defined once"]          # one LocalFrame in that tree


def test_check_facts_finds_long_files_cycles_and_io_in_numerics(tmp_path):
    """The structural checks fail on a tree with a long file, an import cycle, I/O in the
    numerics and an ArduPilot number written twice; and pass once those are gone."""
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import check_facts
    finally:
        sys.path.pop(0)
    planning = tmp_path / "companion" / "planning"
    planning.mkdir(parents=True)
    (tmp_path / "sim_vehicle").mkdir()
    (tmp_path / "companion" / "__init__.py").write_text("")
    (planning / "__init__.py").write_text("from companion.planning import gart\n")
    (planning / "gart.py").write_text("import socket\nfrom . import tree\nFORCE_DISARM_MAGIC = 21196\n")
    (planning / "tree.py").write_text("from companion.planning.gart import socket\n" + "x = 1\n" * 500)
    (tmp_path / "sim_vehicle" / "rsc.py").write_text("FORCE_DISARM_MAGIC = 21196\n")
    results = {name: (ok, found) for name, ok, found in check_facts.check(tmp_path)}
    assert not results["no file over 500 lines in companion/ and sim_vehicle/"][0]
    assert results["no import cycle"] == (False, ["companion.planning.gart <-> companion.planning.tree"])
    assert results["numerics import no I/O library"] == (False, ["companion/planning/gart.py: imports socket"])
    assert not results["ArduPilot numbers pymavlink lacks written once"][0]
    (planning / "tree.py").write_text("x = 1\n")
    (planning / "gart.py").write_text("import math\nfrom . import tree\n")
    results = {name: ok for name, ok, _ in check_facts.check(tmp_path)}
    assert results["no file over 500 lines in companion/ and sim_vehicle/"]
    assert results["no import cycle"]          # a package re-exporting its submodule is no cycle
    assert results["numerics import no I/O library"]
    assert results["ArduPilot numbers pymavlink lacks written once"]
