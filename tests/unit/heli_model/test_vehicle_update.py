"""The pure vehicle update ``VehicleUpdate.update(state, command, dt) -> state`` (controller + RK4)."""

from __future__ import annotations

import numpy as np
import pytest

from heli_model import dynamics
from heli_model.control import FlightController, Setpoint
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleUpdate, substeps

CONTROL_DT_S = 0.01


@pytest.fixture(scope="module")
def vehicle() -> VehicleUpdate:
    return VehicleUpdate.build(HeliModel.default(), physics_dt_s=1.0 / 400.0)


def fly(vehicle: VehicleUpdate, state, setpoint: Setpoint, seconds: float, wind=None):
    """Control periods of the pure update; returns the final state and the positions flown, (K, 3)."""
    flown = []
    for _ in range(int(round(seconds / CONTROL_DT_S))):
        state = vehicle.update(state, VehicleCommand(setpoint, wind), CONTROL_DT_S)
        flown.append(dynamics.pos_ned_m(state.x))
    return state, np.array(flown)


def test_hover_stays_put(vehicle):
    state = vehicle.hover_state((5.0, -3.0, -10.0), 0.7)
    hold = Setpoint(pos_ned_m=(5.0, -3.0, -10.0), vel_ned_m_s=(0.0, 0.0, 0.0), yaw_rad=0.7)
    state, flown = fly(vehicle, state, hold, 20.0)
    assert np.max(np.linalg.norm(flown - [5.0, -3.0, -10.0], axis=1)) < 1e-6
    assert abs(dynamics.euler_rad(state.x)[2] - 0.7) < 1e-6
    assert np.max(np.abs(state.delta)) < 1e-6 and not state.controller.saturated


def test_step_setpoint_is_tracked_without_saturation(vehicle):
    state = vehicle.hover_state((0.0, 0.0, -10.0), 0.0)
    target = np.array([2.0, -1.0, -12.0])
    peak_delta = 0.0
    flown = []
    for _ in range(1500):
        state = vehicle.update(state, VehicleCommand(Setpoint(pos_ned_m=target, yaw_rad=0.5)), CONTROL_DT_S)
        peak_delta = max(peak_delta, float(np.max(np.abs(state.controller.delta_unclipped))))
        flown.append(dynamics.pos_ned_m(state.x))
    flown = np.array(flown)
    error_m = np.linalg.norm(flown - target, axis=1)
    assert error_m[100] > 1.5  # a ramp, not a jump (command slew limits)
    assert error_m[800] < 0.02 and error_m[-1] < 0.001  # arrived after 8 s, and stays
    assert np.max(flown[:, 0]) - target[0] < 0.05  # no overshoot
    assert np.min(flown[:, 2]) - target[2] > -0.05
    assert abs(dynamics.euler_rad(state.x)[2] - 0.5) < 0.01
    assert peak_delta < 1.0


def test_update_is_pure_and_deterministic(vehicle):
    state = vehicle.hover_state((0.0, 0.0, -10.0), 0.0)
    state, _ = fly(vehicle, state, Setpoint(pos_ned_m=(3.0, 0.0, -10.0)), 1.0)
    x_before, delta_before = state.x.copy(), state.delta.copy()
    command = VehicleCommand(Setpoint(pos_ned_m=(3.0, 1.0, -11.0)), (2.0, -1.0, 0.0))
    a = vehicle.update(state, command, CONTROL_DT_S)
    b = vehicle.update(state, command, CONTROL_DT_S)
    assert np.array_equal(state.x, x_before) and np.array_equal(state.delta, delta_before)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.delta, b.delta) and a.controller.z == b.controller.z
    assert not np.array_equal(a.x, state.x)


def test_update_equals_the_controller_and_rk4_loop(vehicle):
    """One control period of the update is the FlightController step followed by four RK4 steps, bit for bit."""
    model = vehicle.model
    controller = FlightController(model)
    x = dynamics.hover_state(model, (0.0, 0.0, -10.0), 0.2)
    controller.reset(x)
    state = vehicle.hover_state((0.0, 0.0, -10.0), 0.2)
    rng = np.random.default_rng(1)
    for k in range(300):
        sp = Setpoint(pos_ned_m=(4.0, -2.0, -11.0), vel_ned_m_s=(0.5, 0.0, 0.0), yaw_rad=0.2 + 0.002 * k)
        winds = rng.normal(0.0, 1.0, (4, 3))
        delta = controller.update(x, sp, CONTROL_DT_S)
        for i in range(4):
            x = dynamics.step_rk4(model, x, delta, 1.0 / 400.0, winds[i])
        state = vehicle.update(state, VehicleCommand(sp, winds), CONTROL_DT_S)
        assert np.array_equal(state.x, x) and np.array_equal(state.delta, delta)


def test_a_command_without_setpoint_holds_the_rotor_inputs(vehicle):
    state = vehicle.hover_state((0.0, 0.0, -10.0), 0.0)
    state = vehicle.update(state, VehicleCommand(Setpoint(pos_ned_m=(5.0, 0.0, -10.0))), 0.0025)
    held = state.delta.copy()
    assert np.max(np.abs(held)) > 0.0
    for _ in range(3):
        state = vehicle.update(state, VehicleCommand(None), 0.0025)
        assert np.array_equal(state.delta, held)


def test_ground_stops_a_descending_vehicle(vehicle):
    state = vehicle.hover_state((0.0, 0.0, -0.05), 0.0)
    state, flown = fly(vehicle, state, Setpoint(pos_ned_m=(0.0, 0.0, float("nan")), vel_ned_m_s=(0.0, 0.0, 1.0)), 1.0)
    assert np.max(flown[:, 2]) == 0.0 and state.x[16] == 0.0 and state.x[2] <= 0.0


def test_time_step_limits(vehicle):
    state = vehicle.hover_state()
    with pytest.raises(ValueError, match="dt_s"):
        vehicle.update(state, VehicleCommand(None), 0.02)
    with pytest.raises(ValueError, match="dt_s"):
        vehicle.update(state, VehicleCommand(None), 0.0)
    assert substeps(0.01, 0.0025) == 4 and substeps(0.0025, 0.0025) == 1 and substeps(0.006, 0.0025) == 3
