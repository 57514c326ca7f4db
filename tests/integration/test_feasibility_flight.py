"""Issue 12 item 3 end to end: a leg whose first timing is infeasible for the helicopter is
stretched by ``companion run`` before takeoff, then flown by a real ``sim-vehicle`` process
without saturating a rotor input (the vehicle's own SERVO_OUTPUT_RAW in the flight record).

The smoothing limits are set far beyond the R-50 class (15 m/s, 5 m/s^2, 20 m/s^3): the speed
profile they give drives the longitudinal cyclic to about 2.5 times its travel on the closed
loop model.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from flight_support import TrackListener, run_companion, wait_until
from support import start_sim_vehicle

from companion.record.flight_record import load_record
from companion.record.report import servo_us_to_delta
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
# takeoff to 20 m, one 110 m leg north-east, land there
MISSION = """QGC WPL 110
0	1	0	16	0.0	0.0	0.0	0.0	47.397742	8.545594	488.0	1
1	0	3	22	0.0	0.0	0.0	0.0	0.0	0.0	20.0	1
2	0	3	16	0.0	2.0	0.0	nan	47.398642	8.546394	20.0	1
3	0	3	21	0.0	0.0	0.0	nan	47.398642	8.546394	0.0	1
"""
CONFIG = """
[smoothing.limits]
speed_m_s = 15.0
accel_m_s2 = 5.0
lat_accel_m_s2 = 6.0
jerk_m_s3 = 20.0
"""


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("feasibility_flight")
    (tmp / "leg.waypoints").write_text(MISSION)
    (tmp / "aggressive.toml").write_text(CONFIG)
    port = free_port()
    with TrackListener() as track, start_sim_vehicle(out=[f"127.0.0.1:{port}", track.address], speedup=SPEEDUP):
        result = run_companion(
            "run",
            "--connect",
            f"udpin://127.0.0.1:{port}",
            "--mission",
            str(tmp / "leg.waypoints"),
            "--config",
            str(tmp / "aggressive.toml"),
            "--time-scale",
            str(SPEEDUP),
            "--no-zenoh",
            "--record",
            str(tmp / "flight.jsonl"),
        )
        wait_until(lambda: track.armed is False, 10.0, "a disarmed heartbeat")
    assert result.returncode == 0, f"companion run failed:\n{result.stderr[-3000:]}"
    return {"result": result, "tmp": tmp, "record": load_record(tmp / "flight.jsonl")}


def test_the_infeasible_first_timing_is_stretched_before_takeoff(flight):
    (plan,) = flight["record"].plans
    f = plan["feasibility"]
    assert f["initial_saturated"] and f["initial_max_abs_delta"] > 1.0
    assert f["feasible"] and not f["saturated"] and f["stretch"] > 1.0
    assert f["max_abs_delta"] <= 0.8 and f["max_tracking_error_m"] <= 2.0
    assert any("stretched" in note for note in plan["notes"])
    summary = json.loads(flight["result"].stdout.strip().splitlines()[-1])
    assert summary["outcome"] == "completed" or summary["landed"]
    assert summary["feasibility"]["legs_stretched"] == 1 and summary["feasibility"]["legs_infeasible"] == 0


def test_the_stretched_leg_is_flown_without_saturation(flight):
    record = flight["record"]
    samples = record.samples
    servo = np.asarray(samples["servo_us"], dtype=float)
    servo = servo[np.all(np.isfinite(servo), axis=1)]
    assert len(servo) > 30  # the record's rate is in wall-clock time (speed-up 4)
    delta = np.abs(servo_us_to_delta(servo))
    assert np.max(delta) < 0.95, f"max |delta| flown {np.max(delta):.3f}"
    # the longitudinal cyclic, the channel the timing loads, peaks where the check predicted
    predicted = record.plans[0]["feasibility"]["peak_abs_delta"]["longitudinal_cyclic"]
    assert np.max(delta[:, 1]) == pytest.approx(predicted, abs=0.15)
    err = np.asarray(samples["tracking_error_m"], dtype=float)
    assert np.nanmax(err) < 2.0


def test_the_report_shows_the_feasibility_figures(flight):
    out = flight["tmp"] / "report"
    result = run_companion("report", str(flight["tmp"] / "flight.jsonl"), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "predicted max |delta|" in result.stdout and "stretch x" in result.stdout
    (leg,) = json.loads((out / "summary.json").read_text())["legs"]
    assert leg["feasibility"]["stretch"] > 1.0 and "peak_abs_delta" in leg["feasibility"]
