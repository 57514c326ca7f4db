"""Issue 5 end to end: real ``sim-vehicle`` and ``companion run`` processes over MAVLink.

The companion flies ``mission_files/exclusion_zones.plan`` (three exclusion zones between the
waypoints, RTL at the end) in GUIDED; an independent pymavlink listener records the vehicle's
own telemetry. Then the same mission is flown in AUTO (the vehicle's straight legs) and shown to
cross an exclusion zone.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from flight_support import TrackListener, run_companion, wait_until
from support import REPO_ROOT, MavlinkPeer, start_sim_vehicle

from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.world import World
from heli_common.mavlink_ids import COPTER_MODES
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
HOME = (47.397742, 8.545594, 488.0)  # sim-vehicle's default home
#: The world's safety margin (3 m) is the rotor radius plus a tracking buffer; the flown track
#: must stay clear of every zone inflated by the rotor radius (R-50 class: about 1.5 m).
ROTOR_RADIUS_M = 1.5
AUTO, GUIDED = COPTER_MODES["AUTO"], COPTER_MODES["GUIDED"]


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("companion_flight")
    port = free_port()
    with TrackListener() as track, start_sim_vehicle(out=[f"127.0.0.1:{port}", track.address], speedup=SPEEDUP) as sim:
        result = run_companion(
            "run",
            "--connect",
            f"udpin://127.0.0.1:{port}",
            "--mission",
            str(MISSION),
            "--time-scale",
            str(SPEEDUP),
            "--no-zenoh",
            "--record",
            str(tmp / "flight.jsonl"),
        )
        wait_until(lambda: track.armed is False, 10.0, "a disarmed heartbeat")
        yield {"result": result, "track": track, "sim": sim, "tmp": tmp, "n_companion": len(track.track)}


@pytest.fixture(scope="module")
def local_mission():
    return mission_to_local(load_mission_file(MISSION), HOME, dim=3)


def summary_of(result) -> dict:
    assert result.returncode == 0, f"companion run failed:\n{result.stderr[-3000:]}"
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_the_companion_completes_the_mission_and_lands(flight):
    summary = summary_of(flight["result"])
    assert summary["outcome"] == "completed"
    assert summary["legs_planned"] == summary["legs_reached"] == 5
    assert summary["landed"] is True
    assert flight["track"].armed is False
    assert abs(flight["track"].positions()[-1, 2]) < 0.3, "the vehicle is not on the ground"


def test_every_waypoint_is_reached_within_its_acceptance_radius(flight, local_mission):
    pos = flight["track"].positions()[: flight["n_companion"]]
    for wp in local_mission.waypoints:
        if wp.kind != "waypoint":
            continue
        closest = float(np.min(np.linalg.norm(pos - wp.pos_ned_m, axis=1)))
        assert closest <= wp.acceptance_radius_m, f"item {wp.seq} missed by {closest:.2f} m"


def test_the_flown_track_never_enters_an_inflated_zone(flight, local_mission):
    world = local_mission.world
    zones = World(world.obstacles, world.bounds_min, world.bounds_max, margin_m=ROTOR_RADIUS_M)
    pos = flight["track"].positions()[: flight["n_companion"]]
    airborne = pos[pos[:, 2] < -1.0]
    assert len(airborne) > 100
    clearance = zones.clearance_m(airborne)
    assert clearance.min() > 0.0, f"entered a zone: clearance {clearance.min():.2f} m"


def test_tracking_error_is_reported_and_small(flight):
    summary = summary_of(flight["result"])
    assert math.isfinite(summary["rms_tracking_error_m"])
    assert summary["rms_tracking_error_m"] < 0.6
    assert summary["max_tracking_error_m"] < 2.0


def test_the_flight_record_renders_a_report(flight):
    out = flight["tmp"] / "report"
    result = run_companion("report", str(flight["tmp"] / "flight.jsonl"), "--out", str(out))
    assert result.returncode == 0, result.stderr
    for name in ("flight_path.png", "tracking.png", "actuators.png", "summary.json"):
        assert (out / name).stat().st_size > 1000 or name == "summary.json"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rms_tracking_error_m"] < 0.6


def test_the_same_mission_in_auto_crosses_an_exclusion_zone(flight, local_mission):
    """The baseline: the vehicle's own AUTO mode flies straight legs through the zones."""
    track, sim = flight["track"], flight["sim"]
    start = len(track.track)
    with MavlinkPeer(sim.port, sim.sysid) as gcs:
        assert gcs.set_mode(AUTO).result == 0
        gcs.arm_heli()  # interlock low, arm, interlock high
        time.sleep(2.5 / SPEEDUP + 0.5)  # the interlock takes effect after the arming delay
        assert gcs.command(gcs.mavlink.MAV_CMD_MISSION_START, 0, 0).result == 0
        deadline = time.monotonic() + 240.0 / SPEEDUP + 60.0
        while time.monotonic() < deadline:
            gcs.receive(0.2)
            if track.armed is False and len(track.track) > start + 50:
                break
    pos = track.positions()[start:]
    airborne = pos[pos[:, 2] < -1.0]
    assert len(airborne) > 50, "the AUTO flight did not take off"
    inside = local_mission.world.clearance_m(airborne) < -local_mission.world.margin_m
    assert inside.any(), "the straight legs were expected to cross an exclusion zone"
