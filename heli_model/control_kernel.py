"""Compiled kernels of the control law (numba): one control period in one call, and its linear part.

:func:`law_step` is :meth:`heli_model.control.law.ControlLaw.step` after its argument checks:
the PID position loop with its feed-forward (:func:`heli_model.control.outer_loop.velocity_command`),
the command limits (:func:`~heli_model.control.outer_loop.limit_command`), the heading
reference (:func:`~heli_model.control.outer_loop.heading_reference`), the linear part
(:func:`law_output`: references in body axes, ``delta = L @ [ref8, x14_err, z]``, clipping, the
LQI integrators) and the position integrators. It gives, bit for bit, what the Python code gives:

* every expression is the Python code's, in the same order, with the same grouping; numba
  compiles without fast-math, so LLVM neither reassociates nor fuses a multiply and an add;
* the functions of CPython's ``math`` that are not the C library's are ported from CPython 3.11's
  ``Modules/mathmodule.c``: ``math.hypot`` (CPython's own ``vector_norm``, not libm's ``hypot``:
  ``heli_common.pyfloat.py_hypot``) and :func:`py_remainder` (``math.remainder``, ``m_remainder``, on the exact
  ``fmod``); ``math.cos``, ``math.sin`` and ``pow`` (for Python's ``a ** 2``, through
  :func:`py_square` with the exponent given at run time so that LLVM does not turn it into
  ``a * a``) are the C library's, the functions CPython calls;
* ``min`` and ``max`` are CPython's for two floats (``heli_common.pyfloat``; NaN kept the same way);
* the matrix-vector product is ``np.dot`` (BLAS's ``dgemv``), which
  :func:`heli_model.dynamics.compiled_kernels` checks against numpy's ``@`` per shape.

Where the Python code raises (an infinite heading for ``math.cos``, an infinite angle for
``math.remainder``, an infinite setpoint entry, a square that overflows) the kernel returns
:data:`FALL_BACK` instead, and the caller runs the Python code, which raises as it always did.

This module imports numba: import it lazily (:meth:`heli_model.control.law.ControlLaw.step`
does), so that importing :mod:`heli_model` stays cheap. The kernels compile on their first call
and stay in numba's cache (``cache=True``, beside this file) for the next processes; every
compiled function they call is in this file, so that numba's cache sees a change to any of them.

Shapes: ``P`` (:data:`N_PARAMS`,) from :func:`pack_settings`; ``L`` (4, 26) from
:func:`heli_model.control.lqi.control_law_matrix`; ``x`` (17,) or (21,); setpoint vectors (3,).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from heli_common.pyfloat import py_hypot, py_max, py_min

__all__ = [
    "FALL_BACK",
    "N_PARAMS",
    "OK",
    "SETTINGS_FIELDS",
    "law_output",
    "law_step",
    "pack_settings",
    "py_hypot",
    "py_remainder",
    "py_square",
]

N_STATES = 13
"""Hover-model states (:data:`heli_model.model.N_STATES`)."""

OK = 0
"""Status of :func:`law_step`: the outputs are the control period's."""
FALL_BACK = 1
"""Status of :func:`law_step`: the Python code would raise here (outputs undefined): run it."""

SETTINGS_FIELDS = (
    "kp_xy_1_s",
    "ki_xy_1_s2",
    "kd_xy",
    "kp_z_1_s",
    "ki_z_1_s2",
    "kd_z",
    "pos_integral_max_m_s",
    "max_speed_xy_m_s",
    "max_climb_m_s",
    "max_descent_m_s",
    "max_accel_m_s2",
    "cmd_accel_xy_m_s2",
    "cmd_accel_z_m_s2",
    "max_yaw_rate_rad_s",
)
"""The :class:`~heli_model.control.settings.ControllerSettings` the kernel reads, in the order of ``P``."""
(
    _KP_XY,
    _KI_XY,
    _KD_XY,
    _KP_Z,
    _KI_Z,
    _KD_Z,
    _POS_INT_MAX,
    _MAX_SPEED_XY,
    _MAX_CLIMB,
    _MAX_DESCENT,
    _MAX_ACCEL,
    _CMD_ACCEL_XY,
    _CMD_ACCEL_Z,
    _MAX_YAW_RATE,
    _TWO,
) = range(len(SETTINGS_FIELDS) + 1)
N_PARAMS = len(SETTINGS_FIELDS) + 1
"""Length of ``P``: the settings, then the exponent 2.0 of :func:`py_square`."""

_TWO_PI = 2.0 * math.pi


