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
