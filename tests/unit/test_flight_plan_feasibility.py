"""Issue 12 item 3: every planned leg is checked on the helicopter's closed loop and its timing
stretched where it is not feasible; the stretched leg is then flown by the full nonlinear
vehicle (RK4 physics, the sim-vehicle's LQI flight controller) without saturating."""

import numpy as np
import pytest

from companion.errors import SmoothingError
from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.plan import FlightPlanSettings, plan_leg, plan_mission
from companion.mission.model import LocalWaypoint
from companion.planning import GartSettings
from companion.smoothing import SmoothingSettings, TrajectoryLimits
from companion.smoothing.feasibility import CHANNELS, FeasibilityChecker
from companion.smoothing.settings import FeasibilitySettings
from companion.world import World
from heli_model import dynamics as D
from heli_model.control import FlightController, Setpoint
from heli_model.model import HeliModel

WORLD = World([], np.array([-50.0, -50.0, -60.0]), np.array([150.0, 150.0, 0.0]), 3.0)
GOAL = LocalWaypoint(seq=2, kind="waypoint", pos_ned_m=np.array([80.0, 30.0, -20.0]), acceptance_radius_m=2.0)
START = np.array([0.0, 0.0, -15.0])  # a 5 m descent, then the level part
AGGRESSIVE = SmoothingSettings(
    limits=TrajectoryLimits(speed_m_s=15.0, accel_m_s2=5.0, lat_accel_m_s2=6.0, jerk_m_s3=20.0)
)
CONTROL_DT, PHYSICS_DT = 1.0 / 100.0, 1.0 / 400.0


@pytest.fixture(scope="module")
def checker():
    return FeasibilityChecker(HeliModel.default())


def pipeline(smoothing, checker=None):
    return TrajectoryPipeline.from_settings(smoothing, GartSettings(kappa_max_1_m=0.1), closed_loop=checker)


def leg(smoothing, checker=None, seed=3):
    return plan_leg(
        0,
        GOAL,
        START,
        WORLD,
        pipeline=pipeline(smoothing, checker),
        settings=FlightPlanSettings(),
        rng=np.random.default_rng(seed),
    )


def fly(trajectory, hold_s=2.0):
    """The full loop on ``trajectory`` (a TrajectoryChain): controller at 100 Hz, RK4 at 400 Hz.
    Returns (max tracking error m, max raw |delta|, saturated)."""
    model = HeliModel.default()
    t = np.arange(0.0, trajectory.duration_s + hold_s, CONTROL_DT)
    pos, vel, acc = trajectory.sample(t)
    yaw, rate = trajectory.yaw_rad(t), trajectory.yaw_rate_rad_s(t)
    done = t > trajectory.duration_s
    vel[done], acc[done], rate[done] = 0.0, 0.0, 0.0
    fc = FlightController(model)
    x = D.hover_state(model, pos[0], yaw[0])
    fc.reset(x)
    err, max_raw, saturated = 0.0, 0.0, False
    for k in range(t.size):
        delta = fc.update(x, Setpoint(pos[k], vel[k], acc[k], yaw[k], rate[k]), CONTROL_DT)
        max_raw = max(max_raw, float(np.max(np.abs(fc.delta_unclipped))))
        saturated |= bool(fc.saturated)
        for _ in range(4):
            x = D.step_rk4(model, x, delta, PHYSICS_DT, None)
        err = max(err, float(np.linalg.norm(x[14:17] - pos[min(k + 1, t.size - 1)])))
    return err, max_raw, saturated


def test_a_gentle_leg_is_checked_and_left_as_it_is(checker):
    plain = leg(SmoothingSettings())
    checked = leg(SmoothingSettings(), checker)
    f = checked.feasibility
    assert plain.feasibility is None
    assert f["feasible"] and f["stretch"] == 1.0 and not f["saturated"] and not f["initial_saturated"]
    assert checked.trajectory.duration_s == pytest.approx(plain.trajectory.duration_s)
    assert len(f["pieces"]) == 2  # the descent and the level part
    assert set(f["peak_abs_delta"]) == set(CHANNELS)
    assert f["max_abs_delta"] == pytest.approx(max(f["peak_abs_delta"].values()), abs=0.01)
    assert 0 < f["max_abs_delta"] < 0.8 and 0 < f["rms_tracking_error_m"] <= f["max_tracking_error_m"] < 2.0
    assert f["check_s"] > 0 and f["reason"] == ""
    assert not any("feasibility" in n for n in checked.notes)


