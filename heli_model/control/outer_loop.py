"""The outer loop of the flight controller: PID position loop, command limits, heading reference.

Pure functions of the settings, the vehicle state, the setpoint and the controller's previous
values (:meth:`heli_model.control.law.ControlLaw.step` calls them once per control period).
"""

from __future__ import annotations

import math

from heli_model.control.settings import ControlError, ControllerSettings, Setpoint, setpoint_axes

__all__ = ["heading_reference", "limit_command", "proportional_term", "velocity_command", "wrap_pi"]

_TWO_PI = 2.0 * math.pi


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi]."""
    return math.remainder(angle_rad, _TWO_PI)


def _sqrt_gain(err_m: float, kp: float, accel: float) -> float:
    """Ratio command/error of the square-root position controller (see :func:`proportional_term`)."""
    if kp <= 0.0:
        return 0.0
    linear_m = accel / (kp * kp)
    if err_m <= linear_m:
        return kp
    return math.sqrt(2.0 * accel * (err_m - 0.5 * linear_m)) / err_m


_NOT_COMMANDED = (math.nan, math.nan, math.nan)
"""The axes of a setpoint vector that is None (NaN: no axis commanded)."""


def velocity_command(st: ControllerSettings, pos_integral: list, x, sp: Setpoint, c: float, s: float):
    """PID position loop + velocity feed-forward.

    Returns the NED velocity command, acceleration and velocity feed-forward (3 each), which
    axes are position-controlled, and the position setpoint (or None). ``pos_integral`` (3
    floats) is reset in place on the axes without a position. ``x`` is the state, a sequence of
    floats (:meth:`~heli_model.control.law.ControlLaw.step` passes it as a list).
    """
    pos = setpoint_axes(sp.pos_ned_m, "pos_ned_m")
    vel = setpoint_axes(sp.vel_ned_m_s, "vel_ned_m_s")
    acc = setpoint_axes(sp.acc_ned_m_s2, "acc_ned_m_s2")
    u, v, w = x[0], x[1], x[2]
    vel_now = (c * u - s * v, s * u + c * v, w)
    cmd = [0.0, 0.0, 0.0]
    acc_ff = [0.0, 0.0, 0.0]
    vel_ff = [0.0, 0.0, 0.0]
    pid_active = [False, False, False]
    p_term = proportional_term(st, x, pos)
    ki_xy, kd_xy = st.ki_xy_1_s2, st.kd_xy
    pos_axes = _NOT_COMMANDED if pos is None else pos
    vel_axes = _NOT_COMMANDED if vel is None else vel
    acc_axes = _NOT_COMMANDED if acc is None else acc
    for i in range(3):
        p, v_ff, a_ff = pos_axes[i], vel_axes[i], acc_axes[i]  # NaN: not commanded
        if p == p:
            ki, kd = (ki_xy, kd_xy) if i < 2 else (st.ki_z_1_s2, st.kd_z)
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


def proportional_term(st: ControllerSettings, x, pos) -> list:
    """P term of the position loop: linear near the target, square root far from it.

    ArduPilot's ``sqrt_controller``: beyond ``a / kp^2`` the velocity command grows as
    ``sqrt(2 a (|e| - a / (2 kp^2)))`` so that the vehicle can stop from it at deceleration
    ``a`` without overshoot; within it, it is ``kp e`` (small errors and trajectory tracking
    stay linear). ``a`` is half the command slew limit, which leaves the inner loop margin
    to follow the braking ramp. Horizontal error is treated as a vector. ``x`` is the state, a
    sequence of floats; returns the three terms, NED.
    """
    out = [0.0, 0.0, 0.0]
    if pos is None:
        return out
    p0, p1, p2 = pos
    ex = p0 - x[14] if p0 == p0 else 0.0
    ey = p1 - x[15] if p1 == p1 else 0.0
    gain = _sqrt_gain(math.hypot(ex, ey), st.kp_xy_1_s, 0.5 * st.cmd_accel_xy_m_s2)
    out[0], out[1] = gain * ex, gain * ey
    if p2 == p2:
        ez = p2 - x[16]
        out[2] = _sqrt_gain(abs(ez), st.kp_z_1_s, 0.5 * st.cmd_accel_z_m_s2) * ez
    return out


def limit_command(st: ControllerSettings, prev, cmd: list, acc_ff: list, dt_s: float) -> tuple[list, list, list]:
    """Slew-rate (from the previous command ``prev``), speed and acceleration limits; returns which axes were limited."""
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
    if acc_ff[0] or acc_ff[1] or acc_ff[2]:  # (zero acceleration is within the limit)
        am = math.sqrt(acc_ff[0] ** 2 + acc_ff[1] ** 2 + acc_ff[2] ** 2)
        if am > st.max_accel_m_s2:
            k = st.max_accel_m_s2 / am
            acc_ff = [a * k for a in acc_ff]
    return cmd, acc_ff, limited


def heading_reference(
    st: ControllerSettings, yaw_ref_rad: float, sp: Setpoint, dt_s: float
) -> tuple[float, float, bool]:
    """Next heading reference (rad), yaw-rate feed-forward (rad/s), and whether it was slewed.

    A commanded heading is approached at most at ``max_yaw_rate_rad_s`` (a heading step
    becomes a ramp, so the pedal does not saturate); a yaw rate alone integrates the
    reference; neither holds it.
    """
    lim = st.max_yaw_rate_rad_s
    rate = 0.0
    if sp.yaw_rate_rad_s is not None:
        rate = float(sp.yaw_rate_rad_s)
        if not math.isfinite(rate):
            raise ControlError(f"setpoint.yaw_rate_rad_s: expected a finite number, got {sp.yaw_rate_rad_s!r}")
        rate = rate if rate < lim else lim  # max(-lim, min(lim, rate)), without the two calls
        rate = rate if rate > -lim else -lim
    limited = False
    if sp.yaw_rad is not None:
        yaw = float(sp.yaw_rad)
        if not math.isfinite(yaw):
            raise ControlError(f"setpoint.yaw_rad: expected a finite number, got {sp.yaw_rad!r}")
        # slew the reference the short way round at most at the yaw-rate limit
        turn = wrap_pi(yaw - yaw_ref_rad)
        max_turn = lim * dt_s
        if abs(turn) > max_turn:
            yaw_ref_rad = wrap_pi(yaw_ref_rad + math.copysign(max_turn, turn))
            limited = True
        else:
            yaw_ref_rad = yaw
    elif sp.yaw_rate_rad_s is not None:
        yaw_ref_rad = wrap_pi(yaw_ref_rad + rate * dt_s)
    return yaw_ref_rad, rate, limited
