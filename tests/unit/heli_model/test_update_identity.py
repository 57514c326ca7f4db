"""The fast vehicle update is the old one to the bit: ``VehicleUpdate.update`` and ``ControlLaw.step``
against a frozen copy of the numpy implementation (main at e984ed2), kept below.

Random states, controller states, setpoints (axes missing or NaN, yaw or yaw rate or neither),
winds (none, one, one per sub-step), time steps, both profiles (without and with servo lag) and
settings with the PID's integral and derivative terms on; single updates, and closed-loop
flights where a difference of one ulp would grow. Outputs are compared as bytes (so -0.0 is not
0.0 and a NaN must be the same NaN): one ulp anywhere fails.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from heli_model import dynamics
from heli_model.control import ControlLaw, ControllerSettings, ControllerState, Setpoint
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleState, VehicleUpdate


# ============================================================================ frozen reference
# Verbatim from main (heli_model/dynamics.py, vehicle_update.py, control/law.py, outer_loop.py,
# settings.py, lqi.py at e984ed2), names prefixed with ref_; only the module plumbing differs.
class RefDynamicsError(ValueError):
    pass


class RefControlError(ValueError):
    pass


def ref_core_matrices(model):
    A, B = model.A, model.B
    E = -A[:, 0:3]
    if model.servo_tau_s > 0.0:
        k = 1.0 / model.servo_tau_s
        n = 13 + 4
        Ac = np.zeros((n, n))
        Ac[:13, :13] = A
        Ac[:13, 13:] = B
        Ac[13:, 13:] = -k * np.eye(4)
        Bc = np.zeros((n, 4 + 3))
        Bc[13:, :4] = k * np.eye(4)
        Bc[:13, 4:] = E
    else:
        Ac = np.array(A)
        Bc = np.hstack([B, E])
    return Ac, Bc


def ref_build_rk4_matrices(model, h):
    Ac, Bc = ref_core_matrices(model)
    n, m = Bc.shape
    S1 = np.hstack([np.eye(n), np.zeros((n, m))])
    F = np.hstack([np.zeros((n, n)), Bc])

    def slope(S):
        return Ac @ S + F

    K1 = slope(S1)
    S2 = S1 + 0.5 * h * K1
    K2 = slope(S2)
    S3 = S1 + 0.5 * h * K2
    K3 = slope(S3)
    S4 = S1 + h * K3
    K4 = slope(S4)
    nxt = S1 + (h / 6.0) * (K1 + 2.0 * K2 + 2.0 * K3 + K4)
    rows = [0, 1, 2, 5]
    return np.vstack([nxt, S2[rows], S3[rows], S4[rows]])


def ref_step_rk4(M, x, delta, dt_s, wind_ned_m_s=None):
    n_total = x.shape[0]
    n_core = M.shape[1] - 7
    lag = n_core > 13
    d0, d1, d2, d3 = delta.tolist()
    if not (d0 - d0 == 0.0 and d1 - d1 == 0.0 and d2 - d2 == 0.0 and d3 - d3 == 0.0):
        raise RefDynamicsError(f"delta: expected 4 finite inputs, got {list(delta)!r}")
    d0 = -1.0 if d0 < -1.0 else (1.0 if d0 > 1.0 else d0)
    d1 = -1.0 if d1 < -1.0 else (1.0 if d1 > 1.0 else d1)
    d2 = -1.0 if d2 < -1.0 else (1.0 if d2 > 1.0 else d2)
    d3 = -1.0 if d3 < -1.0 else (1.0 if d3 > 1.0 else d3)

    psi = float(x[13])
    c1, s1 = math.cos(psi), math.sin(psi)
    vec = np.empty(n_core + 7)
    vec[:13] = x[:13]
    if lag:
        vec[13:n_core] = x[17:]
    vec[n_core] = d0
    vec[n_core + 1] = d1
    vec[n_core + 2] = d2
    vec[n_core + 3] = d3
    if wind_ned_m_s is None:
        vec[n_core + 4 :] = 0.0
    else:
        if type(wind_ned_m_s) is np.ndarray and wind_ned_m_s.shape == (3,):
            wn, we, wd = wind_ned_m_s.tolist()
        else:
            wn, we, wd = (float(v) for v in wind_ned_m_s)
        if not (wn - wn == 0.0 and we - we == 0.0 and wd - wd == 0.0):
            raise RefDynamicsError(f"wind_ned_m_s: expected 3 finite numbers, got {list(wind_ned_m_s)!r}")
        vec[n_core + 4] = c1 * wn + s1 * we
        vec[n_core + 5] = -s1 * wn + c1 * we
        vec[n_core + 6] = wd
    out = M @ vec

    u2, v2, w2, r2, u3, v3, w3, r3, u4, v4, w4, r4 = out[n_core:].tolist()
    u1, v1, w1, r1 = float(x[0]), float(x[1]), float(x[2]), float(x[5])
    h = float(dt_s)
    psi2 = psi + 0.5 * h * r1
    psi3 = psi + 0.5 * h * r2
    psi4 = psi + h * r3
    c2, s2 = math.cos(psi2), math.sin(psi2)
    c3, s3 = math.cos(psi3), math.sin(psi3)
    c4, s4 = math.cos(psi4), math.sin(psi4)
    h6 = h / 6.0
    dn = h6 * ((c1 * u1 - s1 * v1) + 2.0 * (c2 * u2 - s2 * v2) + 2.0 * (c3 * u3 - s3 * v3) + (c4 * u4 - s4 * v4))
    de = h6 * ((s1 * u1 + c1 * v1) + 2.0 * (s2 * u2 + c2 * v2) + 2.0 * (s3 * u3 + c3 * v3) + (s4 * u4 + c4 * v4))
    dd = h6 * (w1 + 2.0 * w2 + 2.0 * w3 + w4)

    x_next = np.empty(n_total)
    x_next[:13] = out[:13]
    x_next[13] = psi + h6 * (r1 + 2.0 * r2 + 2.0 * r3 + r4)
    x_next[14] = x[14] + dn
    x_next[15] = x[15] + de
    x_next[16] = x[16] + dd
    if lag:
        x_next[17:] = out[13:n_core]
    return x_next


def ref_wrap_pi(angle_rad):
    return math.remainder(angle_rad, 2.0 * math.pi)


def ref_setpoint_axes(v, name):
    if v is None:
        return None
    try:
        a, b, c = v
        a, b, c = float(a), float(b), float(c)
    except (TypeError, ValueError):
        raise RefControlError(f"setpoint.{name}: expected 3 numbers, got {v!r}") from None
    for x in (a, b, c):
        if math.isinf(x):
            raise RefControlError(f"setpoint.{name}: expected finite numbers (NaN = axis not commanded), got {v!r}")
    return a, b, c


def ref_sqrt_gain(err_m, kp, accel):
    if kp <= 0.0:
        return 0.0
    linear_m = accel / (kp * kp)
    if err_m <= linear_m:
        return kp
    return math.sqrt(2.0 * accel * (err_m - 0.5 * linear_m)) / err_m


def ref_velocity_command(st, pos_integral, x, sp, c, s):
    pos = ref_setpoint_axes(sp.pos_ned_m, "pos_ned_m")
    vel = ref_setpoint_axes(sp.vel_ned_m_s, "vel_ned_m_s")
    acc = ref_setpoint_axes(sp.acc_ned_m_s2, "acc_ned_m_s2")
    u, v, w = float(x[0]), float(x[1]), float(x[2])
    vel_now = (c * u - s * v, s * u + c * v, w)
    cmd = [0.0, 0.0, 0.0]
    acc_ff = [0.0, 0.0, 0.0]
    vel_ff = [0.0, 0.0, 0.0]
    pid_active = [False, False, False]
    p_term = ref_proportional_term(st, x, pos)
    for i in range(3):
        ki, kd = (st.ki_xy_1_s2, st.kd_xy) if i < 2 else (st.ki_z_1_s2, st.kd_z)
        v_ff = vel[i] if vel is not None and vel[i] == vel[i] else None
        a_ff = acc[i] if acc is not None and acc[i] == acc[i] else 0.0
        if pos is not None and pos[i] == pos[i]:
            vf = 0.0 if v_ff is None else v_ff
            cmd[i] = vf + p_term[i] + ki * pos_integral[i] + kd * (vf - vel_now[i])
            pid_active[i] = True
            acc_ff[i] = a_ff
            vel_ff[i] = vf
        elif v_ff is not None:
            cmd[i] = v_ff
            pos_integral[i] = 0.0
            acc_ff[i] = a_ff
            vel_ff[i] = v_ff
        else:
            pos_integral[i] = 0.0
    return cmd, acc_ff, vel_ff, pid_active, pos


def ref_proportional_term(st, x, pos):
    out = [0.0, 0.0, 0.0]
    if pos is None:
        return out
    ex = pos[0] - float(x[14]) if pos[0] == pos[0] else 0.0
    ey = pos[1] - float(x[15]) if pos[1] == pos[1] else 0.0
    gain = ref_sqrt_gain(math.hypot(ex, ey), st.kp_xy_1_s, 0.5 * st.cmd_accel_xy_m_s2)
    out[0], out[1] = gain * ex, gain * ey
    if pos[2] == pos[2]:
        ez = pos[2] - float(x[16])
        out[2] = ref_sqrt_gain(abs(ez), st.kp_z_1_s, 0.5 * st.cmd_accel_z_m_s2) * ez
    return out


def ref_limit_command(st, prev, cmd, acc_ff, dt_s):
    limited = [False, False, False]
    dx, dy, dz = cmd[0] - prev[0], cmd[1] - prev[1], cmd[2] - prev[2]
    step_xy = st.cmd_accel_xy_m_s2 * dt_s
    dh = math.hypot(dx, dy)
    if dh > step_xy:
        k = step_xy / dh
        cmd[0] = prev[0] + k * dx
        cmd[1] = prev[1] + k * dy
        limited[0] = limited[1] = True
    step_z = st.cmd_accel_z_m_s2 * dt_s
    if abs(dz) > step_z:
        cmd[2] = prev[2] + math.copysign(step_z, dz)
        limited[2] = True
    hs = math.hypot(cmd[0], cmd[1])
    if hs > st.max_speed_xy_m_s:
        k = st.max_speed_xy_m_s / hs
        cmd[0] *= k
        cmd[1] *= k
        limited[0] = limited[1] = True
    if cmd[2] < -st.max_climb_m_s:
        cmd[2] = -st.max_climb_m_s
        limited[2] = True
    elif cmd[2] > st.max_descent_m_s:
        cmd[2] = st.max_descent_m_s
        limited[2] = True
    am = math.sqrt(acc_ff[0] ** 2 + acc_ff[1] ** 2 + acc_ff[2] ** 2)
    if am > st.max_accel_m_s2:
        k = st.max_accel_m_s2 / am
        acc_ff = [a * k for a in acc_ff]
    return cmd, acc_ff, limited


def ref_heading_reference(st, yaw_ref_rad, sp, dt_s):
    lim = st.max_yaw_rate_rad_s
    rate = 0.0
    if sp.yaw_rate_rad_s is not None:
        rate = float(sp.yaw_rate_rad_s)
        if not math.isfinite(rate):
            raise RefControlError(f"setpoint.yaw_rate_rad_s: expected a finite number, got {sp.yaw_rate_rad_s!r}")
        rate = max(-lim, min(lim, rate))
    limited = False
    if sp.yaw_rad is not None:
        yaw = float(sp.yaw_rad)
        if not math.isfinite(yaw):
            raise RefControlError(f"setpoint.yaw_rad: expected a finite number, got {sp.yaw_rad!r}")
        turn = ref_wrap_pi(yaw - yaw_ref_rad)
        max_turn = lim * dt_s
        if abs(turn) > max_turn:
            yaw_ref_rad = ref_wrap_pi(yaw_ref_rad + math.copysign(max_turn, turn))
            limited = True
        else:
            yaw_ref_rad = yaw
    elif sp.yaw_rate_rad_s is not None:
        yaw_ref_rad = ref_wrap_pi(yaw_ref_rad + rate * dt_s)
    return yaw_ref_rad, rate, limited


def ref_control_law_matrix(gains):
    F = gains.ff_map
    Nx, Nd = F[:14], F[14:]
    G = Nd + gains.Kx @ Nx
    return np.hstack([G, -gains.Kx, -gains.Kz])


def ref_law_step(matrix, st, state, x, setpoint, dt_s):
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise RefControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
    psi = float(x[13])
    c, s = math.cos(psi), math.sin(psi)
    pos_integral = list(state.pos_integral_m)
    cmd, acc_ff, vel_ff, pid_active, pos = ref_velocity_command(st, pos_integral, x, setpoint, c, s)
    cmd, acc_ff, limited = ref_limit_command(st, state.cmd_prev_ned_m_s, cmd, acc_ff, dt_s)
    yaw_ref, rate_ref, yaw_limited = ref_heading_reference(st, state.yaw_ref_rad, setpoint, dt_s)
    vel_cmd = np.array(cmd)

    ub = c * cmd[0] + s * cmd[1]
    vb = -s * cmd[0] + c * cmd[1]
    wb = cmd[2]
    vfx = c * vel_ff[0] + s * vel_ff[1]
    vfy = -s * vel_ff[0] + c * vel_ff[1]
    axb = c * acc_ff[0] + s * acc_ff[1] + rate_ref * vfy
    ayb = -s * acc_ff[0] + c * acc_ff[1] - rate_ref * vfx
    azb = acc_ff[2]
    psi_err = ref_wrap_pi(psi - yaw_ref)

    vec = np.empty(matrix.shape[1])
    vec[0:8] = (axb, ayb, azb, rate_ref, ub, vb, wb, 0.0)
    vec[8 : 8 + 13] = x[:13]
    vec[8 + 13] = psi_err
    vec[8 + 14 :] = state.z
    raw = (matrix @ vec).tolist()
    delta = [(-1.0 if d < -1.0 else (1.0 if d > 1.0 else d)) for d in raw]
    saturated = any(abs(d) > 1.0 for d in raw)

    z = state.z
    if not saturated:
        z0, z1, z2, z3 = z
        if not (limited[0] or limited[1] or limited[2]):
            z0 += dt_s * (float(x[0]) - ub)
            z1 += dt_s * (float(x[1]) - vb)
            z2 += dt_s * (float(x[2]) - wb)
        if not yaw_limited:
            z3 += dt_s * psi_err
        z = (z0, z1, z2, z3)
    for i in range(3):
        if pid_active[i] and not saturated and not limited[i]:
            ki = st.ki_xy_1_s2 if i < 2 else st.ki_z_1_s2
            e = pos[i] - float(x[14 + i])
            new = pos_integral[i] + dt_s * e
            if ki > 0:
                cap = st.pos_integral_max_m_s / ki
                new = max(-cap, min(cap, new))
            pos_integral[i] = new
    return ControllerState(
        z, tuple(pos_integral), yaw_ref, tuple(cmd), np.array(delta), np.array(raw), saturated, vel_cmd
    )


def ref_stop_on_ground(x):
    if x[16] >= 0.0:
        x[16] = 0.0
        if x[2] > 0.0:
            x[2] = 0.0


class Reference(NamedTuple):
    """The frozen update for one model and controller: matrices built by the frozen code."""

    settings: ControllerSettings
    law_matrix: np.ndarray
    rk4: dict
    physics_dt_s: float
    model: HeliModel

    def update(self, state, command, dt_s):
        control_dt_s = self.settings.control_dt_s
        if not 0.0 < dt_s <= control_dt_s * (1.0 + 1e-9):
            raise RefDynamicsError(f"dt_s: expected 0 < dt_s <= the control period {control_dt_s:g} s, got {dt_s!r}")
        x, delta, controller = state
        setpoint, wind = command
        if setpoint is not None:
            controller = ref_law_step(self.law_matrix, self.settings, controller, x, setpoint, control_dt_s)
            delta = controller.delta
        n = max(1, math.ceil(dt_s / self.physics_dt_s - 1e-9))
        h = dt_s / n
        if h not in self.rk4:
            self.rk4[h] = ref_build_rk4_matrices(self.model, h)
        per_substep = wind is not None and np.ndim(wind) == 2
        for i in range(n):
            x = ref_step_rk4(self.rk4[h], x, delta, h, wind[i] if per_substep else wind)
            if x[16] >= 0.0:
                ref_stop_on_ground(x)
        return VehicleState(x, delta, controller)


# ============================================================================ comparison
def bits(value) -> bytes:
    """The float64 bytes of an array, tuple or number (the comparison that one ulp fails).

    NaNs count as one value: IEEE 754 leaves the sign and payload of a NaN to the hardware and
    the compiler (which may swap the operands of ``a + b``), and nothing reads them; a NaN
    where the reference has a number, or the other way round, still fails.
    """
    a = np.array(value, dtype=np.float64)
    a[np.isnan(a)] = np.nan
    return a.tobytes()


def assert_same_state(got: VehicleState, want: VehicleState) -> None:
    assert type(got) is VehicleState and type(got.controller) is ControllerState
    for name in ("x", "delta"):
        g, w = getattr(got, name), getattr(want, name)
        assert isinstance(g, np.ndarray) and g.dtype == w.dtype and g.shape == w.shape, name
        assert bits(g) == bits(w), f"{name}: {g!r} != {w!r}"
    assert_same_controller(got.controller, want.controller)


def assert_same_controller(got: ControllerState, want: ControllerState) -> None:
    for name in ControllerState._fields:
        g, w = getattr(got, name), getattr(want, name)
        if name == "saturated":
            assert type(g) is bool and g == w, name
        elif name in ("delta", "delta_unclipped", "vel_cmd_ned_m_s"):
            assert isinstance(g, np.ndarray) and g.dtype == w.dtype and g.shape == w.shape, name
            assert bits(g) == bits(w), f"{name}: {g!r} != {w!r}"
        else:
            assert type(g) is type(w) and bits(g) == bits(w), f"{name}: {g!r} != {w!r}"


def test_the_comparison_sees_one_ulp_and_the_sign_of_zero():
    x = np.linspace(-3.0, 3.0, 17)
    assert bits(x) == bits(x.copy())
    assert bits(x) != bits(np.nextafter(x, np.inf))
    assert bits(-0.0) != bits(0.0) and bits(np.nan) == bits(-np.nan) and bits(np.nan) != bits(np.inf)


# ============================================================================ set-up
MODEL = HeliModel.default()
LAG_MODEL = MODEL.replace(servo_tau_s=0.04)
PID_SETTINGS = ControllerSettings(ki_xy_1_s2=0.3, kd_xy=0.2, ki_z_1_s2=0.4, kd_z=0.1, pos_integral_max_m_s=0.5)


def pair(model: HeliModel, settings_: ControllerSettings | None = None, physics_dt_s: float = 1.0 / 400.0):
    vehicle = VehicleUpdate.build(model, settings_, physics_dt_s)
    law = vehicle.law
    reference = Reference(law.settings, ref_control_law_matrix(law.gains), {}, physics_dt_s, model)
    return vehicle, reference


PAIRS = {
    "default": pair(MODEL),
    "servo lag": pair(LAG_MODEL),
    "pid": pair(MODEL, PID_SETTINGS),
    "300 Hz": pair(MODEL, None, 1.0 / 300.0),
}


def test_the_matrices_are_the_frozen_ones():
    for vehicle, reference in PAIRS.values():
        assert bits(vehicle.law.matrix) == bits(reference.law_matrix)
        for h in (1.0 / 400.0, 0.01 / 3.0, 0.002):
            assert bits(dynamics.rk4_matrices(vehicle.model, h)) == bits(ref_build_rk4_matrices(vehicle.model, h))


def random_vector(rng: np.random.Generator, n: int, nan_chance: float) -> np.ndarray | None:
    v = rng.normal(0.0, 20.0, n)
    v[rng.random(n) < nan_chance] = np.nan
    return v


def random_setpoint(rng: np.random.Generator) -> Setpoint:
    """Any mix of position, velocity, acceleration (None, all axes, or NaN axes) and heading commands."""

    def maybe(scale: float, nan_chance: float):
        kind = rng.integers(4)
        if kind == 0:
            return None
        v = rng.normal(0.0, scale, 3)
        v[rng.random(3) < nan_chance] = np.nan
        return tuple(v.tolist()) if kind == 1 else v

    yaw = float(rng.uniform(-7.0, 7.0)) if rng.random() < 0.6 else None
    rate = float(rng.normal(0.0, 1.5)) if rng.random() < 0.4 else None
    return Setpoint(maybe(30.0, 0.2), maybe(6.0, 0.2), maybe(3.0, 0.2), yaw, rate)


def random_state(rng: np.random.Generator, vehicle: VehicleUpdate) -> VehicleState:
    """A state away from trim (attitudes, rates, flapping, position; sometimes on the ground) with a random controller."""
    x = vehicle.hover_state(rng.normal(0.0, 50.0, 3), float(rng.uniform(-10.0, 10.0))).x
    scale = rng.choice([1e-3, 0.1, 1.0, 5.0])
    x[:13] = rng.normal(0.0, scale, 13)
    if x.shape[0] > 17:
        x[17:] = rng.uniform(-1.2, 1.2, 4)
    if rng.random() < 0.15:
        x[16] = -abs(rng.normal(0.0, 0.01))
        x[2] = abs(x[2])
    controller = ControllerState(
        z=tuple(rng.normal(0.0, 0.3, 4).tolist()),
        pos_integral_m=tuple(rng.normal(0.0, 0.5, 3).tolist()),
        yaw_ref_rad=float(rng.uniform(-4.0, 4.0)),
        cmd_prev_ned_m_s=tuple(rng.normal(0.0, 5.0, 3).tolist()),
        delta=np.zeros(4),
        delta_unclipped=np.zeros(4),
        saturated=False,
        vel_cmd_ned_m_s=np.zeros(3),
    )
    return VehicleState(x, rng.uniform(-1.3, 1.3, 4), controller)


def random_wind(rng: np.random.Generator, n_rows: int):
    kind = rng.integers(4)
    if kind == 0:
        return None
    if kind == 1:
        return rng.normal(0.0, 6.0, 3)
    if kind == 2:
        return tuple(rng.normal(0.0, 6.0, 3).tolist())
    return rng.normal(0.0, 6.0, (n_rows, 3))


# ============================================================================ the tests
@pytest.mark.parametrize("name", sorted(PAIRS))
def test_random_single_updates_are_identical(name):
    vehicle, reference = PAIRS[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    control_dt_s = vehicle.law.settings.control_dt_s
    for _ in range(400):
        state = random_state(rng, vehicle)
        dt_s = float(rng.choice([control_dt_s, vehicle.physics_dt_s, 0.006, 0.004, rng.uniform(1e-4, control_dt_s)]))
        setpoint = random_setpoint(rng) if rng.random() < 0.85 else None
        command = VehicleCommand(setpoint, random_wind(rng, 4))
        x_before = state.x.copy()
        assert_same_state(vehicle.update(state, command, dt_s), reference.update(state, command, dt_s))
        assert bits(state.x) == bits(x_before)  # pure: the state given is not modified


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), name=st.sampled_from(sorted(PAIRS)))
def test_hypothesis_updates_are_identical(seed, name):
    vehicle, reference = PAIRS[name]
    rng = np.random.default_rng(seed)
    state = random_state(rng, vehicle)
    command = VehicleCommand(random_setpoint(rng), random_wind(rng, 4))
    dt_s = vehicle.law.settings.control_dt_s
    assert_same_state(vehicle.update(state, command, dt_s), reference.update(state, command, dt_s))


@pytest.mark.parametrize("name", sorted(PAIRS))
def test_closed_loop_flights_are_identical(name):
    """Fast-time style (a control period per update) and simulator style (a physics step per update, the
    setpoint every fourth): 10 s each with changing setpoints and gusts, compared at every update."""
    vehicle, reference = PAIRS[name]
    rng = np.random.default_rng(7 + len(name))
    control_dt_s = vehicle.law.settings.control_dt_s
    n = math.ceil(control_dt_s / vehicle.physics_dt_s - 1e-9)
    for style in ("fast time", "simulator"):
        new = old = vehicle.hover_state((0.0, 0.0, -20.0), 0.3)
        setpoint = Setpoint(pos_ned_m=(30.0, -10.0, -25.0), yaw_rad=1.0)
        for k in range(1000):
            if k % 150 == 0:
                setpoint = random_setpoint(rng)
            wind = rng.normal(0.0, 3.0, (n, 3)) if k % 2 else rng.normal(0.0, 3.0, 3)
            if style == "fast time":
                command = VehicleCommand(setpoint, wind)
                new, old = vehicle.update(new, command, control_dt_s), reference.update(old, command, control_dt_s)
                assert_same_state(new, old)
            else:
                for i in range(n):
                    command = VehicleCommand(setpoint if i == 0 else None, wind[i] if wind.ndim == 2 else wind)
                    new = vehicle.update(new, command, vehicle.physics_dt_s)
                    old = reference.update(old, command, vehicle.physics_dt_s)
                    assert_same_state(new, old)
        assert np.all(np.isfinite(new.x))


def test_law_step_alone_is_identical():
    vehicle, reference = PAIRS["pid"]
    law: ControlLaw = vehicle.law
    rng = np.random.default_rng(3)
    for _ in range(300):
        state = random_state(rng, vehicle)
        setpoint = random_setpoint(rng)
        dt_s = float(rng.uniform(1e-3, 0.05))
        x = state.x if rng.random() < 0.7 else state.x.tolist()
        got = law.step(state.controller, x, setpoint, dt_s)
        want = ref_law_step(reference.law_matrix, reference.settings, state.controller, state.x, setpoint, dt_s)
        assert_same_controller(got, want)


def test_the_numpy_path_is_identical_too(monkeypatch):
    """Where numba's BLAS would not sum like numpy's, the update falls back to the numpy code: same bits."""
    vehicle, reference = PAIRS["default"]
    rng = np.random.default_rng(11)
    cases = [(random_state(rng, vehicle), VehicleCommand(random_setpoint(rng), random_wind(rng, 4))) for _ in range(60)]
    fast = [vehicle.update(state, command, 0.01) for state, command in cases]
    monkeypatch.setattr(dynamics, "_EXACT_SHAPES", {shape: False for shape in ((25, 20), (4, 26))})
    assert dynamics.compiled_kernels((25, 20)) is None
    for (state, command), quick in zip(cases, fast):
        slow = vehicle.update(state, command, 0.01)
        assert_same_state(slow, reference.update(state, command, 0.01))
        assert_same_state(quick, slow)


def test_the_compiled_kernels_are_used_here():
    """On this machine numba's BLAS sums like numpy's: the fast path runs (else this test's speed-up is lost)."""
    assert all(dynamics.compiled_kernels(shape) is not None for shape in ((25, 20), (29, 24), (4, 26)))


def outcome(update, state, command, dt_s):
    """``("ok", state)`` or ``("raised", type, message)``."""
    try:
        return ("ok", update(state, command, dt_s))
    except Exception as exc:  # noqa: BLE001 - the comparison is the point
        return ("raised", type(exc).__bases__[-1] if type(exc).__name__.startswith("Ref") else type(exc), str(exc))


@pytest.mark.filterwarnings("ignore:.*encountered in:RuntimeWarning")  # numpy's, of the reference
@pytest.mark.parametrize("name", ["default", "servo lag"])
def test_non_finite_states_end_alike(name):
    """NaN and infinite states, inputs and winds: the same bits out (NaNs where NaNs), or the same error."""
    vehicle, reference = PAIRS[name]
    rng = np.random.default_rng(23)
    ended = set()
    for _ in range(300):
        state = random_state(rng, vehicle)
        x, delta = state.x.copy(), state.delta.copy()
        for _ in range(rng.integers(1, 3)):
            target = x if rng.random() < 0.8 else delta
            target[rng.integers(target.shape[0])] = rng.choice([np.nan, np.inf, -np.inf, 1e308])
        state = state._replace(x=x, delta=delta)
        setpoint = random_setpoint(rng) if rng.random() < 0.5 else None
        command = VehicleCommand(setpoint, random_wind(rng, 4))
        dt_s = float(rng.choice([0.01, 0.0025]))
        got, want = outcome(vehicle.update, state, command, dt_s), outcome(reference.update, state, command, dt_s)
        assert got[0] == want[0], (got, want)
        if got[0] == "ok":
            assert_same_state(got[1], want[1])
        else:
            assert issubclass(got[1], want[1]) and got[2] == want[2], (got, want)
        ended.add(got[0] if got[0] == "ok" else got[2].split(":")[0])
    assert {"ok", "delta", "math domain error"} <= ended


def test_errors_are_raised_as_before():
    vehicle, reference = PAIRS["default"]
    state = vehicle.hover_state((0.0, 0.0, -10.0))
    bad = state._replace(delta=np.array([0.0, np.nan, 0.0, 0.0]))
    for update in (vehicle.update, reference.update):
        with pytest.raises(ValueError, match="delta: expected 4 finite inputs"):
            update(bad, VehicleCommand(None), 0.01)
        with pytest.raises(ValueError, match="wind_ned_m_s: expected 3 finite numbers"):
            update(state, VehicleCommand(None, [[0.0, 0.0, 0.0], [0.0, np.inf, 0.0]] * 2), 0.01)
        with pytest.raises(ValueError, match="wind_ned_m_s: expected 3 finite numbers"):
            update(state, VehicleCommand(None, np.array([np.nan, 0.0, 0.0])), 0.0025)
        with pytest.raises(ValueError, match="setpoint.pos_ned_m"):
            update(state, VehicleCommand(Setpoint(pos_ned_m=(np.inf, 0.0, 0.0))), 0.01)
        with pytest.raises(ValueError, match="dt_s"):
            update(state, VehicleCommand(None), 0.02)
    with pytest.raises(dynamics.DynamicsError, match="x: expected shape"):
        vehicle.update(state._replace(x=np.zeros(16)), VehicleCommand(None), 0.01)
    with pytest.raises(dynamics.DynamicsError, match="wind_ned_m_s"):
        vehicle.update(state, VehicleCommand(None, np.zeros((2, 3))), 0.01)