def test_an_infeasible_first_timing_is_stretched_then_flown_without_saturation(checker):
    first = leg(AGGRESSIVE)  # the timing as the limits give it
    checked = leg(AGGRESSIVE, checker)
    f = checked.feasibility
    assert f["initial_saturated"] and f["initial_max_abs_delta"] > 1.0
    assert f["feasible"] and not f["saturated"] and f["stretch"] > 1.0
    assert f["max_abs_delta"] <= 0.8 and f["max_tracking_error_m"] <= 2.0
    assert checked.trajectory.duration_s > first.trajectory.duration_s
    np.testing.assert_allclose(checked.trajectory.end_pos_ned_m, first.trajectory.end_pos_ned_m, atol=1e-6)
    assert any("stretched" in n for n in checked.notes)
    # the full nonlinear loop: the first timing drives the rotor inputs to full travel (the
    # flight controller's own limits keep them just inside it) and the vehicle falls far
    # behind; the stretched timing is tracked with inputs well inside their travel
    err_first, raw_first, sat_first = fly(first.trajectory)
    err, raw, sat = fly(checked.trajectory)
    assert raw_first > 0.95 and (sat_first or err_first > 5.0)
    assert not sat and raw < 0.9 and raw == pytest.approx(f["max_abs_delta"], abs=0.1)
    assert err < 2.0


def test_plan_mission_checks_every_leg(checker):
    from types import SimpleNamespace

    back = LocalWaypoint(seq=3, kind="waypoint", pos_ned_m=np.array([0.0, 60.0, -20.0]), acceptance_radius_m=2.0)
    mission = SimpleNamespace(waypoints=(GOAL, back), world=WORLD)
    legs = plan_mission(
        mission,
        START,
        pipeline=pipeline(AGGRESSIVE, checker),
        settings=FlightPlanSettings(),
        rng=np.random.default_rng(1),
    )
    assert len(legs) == 2 and all(lg.feasibility["feasible"] for lg in legs)
    assert all(lg.feasibility["stretch"] > 1.0 for lg in legs)


def test_enabled_must_be_a_boolean():
    assert FeasibilitySettings().enabled is True
    with pytest.raises(SmoothingError, match="feasibility.enabled"):
        FeasibilitySettings(enabled="yes")


def test_no_feasibility_option_turns_the_check_off(capsys):
    import json

    from companion.cli import main

    assert main(["run", "--no-feasibility", "--print-config", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["feasibility"]["enabled"] is False


def test_the_flight_report_lists_each_legs_figures(checker, tmp_path):
    from companion.daemon import feasibility_totals
    from companion.record.flight_record import FlightRecord
    from companion.record.report import leg_feasibility, summary_text

    legs = [leg(AGGRESSIVE, checker), leg(SmoothingSettings(), checker), leg(SmoothingSettings())]
    totals = feasibility_totals(legs)
    assert totals["legs_checked"] == 2 and totals["legs_stretched"] == 1 and totals["legs_infeasible"] == 0
    record = FlightRecord()
    record.plans = [
        {"leg": 0, "seq": 2, "duration_s": legs[0].trajectory.duration_s, "feasibility": legs[0].feasibility},
        {"leg": 1, "seq": 3, "duration_s": 1.0, "feasibility": None},
    ]
    rows = leg_feasibility(record)
    assert "pieces" not in rows[0]["feasibility"] and rows[1]["feasibility"] is None
    text = summary_text({"outcome": "completed", "legs_planned": 2, "legs_reached": 2}, rows)
    assert "leg 0 (item 2): feasible, stretch x" in text and "(saturates)" in text
    assert "leg 1 (item 3): not checked" in text
