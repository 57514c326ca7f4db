"""The compiled control period is the Python one to the bit: ``ControlLaw.step`` (through
:func:`heli_model.control_kernel.law_step`) and ``VehicleUpdate.update`` against a frozen copy of the
Python step of main at 6a38544 (outer loop of ``outer_loop.py``, ``setpoint_axes``, the numpy linear
part of ``law.py``), kept below.

Also the ports of CPython's ``math.hypot`` and ``math.remainder`` and Python's ``a ** 2`` against
CPython itself. Long closed-loop flights (position steps, velocity commands, turns, yaw rates,
NaN axes, wind, PID settings, servo lag, settings that saturate the rotor) are compared at every
update; outputs are compared as bytes (one ulp, the sign of a zero, a NaN's bits all count).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model import control_kernel as kernel
from heli_model import dynamics
from heli_model.control import ControlError, ControlLaw, ControllerSettings, ControllerState, Setpoint
from heli_model.control import law as law_module
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleState, VehicleUpdate, integrate_compiled

# ============================================================================ frozen reference
# Verbatim from main at 6a38544 (heli_model/control/outer_loop.py, settings.py, law.py), names
# prefixed with ref_; the linear part is law.py's numpy law_output.
_FLOAT64 = np.dtype(np.float64)
_TWO_PI = 2.0 * math.pi
_NOT_COMMANDED = (math.nan, math.nan, math.nan)


def ref_wrap_pi(angle_rad):
    return math.remainder(angle_rad, _TWO_PI)


def ref_setpoint_axes(v, name):
    if v is None:
        return None
    if type(v) is np.ndarray and v.dtype is _FLOAT64 and v.shape == (3,):
        a, b, c = v.tolist()
    else:
        try:
            a, b, c = v
            a, b, c = float(a), float(b), float(c)
        except (TypeError, ValueError):
            raise ControlError(f"setpoint.{name}: expected 3 numbers, got {v!r}") from None
    if a * 0.0 + b * 0.0 + c * 0.0 != 0.0:
        for x in (a, b, c):
            if math.isinf(x):
                raise ControlError(f"setpoint.{name}: expected finite numbers (NaN = axis not commanded), got {v!r}")
    return a, b, c


def ref_sqrt_gain(err_m, kp, accel):
    if kp <= 0.0:
        return 0.0
    linear_m = accel / (kp * kp)
    if err_m <= linear_m:
        return kp
    return math.sqrt(2.0 * accel * (err_m - 0.5 * linear_m)) / err_m


def ref_velocity_command(st_, pos_integral, x, sp, c, s):
    pos = ref_setpoint_axes(sp.pos_ned_m, "pos_ned_m")
    vel = ref_setpoint_axes(sp.vel_ned_m_s, "vel_ned_m_s")
    acc = ref_setpoint_axes(sp.acc_ned_m_s2, "acc_ned_m_s2")
    u, v, w = x[0], x[1], x[2]
    vel_now = (c * u - s * v, s * u + c * v, w)
    cmd = [0.0, 0.0, 0.0]
    acc_ff = [0.0, 0.0, 0.0]
    vel_ff = [0.0, 0.0, 0.0]
    pid_active = [False, False, False]
    p_term = ref_proportional_term(st_, x, pos)
    ki_xy, kd_xy = st_.ki_xy_1_s2, st_.kd_xy
    pos_axes = _NOT_COMMANDED if pos is None else pos
    vel_axes = _NOT_COMMANDED if vel is None else vel
    acc_axes = _NOT_COMMANDED if acc is None else acc
    for i in range(3):
        p, v_ff, a_ff = pos_axes[i], vel_axes[i], acc_axes[i]
        if p == p:
            ki, kd = (ki_xy, kd_xy) if i < 2 else (st_.ki_z_1_s2, st_.kd_z)
            vf = v_ff if v_ff == v_ff else 0.0
            cmd[i] = vf + p_term[i] + ki * pos_integral[i] + kd * (vf - vel_now[i])
            pid_active[i] = True
            acc_ff[i] = a_ff if a_ff == a_ff else 0.0
            vel_ff[i] = vf
        elif v_ff == v_ff:
            cmd[i] = v_ff
            pos_integral[i] = 0.0
            acc_ff[i] = a_ff if a_ff == a_ff else 0.0
            vel_ff[i] = v_ff
        else:
            pos_integral[i] = 0.0
    return cmd, acc_ff, vel_ff, pid_active, pos


def ref_proportional_term(st_, x, pos):
    out = [0.0, 0.0, 0.0]
    if pos is None:
        return out
    p0, p1, p2 = pos
    ex = p0 - x[14] if p0 == p0 else 0.0
    ey = p1 - x[15] if p1 == p1 else 0.0
    gain = ref_sqrt_gain(math.hypot(ex, ey), st_.kp_xy_1_s, 0.5 * st_.cmd_accel_xy_m_s2)
    out[0], out[1] = gain * ex, gain * ey
    if p2 == p2:
        ez = p2 - x[16]
        out[2] = ref_sqrt_gain(abs(ez), st_.kp_z_1_s, 0.5 * st_.cmd_accel_z_m_s2) * ez
    return out


def ref_limit_command(st_, prev, cmd, acc_ff, dt_s):
    limited = [False, False, False]
    dx, dy, dz = cmd[0] - prev[0], cmd[1] - prev[1], cmd[2] - prev[2]
    step_xy = st_.cmd_accel_xy_m_s2 * dt_s
    dh = math.hypot(dx, dy)
    if dh > step_xy:
        k = step_xy / dh
        cmd[0] = prev[0] + k * dx
        cmd[1] = prev[1] + k * dy
        limited[0] = limited[1] = True
    step_z = st_.cmd_accel_z_m_s2 * dt_s
    if abs(dz) > step_z:
        cmd[2] = prev[2] + math.copysign(step_z, dz)
        limited[2] = True
    hs = math.hypot(cmd[0], cmd[1])
    if hs > st_.max_speed_xy_m_s:
        k = st_.max_speed_xy_m_s / hs
        cmd[0] *= k
        cmd[1] *= k
        limited[0] = limited[1] = True
    if cmd[2] < -st_.max_climb_m_s:
        cmd[2] = -st_.max_climb_m_s
        limited[2] = True
    elif cmd[2] > st_.max_descent_m_s:
        cmd[2] = st_.max_descent_m_s
        limited[2] = True
    if acc_ff[0] or acc_ff[1] or acc_ff[2]:
        am = math.sqrt(acc_ff[0] ** 2 + acc_ff[1] ** 2 + acc_ff[2] ** 2)
        if am > st_.max_accel_m_s2:
            k = st_.max_accel_m_s2 / am
            acc_ff = [a * k for a in acc_ff]
    return cmd, acc_ff, limited


def ref_heading_reference(st_, yaw_ref_rad, sp, dt_s):
    lim = st_.max_yaw_rate_rad_s
    rate = 0.0
    if sp.yaw_rate_rad_s is not None:
        rate = float(sp.yaw_rate_rad_s)
        if not math.isfinite(rate):
            raise ControlError(f"setpoint.yaw_rate_rad_s: expected a finite number, got {sp.yaw_rate_rad_s!r}")
        rate = rate if rate < lim else lim
        rate = rate if rate > -lim else -lim
    limited = False
    if sp.yaw_rad is not None:
        yaw = float(sp.yaw_rad)
        if not math.isfinite(yaw):
            raise ControlError(f"setpoint.yaw_rad: expected a finite number, got {sp.yaw_rad!r}")
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


def ref_law_output(
    L,
    x,
    c,
    s,
    cmd0,
    cmd1,
    cmd2,
    vf0,
    vf1,
    a0,
    a1,
    a2,
    rate_ref,
    psi_err,
    z0,
    z1,
    z2,
    z3,
    dt_s,
    integrate_vel,
    integrate_yaw,
    delta,
    raw,
):
    ub = c * cmd0 + s * cmd1
    vb = -s * cmd0 + c * cmd1
    wb = cmd2
    vfx = c * vf0 + s * vf1
    vfy = -s * vf0 + c * vf1
    axb = c * a0 + s * a1 + rate_ref * vfy
    ayb = -s * a0 + c * a1 - rate_ref * vfx
    vec = np.empty(L.shape[1])
    vec[0:8] = (axb, ayb, a2, rate_ref, ub, vb, wb, 0.0)
    vec[8 : 8 + 13] = x[:13]
    vec[8 + 13] = psi_err
    vec[8 + 14 :] = (z0, z1, z2, z3)
    raw[:] = L @ vec
    unclipped = raw.tolist()
    delta[:] = [(-1.0 if d < -1.0 else (1.0 if d > 1.0 else d)) for d in unclipped]
    saturated = any(abs(d) > 1.0 for d in unclipped)
    if not saturated:
        if integrate_vel:
            z0 += dt_s * (float(x[0]) - ub)
            z1 += dt_s * (float(x[1]) - vb)
            z2 += dt_s * (float(x[2]) - wb)
        if integrate_yaw:
            z3 += dt_s * psi_err
    return saturated, (z0, z1, z2, z3)


def ref_step(matrix, st_, state, x, setpoint, dt_s):
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise ControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
    if type(x) is not np.ndarray or x.dtype is not _FLOAT64:
        x = np.asarray(x, dtype=float)
    xl = x.tolist()
    psi = xl[13]
    c, s = math.cos(psi), math.sin(psi)
    pos_integral = list(state.pos_integral_m)
    cmd, acc_ff, vel_ff, pid_active, pos = ref_velocity_command(st_, pos_integral, xl, setpoint, c, s)
    cmd, acc_ff, limited = ref_limit_command(st_, state.cmd_prev_ned_m_s, cmd, acc_ff, dt_s)
    yaw_ref, rate_ref, yaw_limited = ref_heading_reference(st_, state.yaw_ref_rad, setpoint, dt_s)
    psi_err = ref_wrap_pi(psi - yaw_ref)
    cmd0, cmd1, cmd2 = cmd
    z0, z1, z2, z3 = state.z
    delta, raw = np.empty(4), np.empty(4)
    saturated, z = ref_law_output(
        matrix,
        x,
        c,
        s,
        cmd0,
        cmd1,
        cmd2,
        vel_ff[0],
        vel_ff[1],
        acc_ff[0],
        acc_ff[1],
        acc_ff[2],
        rate_ref,
        psi_err,
        z0,
        z1,
        z2,
        z3,
        float(dt_s),
        not (limited[0] or limited[1] or limited[2]),
        not yaw_limited,
        delta,
        raw,
    )
    if saturated:
        z = state.z
    else:
        for i in range(3):
            if pid_active[i] and not limited[i]:
                new = pos_integral[i] + dt_s * (pos[i] - xl[14 + i])
                ki = st_.ki_xy_1_s2 if i < 2 else st_.ki_z_1_s2
                if ki > 0:
                    cap = st_.pos_integral_max_m_s / ki
                    new = max(-cap, min(cap, new))
                pos_integral[i] = new
    cmd = (cmd0, cmd1, cmd2)
    return ControllerState(z, tuple(pos_integral), yaw_ref, cmd, delta, raw, saturated, np.array(cmd))


def ref_update(vehicle: VehicleUpdate, state: VehicleState, command: VehicleCommand, dt_s: float) -> VehicleState:
    """``VehicleUpdate.update`` with the frozen law and the (already verified) compiled integration."""
    law = vehicle.law
    x, delta, controller = state
    setpoint, wind = command
    if setpoint is not None:
        controller = ref_step(law.matrix, law.settings, controller, x, setpoint, law.settings.control_dt_s)
        delta = controller.delta
    n = math.ceil(dt_s / vehicle.physics_dt_s - 1e-9)
    h = dt_s / n
    M = dynamics.rk4_matrices(vehicle.model, h)
    x = integrate_compiled(dynamics.compiled_kernels(M.shape), vehicle.model, M, x, delta, h, n, wind)
    return VehicleState(x, delta, controller)


# ============================================================================ comparison
def bits(value) -> bytes:
    """The exact bits of a float, a tuple of floats or an array (bools and ints as themselves)."""
    if isinstance(value, np.ndarray):
        return b"a" + value.dtype.str.encode() + repr(value.shape).encode() + value.tobytes()
    if isinstance(value, tuple):
        return b"t(" + b",".join(bits(v) for v in value) + b")"
    if isinstance(value, bool):
        return b"b1" if value else b"b0"
    return b"f" + np.float64(value).tobytes() + type(value).__name__.encode()


def assert_same_controller(got: ControllerState, want: ControllerState) -> None:
    for name, g, w in zip(ControllerState._fields, got, want):
        assert bits(g) == bits(w), (name, g, w)


def assert_same_state(got: VehicleState, want: VehicleState) -> None:
    assert bits(got.x) == bits(want.x) and bits(got.delta) == bits(want.delta)
    assert_same_controller(got.controller, want.controller)


def test_the_comparison_sees_one_ulp_the_sign_of_zero_and_the_type():
    assert bits(1.0) != bits(np.nextafter(1.0, 2.0)) and bits(0.0) != bits(-0.0) and bits(1.0) != bits(1)
    assert bits((1.0, 2.0)) == bits((1.0, 2.0)) and bits(np.zeros(3)) != bits(np.zeros(4))


# ============================================================================ the ported functions
SPECIAL = [
    0.0,
    -0.0,
    math.nan,
    -math.nan,
    math.inf,
    -math.inf,
    5e-324,
    -5e-324,
    2.2250738585072014e-308,
    1e-310,
    1.7976931348623157e308,
    1e154,
    1e-154,
    1.0,
    -1.0,
    3.0,
    4.0,
    math.pi,
    -math.pi,
]


def wide_floats(rng: np.random.Generator, n: int) -> np.ndarray:
    """Normal deviates scaled over the whole exponent range, sometimes near a few magnitudes of the flights."""
    v = rng.normal(size=n) * 10.0 ** rng.uniform(-320.0, 308.0, size=n)
    near = rng.random(n) < 0.5
    v[near] = rng.normal(size=near.sum()) * 10.0 ** rng.uniform(-8.0, 3.0, size=near.sum())
    return v


def test_hypot_is_cpythons():
    rng = np.random.default_rng(1)
    xs, ys = wide_floats(rng, 40000), wide_floats(rng, 40000)
    with np.errstate(over="ignore"):
        ys[::3] = xs[::3] * 10.0 ** rng.uniform(-20.0, 20.0, size=ys[::3].shape)  # comparable sizes
    pairs = list(zip(xs.tolist(), ys.tolist())) + [(a, b) for a in SPECIAL for b in SPECIAL]
    for a, b in pairs:
        assert bits(kernel.py_hypot(a, b)) == bits(math.hypot(a, b)), (a, b)


def test_remainder_is_cpythons():
    rng = np.random.default_rng(2)
    values = (
        wide_floats(rng, 40000).tolist()
        + [k * math.pi for k in range(-40, 41)]
        + [k * math.pi + d for k in range(-9, 10) for d in (-1e-15, 1e-15)]
        + [v for v in SPECIAL if not math.isinf(v)]
    )
    for a in values:
        assert bits(kernel.py_remainder(a, 2.0 * math.pi)) == bits(math.remainder(a, 2.0 * math.pi)), a


def test_square_is_pythons():
    rng = np.random.default_rng(3)
    for a in wide_floats(rng, 40000).tolist() + [v for v in SPECIAL if math.isfinite(v)]:
        try:
            want = a**2
        except OverflowError:
            assert math.isinf(kernel.py_square(a, 2.0)), a
            continue
        assert bits(kernel.py_square(a, 2.0)) == bits(want), a


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True))
def test_hypothesis_hypot_and_remainder(a, b):
    assert bits(kernel.py_hypot(a, b)) == bits(math.hypot(a, b))
    if not math.isinf(a):
        assert bits(kernel.py_remainder(a, 2.0 * math.pi)) == bits(math.remainder(a, 2.0 * math.pi))


# ============================================================================ set-up
MODEL = HeliModel.default()
PID = ControllerSettings(ki_xy_1_s2=0.3, kd_xy=0.2, ki_z_1_s2=0.4, kd_z=0.1, pos_integral_max_m_s=0.5)
HARSH = ControllerSettings(
    kp_xy_1_s=3.0,
    kp_z_1_s=3.0,
    max_speed_xy_m_s=40.0,
    max_climb_m_s=15.0,
    max_descent_m_s=15.0,
    max_accel_m_s2=30.0,
    cmd_accel_xy_m_s2=60.0,
    cmd_accel_z_m_s2=40.0,
    max_yaw_rate_rad_s=4.0,
    ki_xy_1_s2=0.5,
    ki_z_1_s2=0.5,
)
"""Gains and limits that drive the rotor inputs into saturation on steps."""
VEHICLES = {
    "default": VehicleUpdate.build(MODEL),
    "pid": VehicleUpdate.build(MODEL, PID),
    "servo lag": VehicleUpdate.build(MODEL.replace(servo_tau_s=0.04), PID),
    "harsh": VehicleUpdate.build(MODEL, HARSH),
}


def random_setpoint(rng: np.random.Generator) -> Setpoint:
    """Any mix of vectors (None, arrays, tuples, lists; NaN axes) and heading commands (heading, rate, both, neither)."""

    def maybe(scale: float):
        kind = rng.integers(5)
        if kind == 0:
            return None
        v = rng.normal(0.0, scale, 3)
        v[rng.random(3) < 0.2] = np.nan
        return (v, v, tuple(v.tolist()), v.tolist())[kind - 1]

    yaw = float(rng.uniform(-7.0, 7.0)) if rng.random() < 0.6 else None
    rate = float(rng.normal(0.0, 2.0)) if rng.random() < 0.4 else None
    return Setpoint(maybe(40.0), maybe(8.0), maybe(6.0), yaw, rate)


def random_controller(rng: np.random.Generator, x: np.ndarray) -> ControllerState:
    return ControllerState(
        z=tuple(rng.normal(0.0, 0.3, 4).tolist()),
        pos_integral_m=tuple(rng.normal(0.0, 2.0, 3).tolist()),
        yaw_ref_rad=float(rng.uniform(-4.0, 4.0)),
        cmd_prev_ned_m_s=tuple(rng.normal(0.0, 8.0, 3).tolist()),
        delta=np.zeros(4),
        delta_unclipped=np.zeros(4),
        saturated=False,
        vel_cmd_ned_m_s=np.zeros(3),
    )


def random_x(rng: np.random.Generator, vehicle: VehicleUpdate) -> np.ndarray:
    x = vehicle.hover_state(rng.normal(0.0, 50.0, 3), float(rng.uniform(-10.0, 10.0))).x
    x[:13] = rng.normal(0.0, rng.choice([0.0, 1e-4, 1e-3, 0.01, 0.1, 1.0, 5.0]), 13)
    if x.shape[0] > 17:
        x[17:] = rng.uniform(-1.2, 1.2, 4)
    return x


# ============================================================================ the law alone
@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_random_steps_are_identical(name):
    law: ControlLaw = VEHICLES[name].law
    rng = np.random.default_rng(len(name))
    saturated = 0
    for _ in range(1500):
        x = random_x(rng, VEHICLES[name])
        state = random_controller(rng, x)
        setpoint = (
            random_setpoint(rng) if rng.random() < 0.7 else Setpoint(pos_ned_m=x[14:17] + rng.normal(0.0, 0.1, 3))
        )
        if rng.random() < 0.5:
            state = state._replace(z=(0.0, 0.0, 0.0, 0.0), cmd_prev_ned_m_s=(0.0, 0.0, 0.0), yaw_ref_rad=float(x[13]))
        dt_s = float(rng.choice([0.01, rng.uniform(1e-3, 0.05)]))
        got = law.step(state, x, setpoint, dt_s)
        assert_same_controller(got, ref_step(law.matrix, law.settings, state, x, setpoint, dt_s))
        saturated += got.saturated
    assert 50 < saturated < 1450, saturated  # both branches seen


def test_the_kernel_runs_for_the_usual_arguments(monkeypatch):
    """Arrays, tuples, lists, None and NaN axes all go through the kernel (the Python step is not called)."""
    law = VEHICLES["pid"].law
    calls = []
    monkeypatch.setattr(ControlLaw, "step_python", lambda *args: calls.append(args))
    rng = np.random.default_rng(5)
    for _ in range(200):
        x = random_x(rng, VEHICLES["pid"])
        assert law.step(random_controller(rng, x), x, random_setpoint(rng), 0.01) is not None
    assert calls == []


def outcome(step, *args):
    try:
        return ("ok", step(*args))
    except Exception as exc:  # noqa: BLE001 - the comparison is the point
        return ("raised", type(exc), str(exc))


def test_where_python_raises_it_still_raises_the_same():
    """Infinite headings, setpoints and references, squares that overflow, bad vectors: the same error."""
    law = VEHICLES["default"].law
    rng = np.random.default_rng(9)
    x0 = random_x(rng, VEHICLES["default"])
    base = random_controller(rng, x0)
    x_inf = x0.copy()
    x_inf[13] = math.inf
    cases = [
        (base, x_inf, Setpoint(pos_ned_m=(1.0, 2.0, 3.0))),
        (base, x0, Setpoint(pos_ned_m=np.array([math.inf, 0.0, 0.0]))),
        (base, x0, Setpoint(vel_ned_m_s=(0.0, -math.inf, 0.0))),
        (base, x0, Setpoint(acc_ned_m_s2=[1e200, 0.0, 0.0], vel_ned_m_s=(1.0, 0.0, 0.0))),
        (base, x0, Setpoint(pos_ned_m=(1.0, 2.0))),
        (base, x0, Setpoint(pos_ned_m="abc")),
        (base, x0, Setpoint(yaw_rad=math.inf)),
        (base, x0, Setpoint(yaw_rad=math.nan)),
        (base, x0, Setpoint(yaw_rate_rad_s=-math.inf)),
        (base, x0, Setpoint(yaw_rad="north")),
        (base._replace(yaw_ref_rad=math.inf), x0, Setpoint(yaw_rad=1.0)),
        (base._replace(yaw_ref_rad=math.inf), x0, Setpoint(yaw_rate_rad_s=0.5)),
        (base._replace(yaw_ref_rad=math.inf), x0, Setpoint()),
        (base._replace(yaw_ref_rad=1e308), x0, Setpoint(yaw_rad=-1e308)),
        (base._replace(z=(0.0, 0.0)), x0, Setpoint()),
        (base, x0[:16], Setpoint()),
        (base, x0.reshape(17, 1), Setpoint()),
    ]
    raised = 0
    for state, x, setpoint in cases:
        got = outcome(law.step, state, x, setpoint, 0.01)
        want = outcome(ref_step, law.matrix, law.settings, state, x, setpoint, 0.01)
        assert got[0] == want[0], (got, want)
        if got[0] == "ok":
            assert_same_controller(got[1], want[1])
        else:
            assert got[1:] == want[1:], (got, want)
        raised += got[0] == "raised"
    assert raised >= len(cases) - 2  # the overflowing square and the NaN reference's heading step need not raise


@pytest.mark.filterwarnings("ignore:.*encountered in:RuntimeWarning")  # numpy's, of the reference
def test_non_finite_states_are_identical():
    law = VEHICLES["pid"].law
    rng = np.random.default_rng(10)
    for _ in range(400):
        x = random_x(rng, VEHICLES["pid"])
        state = random_controller(rng, x)
        x[rng.integers(17)] = rng.choice([np.nan, np.inf, -np.inf, 1e308])
        if rng.random() < 0.3:
            state = state._replace(
                yaw_ref_rad=float(rng.choice([np.nan, 1e308])),
                cmd_prev_ned_m_s=(float(rng.choice([np.nan, 1e308, 0.0])), 0.0, 0.0),
            )
        setpoint = random_setpoint(rng)
        got = outcome(law.step, state, x, setpoint, 0.01)
        want = outcome(ref_step, law.matrix, law.settings, state, x, setpoint, 0.01)
        assert got[0] == want[0], (got, want)
        if got[0] == "ok":
            assert_same_controller(got[1], want[1])
        else:
            assert got[1:] == want[1:]


def test_settings_given_as_ints_run_the_python_step():
    law = ControlLaw(MODEL, ControllerSettings(kp_xy_1_s=2, max_speed_xy_m_s=5))
    rng = np.random.default_rng(12)
    for _ in range(50):
        x = random_x(rng, VEHICLES["default"])
        state, setpoint = random_controller(rng, x), random_setpoint(rng)
        assert_same_controller(
            law.step(state, x, setpoint, 0.01), ref_step(law.matrix, law.settings, state, x, setpoint, 0.01)
        )


def test_replaced_settings_are_read_again():
    law = ControlLaw(MODEL)
    x = VEHICLES["default"].hover_state().x
    setpoint = Setpoint(pos_ned_m=(100.0, 0.0, 0.0))
    law.settings = HARSH
    state = law.reset(x)
    assert_same_controller(law.step(state, x, setpoint, 0.01), ref_step(law.matrix, HARSH, state, x, setpoint, 0.01))


def test_the_numpy_path_is_identical_too(monkeypatch):
    law = VEHICLES["pid"].law
    rng = np.random.default_rng(13)
    cases = []
    for _ in range(100):
        x = random_x(rng, VEHICLES["pid"])
        cases.append((random_controller(rng, x), x, random_setpoint(rng)))
    monkeypatch.setattr(dynamics, "_EXACT_SHAPES", {(4, 26): False})
    for state, x, setpoint in cases:
        assert_same_controller(
            law.step(state, x, setpoint, 0.01), ref_step(law.matrix, law.settings, state, x, setpoint, 0.01)
        )
    assert law_module._KERNEL  # and the kernel was loaded beforehand (the compiled path ran)


# ============================================================================ closed loop
def flight_setpoints(rng: np.random.Generator, k: int, t_s: float) -> Setpoint:
    """A schedule: position steps with headings, a circle with feed-forward, velocity commands with a yaw
    rate, NaN axes (landing-like), a far target (speed limits), then random setpoints."""
    phase = (k // 400) % 6
    if phase == 0:
        return Setpoint(pos_ned_m=np.array([30.0, -10.0, -25.0]), yaw_rad=1.0)
    if phase == 1:
        w = 5.0 / 30.0
        return Setpoint(
            np.array([30.0 * math.cos(w * t_s), 30.0 * math.sin(w * t_s), -20.0]),
            np.array([-5.0 * math.sin(w * t_s), 5.0 * math.cos(w * t_s), 0.0]),
            np.array([-5.0 * w * math.cos(w * t_s), -5.0 * w * math.sin(w * t_s), 0.0]),
            w * t_s + math.pi / 2.0,
            w,
        )
    if phase == 2:
        return Setpoint(vel_ned_m_s=np.array([4.0, -2.0, 0.5]), yaw_rate_rad_s=0.8)
    if phase == 3:
        return Setpoint(pos_ned_m=(0.0, 0.0, math.nan), vel_ned_m_s=(0.0, 0.0, 1.0), yaw_rad=-2.5)
    if phase == 4:
        return Setpoint(pos_ned_m=[800.0, 600.0, -80.0], acc_ned_m_s2=[3.0, -4.0, 9.0], yaw_rad=3.1)
    return random_setpoint(rng)


@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_closed_loop_flights_are_identical(name):
    """2400 control periods each, fast-time style (a period per update) and simulator style (a physics step
    per update, the setpoint every fourth), with gusts: compared at every update."""
    vehicle = VEHICLES[name]
    rng = np.random.default_rng(100 + len(name))
    control_dt_s = vehicle.law.settings.control_dt_s
    n = math.ceil(control_dt_s / vehicle.physics_dt_s - 1e-9)
    saturated = limited = 0
    for style in ("fast time", "simulator"):
        new = old = vehicle.hover_state((0.0, 0.0, -20.0), 0.3)
        setpoint = flight_setpoints(rng, 0, 0.0)
        for k in range(2400 if style == "fast time" else 800):
            if k % 20 == 0:
                setpoint = flight_setpoints(rng, k, k * control_dt_s)
            wind = None if k % 3 == 0 else (rng.normal(0.0, 3.0, (n, 3)) if k % 3 == 1 else rng.normal(0.0, 3.0, 3))
            if style == "fast time":
                command = VehicleCommand(setpoint, wind)
                new, old = vehicle.update(new, command, control_dt_s), ref_update(vehicle, old, command, control_dt_s)
                assert_same_state(new, old)
            else:
                for i in range(n):
                    w = wind[i] if wind is not None and wind.ndim == 2 else wind
                    command = VehicleCommand(setpoint if i == 0 else None, w)
                    new = vehicle.update(new, command, vehicle.physics_dt_s)
                    old = ref_update(vehicle, old, command, vehicle.physics_dt_s)
                    assert_same_state(new, old)
            saturated += new.controller.saturated
            limited += new.controller.cmd_prev_ned_m_s != tuple(new.controller.vel_cmd_ned_m_s.tolist())
        assert np.all(np.isfinite(new.x))
    if name == "harsh":
        assert saturated > 20
    assert limited == 0  # vel_cmd and cmd_prev agree (both the limited command)