def pack_settings(settings) -> np.ndarray | None:
    """``P`` for :func:`law_step`: the :data:`SETTINGS_FIELDS` of ``settings`` and 2.0, (:data:`N_PARAMS`,).

    None unless every one is a float: the kernel computes in floats, where the Python code
    would compute with an int as it is (a setting given as an int runs the Python code).
    """
    values = [getattr(settings, name) for name in SETTINGS_FIELDS]
    if any(type(v) is not float for v in values):
        return None
    return np.array(values + [2.0])


@njit(cache=True)
def py_remainder(x: float, y: float) -> float:
    """``math.remainder(x, y)`` of CPython 3.11 for a finite ``y != 0`` and an ``x`` that is not infinite.

    ``m_remainder`` of ``Modules/mathmodule.c`` (every step exact); a NaN ``x`` is returned as it is.
    """
    if x != x:
        return x
    absx = abs(x)
    absy = abs(y)
    m = np.fmod(absx, absy)
    c = absy - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:
        r = m - 2.0 * np.fmod(0.5 * (absx - m), absy)
    return math.copysign(1.0, x) * r


@njit(cache=True)
def py_square(a: float, two: float) -> float:
    """Python's ``a ** 2`` for a finite float: the C library's ``pow(|a|, 2.0)`` (``two`` = 2.0, given at run time).

    Infinite where the square overflows (where Python raises OverflowError).
    """
    if a == 0.0:
        return 0.0
    return math.pow(abs(a), two)


@njit(cache=True)
def _wrap_pi(angle: float) -> float:
    """:func:`heli_model.control.outer_loop.wrap_pi` of an angle that is not infinite."""
    return py_remainder(angle, _TWO_PI)


@njit(cache=True)
def _sqrt_gain(err_m: float, kp: float, accel: float) -> float:
    """:func:`heli_model.control.outer_loop._sqrt_gain`."""
    if kp <= 0.0:
        return 0.0
    linear_m = accel / (kp * kp)
    if err_m <= linear_m:
        return kp
    return math.sqrt(2.0 * accel * (err_m - 0.5 * linear_m)) / err_m


@njit(cache=True)
def _clip_unit(d: float) -> float:
    """``d`` clipped to [-1, 1], NaN kept (the numpy code's conditional expression)."""
    return -1.0 if d < -1.0 else (1.0 if d > 1.0 else d)


@njit(cache=True)
def law_output(
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
    dt,
    integrate_vel,
    integrate_yaw,
    delta,
    raw,
):
    """The linear part of one control period (the LQI with its feed-forward) and its integrators.

    Parameters
    ----------
    L : ndarray, shape (4, 26)
        ``delta = L @ [ref8, x14_err, z]``.
    x : ndarray, shape (17,) or (21,)
    c, s : float
        ``cos`` and ``sin`` of the heading ``x[13]``.
    cmd0, cmd1, cmd2 : float
        NED velocity command (after its limits), m/s.
    vf0, vf1 : float
        North and east velocity feed-forward, m/s.
    a0, a1, a2 : float
        NED acceleration feed-forward (after its limit), m/s^2.
    rate_ref, psi_err : float
        Yaw-rate feed-forward, rad/s, and heading error wrapped to [-pi, pi], rad.
    z0, z1, z2, z3 : float
        LQI integrators.
    dt : float
    integrate_vel, integrate_yaw : bool
        Whether the velocity and heading integrators may run (the command was not limited).
    delta, raw : ndarray, shape (4,)
        Outputs: the rotor inputs clipped to [-1, 1], and before clipping.

    Returns
    -------
    saturated : bool
    z_next : tuple of 4 float
        The integrators after the period (unchanged while saturated).
    """
    ub = c * cmd0 + s * cmd1
    vb = -s * cmd0 + c * cmd1
    wb = cmd2
    vfx = c * vf0 + s * vf1
    vfy = -s * vf0 + c * vf1
    vec = np.empty(L.shape[1])
    vec[0] = c * a0 + s * a1 + rate_ref * vfy
    vec[1] = -s * a0 + c * a1 - rate_ref * vfx
    vec[2], vec[3], vec[4], vec[5], vec[6], vec[7] = a2, rate_ref, ub, vb, wb, 0.0
    vec[8 : 8 + N_STATES] = x[:N_STATES]
    vec[8 + N_STATES] = psi_err
    vec[9 + N_STATES], vec[10 + N_STATES], vec[11 + N_STATES], vec[12 + N_STATES] = z0, z1, z2, z3
    raw[:] = np.dot(L, vec)
    saturated = False
    for k in range(4):
        delta[k] = _clip_unit(raw[k])
        if abs(raw[k]) > 1.0:
            saturated = True
    if not saturated:
        if integrate_vel:
            z0 += dt * (x[0] - ub)
            z1 += dt * (x[1] - vb)
            z2 += dt * (x[2] - wb)
        if integrate_yaw:
            z3 += dt * psi_err
    return saturated, (z0, z1, z2, z3)


