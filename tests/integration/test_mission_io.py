"""``companion upload`` / ``companion download`` against a real sim-vehicle (real MAVSDK).

One ``sim-vehicle`` on a free UDP port serves the module (each test uploads what it needs
first); the CLI connects with ``udpout://127.0.0.1:<port>`` (the vehicle answers every peer).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from companion.mission import load_mission_file
from heli_common.ports import free_port

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support import REPO_ROOT, start_sim_vehicle  # noqa: E402

pytestmark = pytest.mark.integration
SAMPLES = REPO_ROOT / "mission_files"


@pytest.fixture(scope="module")
def sim():
    with start_sim_vehicle(speedup=1.0) as vehicle:
        yield vehicle


def companion(*args: str, timeout_s: float = 90.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", *args],
        cwd=str(REPO_ROOT),
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def url(sim) -> str:
    return f"udpout://127.0.0.1:{sim.port}"


def assert_same_items(got, want):
    assert len(got) == len(want)
    for k, (a, b) in enumerate(zip(got, want)):
        assert (a.command, a.frame, a.autocontinue) == (b.command, b.frame, b.autocontinue), k
        for name in ("param1", "param2", "param3", "param4", "alt_m"):
            va, vb = getattr(a, name), getattr(b, name)
            assert (math.isnan(va) and math.isnan(vb)) or va == pytest.approx(vb, abs=1e-5), (k, name)
        assert a.lat_deg == pytest.approx(b.lat_deg, abs=1.5e-7), k
        assert a.lon_deg == pytest.approx(b.lon_deg, abs=1.5e-7), k


def assert_same_fence_and_rally(got, want):
    assert [p.inclusion for p in got.polygons] == [p.inclusion for p in want.polygons]
    for pa, pb in zip(got.polygons, want.polygons):
        assert len(pa.vertices_deg) == len(pb.vertices_deg)
        for va, vb in zip(pa.vertices_deg, pb.vertices_deg):
            assert va == pytest.approx(vb, abs=1.5e-7)
    assert len(got.circles) == len(want.circles)
    for ca, cb in zip(got.circles, want.circles):
        assert (ca.lat_deg, ca.lon_deg) == pytest.approx((cb.lat_deg, cb.lon_deg), abs=1.5e-7)
        assert ca.radius_m == pytest.approx(cb.radius_m) and ca.inclusion == cb.inclusion
    assert len(got.rally) == len(want.rally)
    for ra, rb in zip(got.rally, want.rally):
        assert (ra.lat_deg, ra.lon_deg, ra.alt_m) == pytest.approx((rb.lat_deg, rb.lon_deg, rb.alt_m), abs=1.5e-7)


def test_plan_round_trip_preserves_mission_fence_and_rally(tmp_path, sim):
    source = SAMPLES / "exclusion_zones.plan"
    up = companion("upload", str(source), "--connect", url(sim))
    assert up.returncode == 0, up.stderr + sim.log_tail()
    assert "uploaded" in up.stdout
    out = tmp_path / "onboard.plan"
    down = companion("download", str(out), "--connect", url(sim))
    assert down.returncode == 0, down.stderr
    want = load_mission_file(source)
    got = load_mission_file(out)
    assert_same_items(got.items, want.items)
    assert_same_fence_and_rally(got, want)
    assert got.planned_home == pytest.approx(want.planned_home, abs=1e-6)
    json.loads(out.read_text())  # QGroundControl-readable JSON


def test_waypoints_round_trip_and_fence_cleared(tmp_path, sim):
    # a mission with a fence first, then a .waypoints file (no fence): the fence is cleared
    assert companion("upload", str(SAMPLES / "exclusion_zones.plan"), "--connect", url(sim)).returncode == 0
    up = companion("upload", str(SAMPLES / "square.waypoints"), "--connect", url(sim))
    assert up.returncode == 0, up.stderr
    out_wpl = tmp_path / "onboard.waypoints"
    out_plan = tmp_path / "onboard.plan"
    assert companion("download", str(out_wpl), "--connect", url(sim)).returncode == 0
    assert companion("download", str(out_plan), "--connect", url(sim)).returncode == 0
    want = load_mission_file(SAMPLES / "square.waypoints")
    assert_same_items(load_mission_file(out_wpl).items, want.items)
    onboard = load_mission_file(out_plan)
    assert_same_items(onboard.items, want.items)
    assert onboard.polygons == () and onboard.circles == () and onboard.rally == ()


@pytest.mark.parametrize(
    "breakage, message",
    [
        ("json", "broken JSON at line"),
        ("command", "unsupported command"),
        ("latitude", "latitude"),
        ("inside_zone", "inside exclusion zone"),
        ("empty", "empty"),
    ],
)
def test_broken_file_uploads_nothing(tmp_path, sim, breakage, message):
    good = SAMPLES / "exclusion_zones.plan"
    doc = json.loads(good.read_text())
    if breakage == "command":
        doc["mission"]["items"][3]["command"] = 31000
    elif breakage == "latitude":
        doc["mission"]["items"][1]["params"][4] = 123.0
    elif breakage == "inside_zone":
        circle = doc["geoFence"]["circles"][0]["circle"]["center"]
        doc["mission"]["items"][1]["params"][4:6] = circle
    elif breakage == "empty":
        doc["mission"]["items"] = []
    bad = tmp_path / "bad.plan"
    text = json.dumps(doc, indent=2)
    bad.write_text(text.replace('"fileType"', '"fileType" "', 1) if breakage == "json" else text)
    assert companion("upload", str(good), "--connect", url(sim)).returncode == 0
    result = companion("upload", str(bad), "--connect", url(sim))
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    out = tmp_path / "after.plan"
    assert companion("download", str(out), "--connect", url(sim)).returncode == 0
    after = load_mission_file(out)
    want = load_mission_file(good)
    assert_same_items(after.items, want.items)
    assert_same_fence_and_rally(after, want)


def test_no_vehicle_is_a_clear_error(tmp_path):
    port = free_port()
    result = companion(
        "upload", str(SAMPLES / "square.waypoints"), "--connect", f"udpout://127.0.0.1:{port}", "--timeout", "2"
    )
    assert result.returncode == 2
    assert "no autopilot" in result.stderr and "Traceback" not in result.stderr


def test_bad_arguments_fail_before_connecting(tmp_path):
    result = companion("download", str(tmp_path / "x.kml"), "--connect", "udpin://0.0.0.0:1")
    assert result.returncode == 2 and "unknown mission file extension" in result.stderr
    result = companion("upload", str(SAMPLES / "square.waypoints"), "--connect", "14550")
    assert result.returncode == 2 and "not a MAVSDK URL" in result.stderr
    result = companion("upload", str(tmp_path / "missing.plan"))
    assert result.returncode == 2 and "does not exist" in result.stderr
