"""Issue 5 bad input: ``companion run`` refuses before takeoff and leaves the vehicle as it was.

A real ``sim-vehicle`` holds a known mission (uploaded with ``companion upload``); each bad
run must exit with one clear line, upload nothing and leave the vehicle disarmed on the ground
with the same mission.
"""

from __future__ import annotations

import json

import pytest
from flight_support import TrackListener, run_companion
from support import REPO_ROOT, start_sim_vehicle

pytestmark = pytest.mark.integration

MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
KNOWN = REPO_ROOT / "mission_files" / "square.waypoints"
HOME = (47.397742, 8.545594, 488.0)


@pytest.fixture(scope="module")
def vehicle():
    with TrackListener() as track, start_sim_vehicle(out=[track.address], speedup=2.0) as sim:
        url = f"udpout://127.0.0.1:{sim.port}"
        result = run_companion("upload", str(KNOWN), "--connect", url, timeout_s=60)
        assert result.returncode == 0, result.stderr
        yield sim, track, url


def stored_items(url: str, tmp_path) -> list:
    out = tmp_path / "stored.plan"
    result = run_companion("download", str(out), "--connect", url, timeout_s=60)
    assert result.returncode == 0, result.stderr
    return json.loads(out.read_text())["mission"]["items"]


def run_bad(url: str, *args: str):
    return run_companion("run", "--connect", url, "--no-zenoh", "--time-scale", "2", *args, timeout_s=120)


def assert_one_line_error(result, *needles: str, status: int = 2) -> None:
    assert result.returncode == status, result.stderr[-2000:]
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("companion: error:")]
    assert len(lines) == 1, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def check_untouched(vehicle, before, tmp_path) -> None:
    sim, track, url = vehicle
    assert stored_items(url, tmp_path) == before
    assert track.armed is False
    assert sim.is_running()


def test_broken_json_mission_is_refused_before_anything_is_sent(vehicle, tmp_path):
    before = stored_items(vehicle[2], tmp_path)
    broken = tmp_path / "broken.plan"
    broken.write_text(MISSION.read_text()[:-200])
    assert_one_line_error(run_bad(vehicle[2], "--mission", str(broken)), "broken.plan")
    check_untouched(vehicle, before, tmp_path)


def test_unknown_command_is_refused_naming_the_item(vehicle, tmp_path):
    before = stored_items(vehicle[2], tmp_path)
    plan = json.loads(MISSION.read_text())
    plan["mission"]["items"][1]["command"] = 31000  # not a supported MAV_CMD
    bad = tmp_path / "unknown.plan"
    bad.write_text(json.dumps(plan))
    assert_one_line_error(run_bad(vehicle[2], "--mission", str(bad)), "31000")
    check_untouched(vehicle, before, tmp_path)


def test_waypoint_inside_an_exclusion_zone_is_unreachable(vehicle, tmp_path):
    before = stored_items(vehicle[2], tmp_path)
    plan = json.loads(MISSION.read_text())
    circle = plan["geoFence"]["circles"][0]["circle"]
    lat, lon = circle["center"]
    plan["mission"]["items"][1]["params"][4:6] = [lat, lon]  # item 2 at the circle's centre
    bad = tmp_path / "inside.plan"
    bad.write_text(json.dumps(plan))
    assert_one_line_error(run_bad(vehicle[2], "--mission", str(bad)), "item 2")
    check_untouched(vehicle, before, tmp_path)


def test_latitude_out_of_range_is_refused(vehicle, tmp_path):
    before = stored_items(vehicle[2], tmp_path)
    plan = json.loads(MISSION.read_text())
    plan["mission"]["items"][1]["params"][4] = 123.0
    bad = tmp_path / "latitude.plan"
    bad.write_text(json.dumps(plan))
    assert_one_line_error(run_bad(vehicle[2], "--mission", str(bad)), "latitude")
    check_untouched(vehicle, before, tmp_path)


def test_wrong_settings_are_refused_naming_the_key(vehicle, tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text("[smoothing.limits]\nspeed_m_s = -3\n")
    assert_one_line_error(run_bad(vehicle[2], "--config", str(config)), "speed_m_s")
    config.write_text("[link]\nconect = 'udpin://0.0.0.0:1'\n")
    assert_one_line_error(run_bad(vehicle[2], "--config", str(config)), "conect")


def test_wrong_command_line_arguments_exit_2_with_usage():
    result = run_companion("run", "--time-scale", "fast")
    assert result.returncode == 2
    assert "--time-scale" in result.stderr and "Traceback" not in result.stderr


def set_param(sim, name: str, value: float) -> None:
    from support import MavlinkPeer

    with MavlinkPeer(sim.port, sim.sysid) as gcs:
        m = gcs.mavlink
        gcs.send(gcs.mav.param_set_encode(sim.sysid, 1, name.encode(), value, m.MAV_PARAM_TYPE_INT8))
        echo = gcs.wait("PARAM_VALUE", 5.0, lambda msg: msg.param_id == name)
        assert echo is not None and echo.param_value == value


def test_a_vehicle_that_refuses_to_arm_is_left_with_its_mission(vehicle, tmp_path):
    """A refusal by the vehicle is not bad input: exit status 3, the vehicle's reason in the line."""
    sim, track, url = vehicle
    before = stored_items(url, tmp_path)
    set_param(sim, "SIM_PREARM_FAIL", 1.0)
    try:
        result = run_bad(url, "--mission", str(MISSION))
    finally:
        set_param(sim, "SIM_PREARM_FAIL", 0.0)
    assert_one_line_error(result, "arm refused by the vehicle", status=3)
    assert "PreArm" in result.stderr or "DENIED" in result.stderr or "FAILED" in result.stderr
    assert json.loads(result.stdout.strip().splitlines()[-1])["outcome"].startswith("refused: arm")
    check_untouched(vehicle, before, tmp_path)
