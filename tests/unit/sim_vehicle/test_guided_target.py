"""GUIDED pos-vel-acc targets advance between setpoints; the pre-arm fault injection."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model.control import Setpoint
from heli_model.model import HeliModel
from sim_vehicle import autopilot as ap
from sim_vehicle.autopilot import TARGET_INTEGRATION_MAX_S, Autopilot, integrate_target
from sim_vehicle.config import VehicleSettings, replace_path

HOME = (47.397742, 8.545594, 488.0, 0.0)
finite = st.floats(-20, 20)


@settings(deadline=None, max_examples=60)
@given(st.lists(finite, min_size=9, max_size=9), st.floats(0.0, 2.0))
def test_target_moves_by_velocity_and_acceleration(values, age_s):
    pos, vel, acc = (np.array(values[i : i + 3]) for i in (0, 3, 6))
    out = integrate_target(Setpoint(pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc), age_s)
    dt = min(age_s, TARGET_INTEGRATION_MAX_S)
    assert np.allclose(out.pos_ned_m, pos + vel * dt + 0.5 * acc * dt**2)
    assert np.allclose(out.vel_ned_m_s, vel + acc * dt)


def test_heading_given_with_a_rate_advances():
    sp = Setpoint(pos_ned_m=(0.0, 0.0, -10.0), vel_ned_m_s=(1.0, 0.0, 0.0), yaw_rad=0.5, yaw_rate_rad_s=0.2)
    assert integrate_target(sp, 0.25).yaw_rad == pytest.approx(0.55)


def test_uncommanded_axes_stay_uncommanded():
    sp = Setpoint(pos_ned_m=(1.0, 2.0, float("nan")), vel_ned_m_s=(1.0, 0.0, 0.0))
    out = integrate_target(sp, 0.2)
    assert np.isnan(out.pos_ned_m[2]) and out.pos_ned_m[0] == pytest.approx(1.2)
    position_only = Setpoint(pos_ned_m=(1.0, 2.0, 3.0))
    assert integrate_target(position_only, 0.2) is position_only


def test_prearm_failure_injection_refuses_to_arm():
    settings_ = replace_path(VehicleSettings(), "flight.prearm_fail", 1)
    vehicle = Autopilot(HeliModel.default(), settings_, HOME, np.random.default_rng(0))
    assert vehicle.set_mode(ap.GUIDED)[0]
    ok, reason = vehicle.arm()
    assert not ok and "PreArm" in reason and not vehicle.armed