@njit(cache=True)
def _has_infinity(a: float, b: float, c: float) -> bool:
    """Whether one of the 3 entries of a setpoint vector is infinite (where ``setpoint_axes`` raises)."""
    return math.isinf(a) or math.isinf(b) or math.isinf(c)


@njit(cache=True)
def _axis_command(p, v_ff, a_ff, pt, vn, ki, kd, integral):
    """One axis of :func:`heli_model.control.outer_loop.velocity_command`: ``(cmd, acc_ff, vel_ff, pid, integral)``."""
    if p == p:
        vf = v_ff if v_ff == v_ff else 0.0
        return vf + pt + ki * integral + kd * (vf - vn), (a_ff if a_ff == a_ff else 0.0), vf, True, integral
    if v_ff == v_ff:
        return v_ff, (a_ff if a_ff == a_ff else 0.0), v_ff, False, 0.0
    return 0.0, 0.0, 0.0, False, 0.0


@njit(cache=True)
def _integrate_position(integral, dt, p, now, ki, pos_int_max):
    """One PID position integrator after a period, clamped to ``pos_int_max / ki`` (``ki > 0``)."""
    new = integral + dt * (p - now)
    if ki > 0:
        cap = pos_int_max / ki
        new = py_max(-cap, py_min(cap, new))
    return new


