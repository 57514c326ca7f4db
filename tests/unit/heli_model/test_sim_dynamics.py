"""dynamics.step_rk4: hover trim, exact RK4 of the full system, order 4, saturation, lag, wind."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model import dynamics as D
from heli_model.model import HeliModel
from heli_model.wind import WindError, WindModel, WindSettings

MODEL = HeliModel.default()
LAG_MODEL = MODEL.replace(servo_tau_s=0.04)


def _textbook_rk4(f, x, h):
    k1 = f(x)
    k2 = f(x + 0.5 * h * k1)
    k3 = f(x + 0.5 * h * k2)
    k4 = f(x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def _simulate(model, x0, delta, dt, t_end):
    x = x0
    for _ in range(int(round(t_end / dt))):
        x = D.step_rk4(model, x, delta, dt)
    return x


def test_hover_with_zero_input_stays_at_rest():
    x0 = D.hover_state(MODEL, (10.0, -5.0, -20.0), yaw_rad=1.0)
    x = _simulate(MODEL, x0, np.zeros(4), 0.0025, 5.0)
    assert np.array_equal(x, x0)


def test_step_is_pure():
    x0 = D.hover_state(MODEL) + 0.1
    keep = x0.copy()
    D.step_rk4(MODEL, x0, np.array([0.2, 0.1, 0.0, -0.3]), 0.01)
    assert np.array_equal(x0, keep)


@pytest.mark.parametrize("model", [MODEL, LAG_MODEL], ids=["ideal servos", "servo lag"])
def test_step_equals_textbook_rk4_of_the_full_nonlinear_system(model):
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.3, D.state_size(model))
    x[D.IDX_PSI] = 2.5
    delta = np.array([0.4, -0.7, 0.3, 0.9])
    wind = np.array([4.0, -2.0, 0.5])
    for h in (0.0025, 0.02):
        got = D.step_rk4(model, x, delta, h, wind)
        want = _textbook_rk4(lambda y: D.derivative(model, y, delta, wind, wind_heading_rad=x[D.IDX_PSI]), x, h)
        assert np.max(np.abs(got - want)) < 1e-12


@pytest.mark.parametrize("part", ["linear", "kinematic"])
def test_rk4_converges_at_order_four(part):
    """Halving dt divides the global error by about 16 (velocities and position)."""
    rng = np.random.default_rng(7)
    x0 = D.hover_state(MODEL)
    x0[:13] = rng.normal(0.0, 0.2, 13)
    x0[5] = 1.5  # fast yaw rate: the heading rotation matters
    delta = np.array([0.3, -0.2, 0.4, -0.3])
    t_end = 0.8
    ref = _simulate(MODEL, x0, delta, 0.005 / 32, t_end)
    rows = slice(0, 13) if part == "linear" else slice(13, 17)
    errs = [np.max(np.abs(_simulate(MODEL, x0, delta, h, t_end)[rows] - ref[rows])) for h in (0.02, 0.01, 0.005)]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert all(12.0 < r < 20.0 for r in ratios), (errs, ratios)


def test_inputs_saturate_at_full_travel():
    x0 = D.hover_state(MODEL)
    a = D.step_rk4(MODEL, x0, np.array([5.0, -3.0, 2.0, -9.0]), 0.01)
    b = D.step_rk4(MODEL, x0, np.array([1.0, -1.0, 1.0, -1.0]), 0.01)
    assert np.array_equal(a, b)


def test_collective_climbs_and_yaw_integrates_to_heading():
    x = _simulate(MODEL, D.hover_state(MODEL), np.array([0.0, 0.0, 0.0, 0.2]), 0.0025, 1.0)
    assert D.vel_ned_m_s(x)[2] < -0.5  # more collective (Zcol < 0): climb (down < 0)
    x = D.hover_state(MODEL)
    x[5] = 0.5
    y = D.step_rk4(MODEL, x, np.zeros(4), 0.01)
    assert y[D.IDX_PSI] == pytest.approx(0.005, rel=0.05)


def test_servo_lag_follows_a_first_order_response():
    x = D.hover_state(LAG_MODEL)
    assert x.shape == (21,)
    cmd = np.array([0.5, 0.0, 0.0, 0.0])
    x = _simulate(LAG_MODEL, x, cmd, 0.001, LAG_MODEL.servo_tau_s)
    act = D.actuator(LAG_MODEL, x)
    assert act[0] == pytest.approx(0.5 * (1.0 - math.exp(-1.0)), rel=1e-6)
    assert act[1] == 0.0


def test_lag_model_needs_the_extended_state():
    with pytest.raises(D.DynamicsError, match="x: expected shape \\(21,\\)"):
        D.step_rk4(LAG_MODEL, np.zeros(17), np.zeros(4), 0.01)


def test_moving_with_the_air_feels_no_aerodynamic_force():
    x = D.hover_state(MODEL, yaw_rad=0.7)
    wind = np.array([3.0, -4.0, 1.0])
    x[0:3] = [math.cos(0.7) * 3.0 + math.sin(0.7) * -4.0, -math.sin(0.7) * 3.0 + math.cos(0.7) * -4.0, 1.0]
    xdot = D.derivative(MODEL, x, np.zeros(4), wind)
    assert np.max(np.abs(xdot[:13])) < 1e-12
    assert np.allclose(xdot[14:17], wind)


def test_steady_wind_pushes_a_hovering_vehicle_downwind():
    x = D.hover_state(MODEL)
    for _ in range(400):
        x = D.step_rk4(MODEL, x, np.zeros(4), 0.0025, np.array([0.0, 6.0, 0.0]))
    assert D.vel_ned_m_s(x)[1] > 0.1


@pytest.mark.parametrize(
    ("args", "name"),
    [
        ((np.zeros(16), np.zeros(4), 0.01), "x"),
        ((np.zeros(17), np.array([0.0, np.nan, 0.0, 0.0]), 0.01), "delta"),
        ((np.zeros(17), np.zeros(3), 0.01), "delta"),
        ((np.zeros(17), np.zeros(4), 0.0), "dt_s"),
        ((np.zeros(17), np.zeros(4), float("nan")), "dt_s"),
    ],
)
def test_bad_arguments_name_the_argument(args, name):
    with pytest.raises(D.DynamicsError, match=name):
        D.step_rk4(MODEL, *args)
    with pytest.raises(D.DynamicsError, match="wind"):
        D.step_rk4(MODEL, np.zeros(17), np.zeros(4), 0.01, np.array([np.inf, 0, 0]))


@settings(deadline=None, max_examples=40)
@given(yaw=st.floats(-10.0, 10.0), u=st.floats(-10.0, 10.0), v=st.floats(-10.0, 10.0))
def test_ned_velocity_is_the_body_velocity_turned_by_heading(yaw, u, v):
    x = D.hover_state(MODEL, yaw_rad=yaw)
    x[0], x[1], x[2] = u, v, 0.5
    vel = D.vel_ned_m_s(x)
    assert math.hypot(vel[0], vel[1]) == pytest.approx(math.hypot(u, v), abs=1e-9)
    assert vel[2] == 0.5
    assert -math.pi <= D.euler_rad(x)[2] <= math.pi
    # body x axis points along the heading
    x[1] = 0.0
    vel = D.vel_ned_m_s(x)
    assert vel[0] == pytest.approx(u * math.cos(yaw), abs=1e-9)
    assert vel[1] == pytest.approx(u * math.sin(yaw), abs=1e-9)


def test_gusts_are_seeded_and_have_the_requested_spread():
    wind = WindSettings((2.0, 0.0, 0.0), gust_std_m_s=1.5, gust_tau_s=0.5)
    a = WindModel(wind, np.random.default_rng(11))
    b = WindModel(wind, np.random.default_rng(11))
    sa = np.array([a.step(0.01) for _ in range(20000)])
    sb = np.array([b.step(0.01) for _ in range(20000)])
    assert np.array_equal(sa, sb)
    assert np.mean(sa[:, 0]) == pytest.approx(2.0, abs=0.3)
    assert np.std(sa[:, 1]) == pytest.approx(1.5, rel=0.2)
    calm = WindModel(WindSettings(), np.random.default_rng(0))
    assert np.array_equal(calm.step(0.01), np.zeros(3))


def test_bad_wind_settings_name_the_key():
    with pytest.raises(WindError, match="gust_std_m_s"):
        WindSettings(gust_std_m_s=-1.0)
    with pytest.raises(WindError, match="steady_ned_m_s"):
        WindSettings(steady_ned_m_s=(1.0, float("nan"), 0.0))