@njit(cache=True)
def law_step(
    P,
    L,
    x,
    p0,
    p1,
    p2,
    v0,
    v1,
    v2,
    a0,
    a1,
    a2,
    has_yaw,
    yaw,
    has_rate,
    rate,
    z0,
    z1,
    z2,
    z3,
    i0,
    i1,
    i2,
    yaw_ref,
    prev0,
    prev1,
    prev2,
    dt,
    delta,
    raw,
    vel_cmd,
):
    """One control period of :meth:`heli_model.control.law.ControlLaw.step` (after its argument checks).

    Parameters
    ----------
    P : ndarray, shape (N_PARAMS,)
        :func:`pack_settings`.
    L : ndarray, shape (4, 26)
        The control-law matrix.
    x : ndarray, shape (17,) or (21,)
        Simulation state.
    p0, p1, p2, v0, v1, v2, a0, a1, a2 : float
        Setpoint position, m, velocity, m/s, and acceleration, m/s^2, NED; NaN = axis not
        commanded (a vector that is None is three NaN).
    has_yaw, has_rate : bool
        Whether the setpoint has a heading, a yaw rate.
    yaw, rate : float
        Heading, rad, and yaw rate, rad/s, of the setpoint (read only where given).
    z0, z1, z2, z3 : float
        LQI integrators.
    i0, i1, i2 : float
        PID position integrators, NED.
    yaw_ref : float
        Heading reference, rad.
    prev0, prev1, prev2 : float
        Previous velocity command, NED, m/s.
    dt : float
        Time since the previous period, s.
    delta, raw : ndarray, shape (4,)
        Outputs: the rotor inputs clipped to [-1, 1], and before clipping.
    vel_cmd : ndarray, shape (3,)
        Output: the velocity command after its limits.

    Returns
    -------
    status : int
        :data:`OK`, or :data:`FALL_BACK` where the Python code raises (the outputs are then undefined).
    saturated : bool
    z_next : tuple of 4 float
    pos_integral_next : tuple of 3 float
    yaw_ref_next : float
    cmd : tuple of 3 float
        The velocity command (the next period's previous command).
    """
    nothing = (FALL_BACK, False, (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    psi = x[13]
    if math.isinf(psi) or _has_infinity(p0, p1, p2) or _has_infinity(v0, v1, v2) or _has_infinity(a0, a1, a2):
        return nothing
    c, s = math.cos(psi), math.sin(psi)
    # velocity_command: PID position loop + velocity feed-forward
    u, v, w = x[0], x[1], x[2]
    vn0, vn1, vn2 = c * u - s * v, s * u + c * v, w
    ex = p0 - x[14] if p0 == p0 else 0.0
    ey = p1 - x[15] if p1 == p1 else 0.0
    gain = _sqrt_gain(py_hypot(ex, ey), P[_KP_XY], 0.5 * P[_CMD_ACCEL_XY])
    pt0, pt1 = gain * ex, gain * ey
    pt2 = 0.0
    if p2 == p2:
        ez = p2 - x[16]
        pt2 = _sqrt_gain(abs(ez), P[_KP_Z], 0.5 * P[_CMD_ACCEL_Z]) * ez
    cmd0, af0, vf0, pid0, i0 = _axis_command(p0, v0, a0, pt0, vn0, P[_KI_XY], P[_KD_XY], i0)
    cmd1, af1, vf1, pid1, i1 = _axis_command(p1, v1, a1, pt1, vn1, P[_KI_XY], P[_KD_XY], i1)
    cmd2, af2, _, pid2, i2 = _axis_command(p2, v2, a2, pt2, vn2, P[_KI_Z], P[_KD_Z], i2)
    # limit_command: slew rate, speed and acceleration limits
    lim0 = lim1 = lim2 = False
    dx, dy, dz = cmd0 - prev0, cmd1 - prev1, cmd2 - prev2
    step_xy = P[_CMD_ACCEL_XY] * dt
    dh = py_hypot(dx, dy)
    if dh > step_xy:
        k = step_xy / dh
        cmd0 = prev0 + k * dx
        cmd1 = prev1 + k * dy
        lim0 = lim1 = True
    step_z = P[_CMD_ACCEL_Z] * dt
    if abs(dz) > step_z:
        cmd2 = prev2 + math.copysign(step_z, dz)
        lim2 = True
    hs = py_hypot(cmd0, cmd1)
    if hs > P[_MAX_SPEED_XY]:
        k = P[_MAX_SPEED_XY] / hs
        cmd0 *= k
        cmd1 *= k
        lim0 = lim1 = True
    if cmd2 < -P[_MAX_CLIMB]:
        cmd2 = -P[_MAX_CLIMB]
        lim2 = True
    elif cmd2 > P[_MAX_DESCENT]:
        cmd2 = P[_MAX_DESCENT]
        lim2 = True
    if af0 != 0.0 or af1 != 0.0 or af2 != 0.0:  # Python's truth of a float (these are not NaN)
        q0, q1, q2 = py_square(af0, P[_TWO]), py_square(af1, P[_TWO]), py_square(af2, P[_TWO])
        if math.isinf(q0) or math.isinf(q1) or math.isinf(q2):  # OverflowError in Python
            return nothing
        am = math.sqrt(q0 + q1 + q2)
        if am > P[_MAX_ACCEL]:
            k = P[_MAX_ACCEL] / am
            af0, af1, af2 = af0 * k, af1 * k, af2 * k
    # heading_reference
    lim = P[_MAX_YAW_RATE]
    rate_ref = 0.0
    if has_rate:
        if not math.isfinite(rate):
            return nothing
        rate_ref = rate if rate < lim else lim
        rate_ref = rate_ref if rate_ref > -lim else -lim
    yaw_limited = False
    if has_yaw:
        if not math.isfinite(yaw) or math.isinf(yaw - yaw_ref):
            return nothing
        turn = _wrap_pi(yaw - yaw_ref)
        max_turn = lim * dt
        if abs(turn) > max_turn:
            a = yaw_ref + math.copysign(max_turn, turn)
            if math.isinf(a):
                return nothing
            yaw_ref = _wrap_pi(a)
            yaw_limited = True
        else:
            yaw_ref = yaw
    elif has_rate:
        a = yaw_ref + rate_ref * dt
        if math.isinf(a):
            return nothing
        yaw_ref = _wrap_pi(a)
    if math.isinf(psi - yaw_ref):
        return nothing
    psi_err = _wrap_pi(psi - yaw_ref)
    # the LQI with its feed-forward, its integrators, then the position integrators
    saturated, z = law_output(
        L,
        x,
        c,
        s,
        cmd0,
        cmd1,
        cmd2,
        vf0,
        vf1,
        af0,
        af1,
        af2,
        rate_ref,
        psi_err,
        z0,
        z1,
        z2,
        z3,
        dt,
        not (lim0 or lim1 or lim2),
        not yaw_limited,
        delta,
        raw,
    )
    if not saturated:
        ki_xy, ki_z, pos_int_max = P[_KI_XY], P[_KI_Z], P[_POS_INT_MAX]
        if pid0 and not lim0:
            i0 = _integrate_position(i0, dt, p0, x[14], ki_xy, pos_int_max)
        if pid1 and not lim1:
            i1 = _integrate_position(i1, dt, p1, x[15], ki_xy, pos_int_max)
        if pid2 and not lim2:
            i2 = _integrate_position(i2, dt, p2, x[16], ki_z, pos_int_max)
    vel_cmd[0], vel_cmd[1], vel_cmd[2] = cmd0, cmd1, cmd2
    return OK, saturated, z, (i0, i1, i2), yaw_ref, (cmd0, cmd1, cmd2)
