"""The flight controller's per-tick law, pure: PID position loop around the LQI (paper section 2.2).

:meth:`ControlLaw.step` maps ``(controller state, vehicle state, setpoint, dt)`` to the next
controller state, whose ``delta`` are the rotor inputs; it keeps no state of its own
(:class:`heli_model.control.FlightController` is the stateful wrapper). The LQI tracks body
velocities and heading (:mod:`heli_model.control.lqi`); around it sits the outer loop of
section 2.2:

1. **PID position loop**, per NED axis: ``v_cmd = v_ff + P(e) + Ki int(e) + Kd (v_ff - v)``
   with ``e = p_ref - p``. ``P(e) = Kp e`` for errors up to a few metres and grows as a
   square root beyond (ArduPilot's ``sqrt_controller``) so that far targets are reached
   without overshoot. The command is slew-limited (``cmd_accel_*``: a position step becomes a
   velocity ramp), its horizontal speed limited to ``max_speed_xy_m_s`` and its vertical speed
   to the climb/descent rates. Anti-windup: the position integrators and the LQI velocity
   integrators are frozen while the command is limited, every integrator while the rotor
   inputs saturate (conditional integration), and the position integrators are clamped.
   ``Ki`` and ``Kd`` default to 0: the LQI's velocity integrators already make the position
   loop reject steady disturbances (steady wind) with zero error, and a position integrator
   would only add a slow closed-loop pole; both are settings.
2. **Feed-forward** from the setpoint: the velocity ``v_ff`` enters the PID above, and the
   acceleration ``a_ff`` (with the yaw rate) sets the *quasi-steady* reference state: the
   controller solves, once per design, the linear trim equations

       [A14 B; C 0] [x_ff; delta_ff] = [xdot_ff; y_ref],
       xdot_ff = (u', v', w' = body acceleration, 0 ... 0, psi' = r_ref),

   so ``x_ff`` holds the attitude, flapping and rates that produce the commanded velocity *and*
   acceleration, and ``delta_ff`` the matching stick positions. The body acceleration is
   ``Rz(psi)^T a_ff - r_ref x Rz(psi)^T v_ff`` (the body axes turn with the heading).
3. **Heading**: ``yaw_rad`` is tracked with the error wrapped to (-pi, pi], its reference
   slewed at most at ``max_yaw_rate_rad_s`` (a heading step is flown as a turn); a yaw rate
   alone integrates the reference.

Speed: the outer loop is Python written for speed (:mod:`~heli_model.control.outer_loop`), the
linear part one call of a compiled kernel (:mod:`heli_model.rk4_kernel`) that gives the numpy
code's results to the bit (:func:`law_output` is that numpy code).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from heli_model.control.lqi import control_law_matrix, design_lqi
from heli_model.control.outer_loop import heading_reference, limit_command, velocity_command, wrap_pi
from heli_model.control.settings import N_LQI_STATES, ControlError, ControllerSettings, Setpoint
from heli_model.dynamics import IDX_PSI, compiled_kernels, hover_state
from heli_model.model import N_INPUTS, N_STATES, HeliModel

__all__ = ["ControlLaw", "ControllerState", "initial_controller_state", "law_output"]

_FLOAT64 = np.dtype(np.float64)


class ControllerState(NamedTuple):
    """What the flight controller carries from one control period to the next, and its output.

    Attributes
    ----------
    z : tuple of 4 float
        LQI integrators of the ``u, v, w, psi`` tracking errors.
    pos_integral_m : tuple of 3 float
        PID position integrators, NED.
    yaw_ref_rad : float
        Heading reference the LQI tracks.
    cmd_prev_ned_m_s : tuple of 3 float
        Previous velocity command (the slew limiter starts from it).
    delta : ndarray, shape (4,)
        Rotor inputs ``[d_lat, d_lon, d_ped, d_col]``, clipped to [-1, 1].
    delta_unclipped : ndarray, shape (4,)
        The same before clipping (``|.| > 1`` where the rotor saturated).
    saturated : bool
        Whether ``delta`` was clipped.
    vel_cmd_ned_m_s : ndarray, shape (3,)
        Velocity command of the position loop (after its limits).
    """

    z: tuple
    pos_integral_m: tuple
    yaw_ref_rad: float
    cmd_prev_ned_m_s: tuple
    delta: np.ndarray
    delta_unclipped: np.ndarray
    saturated: bool
    vel_cmd_ned_m_s: np.ndarray


def initial_controller_state() -> ControllerState:
    """All integrators, commands and outputs zero, heading reference 0."""
    return ControllerState(z=(0.0, 0.0, 0.0, 0.0), pos_integral_m=(0.0, 0.0, 0.0), yaw_ref_rad=0.0,
                           cmd_prev_ned_m_s=(0.0, 0.0, 0.0), delta=np.zeros(N_INPUTS),
                           delta_unclipped=np.zeros(N_INPUTS), saturated=False, vel_cmd_ned_m_s=np.zeros(3))


class ControlLaw:
    """The designed controller: LQI gains, control-law matrix and PID settings (no mutable state).

    Parameters
    ----------
    model : HeliModel
    settings : ControllerSettings, optional

    Attributes
    ----------
    settings : ControllerSettings
    gains : LqiGains
    matrix : ndarray, shape (4, 26)
        ``delta = matrix @ [ref8, x14_err, z]`` (cached on the model).

    Notes
    -----
    The constructor runs one :meth:`step` at hover, so that the compiled kernel of the linear
    part is loaded here (numba's cache; compiled the first time on a machine) rather than in the
    first step of a flight.
    """

    def __init__(self, model: HeliModel, settings: ControllerSettings | None = None) -> None:
        self.settings = settings if settings is not None else ControllerSettings()
        s = self.settings
        self.gains = design_lqi(model, s.control_dt_s, s.q_weights, s.r_weights)
        self.matrix = model.cached(("law", s.control_dt_s, self.gains.q_weights, self.gains.r_weights),
                                   lambda: control_law_matrix(self.gains))
        self._matrix_shape = self.matrix.shape
        hover = hover_state(model)
        self.step(self.reset(hover), hover, Setpoint(), s.control_dt_s)

    def reset(self, x: np.ndarray) -> ControllerState:
        """Integrators cleared, heading held, velocity command = the current velocity (taking over)."""
        yaw = float(x[IDX_PSI])
        c, s = math.cos(yaw), math.sin(yaw)
        u, v, w = float(x[0]), float(x[1]), float(x[2])
        cmd_prev = (c * u - s * v, s * u + c * v, w)
        return ControllerState(z=(0.0, 0.0, 0.0, 0.0), pos_integral_m=(0.0, 0.0, 0.0), yaw_ref_rad=yaw,
                               cmd_prev_ned_m_s=cmd_prev, delta=np.zeros(N_INPUTS),
                               delta_unclipped=np.zeros(N_INPUTS), saturated=False,
                               vel_cmd_ned_m_s=np.array(cmd_prev))

    def step(self, state: ControllerState, x: np.ndarray, setpoint: Setpoint, dt_s: float) -> ControllerState:
        """One control period: controller state, vehicle state and setpoint in, next controller state out.

        Parameters
        ----------
        state : ControllerState
        x : ndarray, shape (17,) or (21,)
            Simulation state (see :mod:`heli_model.dynamics`).
        setpoint : Setpoint
        dt_s : float
            Time since the previous period, s.

        Returns
        -------
        ControllerState
            Its ``delta`` are the rotor inputs for the coming period.

        Notes
        -----
        The outer loop runs in Python (:mod:`~heli_model.control.outer_loop`); the linear part
        (references in body axes, the LQI with its feed-forward, clipping, integrators) runs
        compiled, :func:`heli_model.rk4_kernel.law_output`, or in numpy, :func:`law_output`,
        where the compiled product would not be numpy's to the bit: the same results either way.
        """
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
        if type(x) is not np.ndarray or x.dtype is not _FLOAT64:
            x = np.asarray(x, dtype=float)
        st = self.settings
        xl = x.tolist()  # the state as floats, once
        psi = xl[IDX_PSI]
        c, s = math.cos(psi), math.sin(psi)
        pos_integral = list(state.pos_integral_m)
        cmd, acc_ff, vel_ff, pid_active, pos = velocity_command(st, pos_integral, xl, setpoint, c, s)
        cmd, acc_ff, limited = limit_command(st, state.cmd_prev_ned_m_s, cmd, acc_ff, dt_s)
        yaw_ref, rate_ref, yaw_limited = heading_reference(st, state.yaw_ref_rad, setpoint, dt_s)
        psi_err = wrap_pi(psi - yaw_ref)

        # the LQI with its feed-forward, and its integrators (conditional-integration anti-windup: a
        # slewing or speed-limited command is a ramp the velocity integrators must not chase)
        cmd0, cmd1, cmd2 = cmd
        z0, z1, z2, z3 = state.z
        delta, raw = np.empty(N_INPUTS), np.empty(N_INPUTS)
        kernels = compiled_kernels(self._matrix_shape)
        saturated, z = (law_output if kernels is None else kernels.law_output)(
            self.matrix, x, c, s, cmd0, cmd1, cmd2, vel_ff[0], vel_ff[1], acc_ff[0], acc_ff[1], acc_ff[2], rate_ref,
            psi_err, z0, z1, z2, z3, float(dt_s), not (limited[0] or limited[1] or limited[2]), not yaw_limited,
            delta, raw)
        if saturated:
            z = state.z
        else:  # the PID position integrators of the position-controlled axes whose command was not limited
            for i in range(3):
                if pid_active[i] and not limited[i]:
                    new = pos_integral[i] + dt_s * (pos[i] - xl[14 + i])
                    ki = st.ki_xy_1_s2 if i < 2 else st.ki_z_1_s2
                    if ki > 0:
                        cap = st.pos_integral_max_m_s / ki
                        new = max(-cap, min(cap, new))
                    pos_integral[i] = new
        # positional: the fields in their order (z, pos_integral_m, yaw_ref_rad, cmd_prev_ned_m_s, delta,
        # delta_unclipped, saturated, vel_cmd_ned_m_s), a little faster than keywords at 100 Hz
        cmd = (cmd0, cmd1, cmd2)
        return ControllerState(z, tuple(pos_integral), yaw_ref, cmd, delta, raw, saturated, np.array(cmd))


def law_output(L: np.ndarray, x: np.ndarray, c: float, s: float, cmd0: float, cmd1: float, cmd2: float,
               vf0: float, vf1: float, a0: float, a1: float, a2: float, rate_ref: float, psi_err: float,
               z0: float, z1: float, z2: float, z3: float, dt_s: float, integrate_vel: bool, integrate_yaw: bool,
               delta: np.ndarray, raw: np.ndarray) -> tuple[bool, tuple]:
    """The linear part of a control period in numpy: references in body axes, ``L @ vec``, clip, integrators.

    The reference implementation of :func:`heli_model.rk4_kernel.law_output` (same arguments,
    same results bit for bit), run where the compiled kernels are not exact.
    """
    # references in body axes
    ub = c * cmd0 + s * cmd1
    vb = -s * cmd0 + c * cmd1
    wb = cmd2
    # body acceleration of the feed-forward: Rz^T a_ff - r_ref x (Rz^T v_ff)
    vfx = c * vf0 + s * vf1
    vfy = -s * vf0 + c * vf1
    axb = c * a0 + s * a1 + rate_ref * vfy
    ayb = -s * a0 + c * a1 - rate_ref * vfx
    vec = np.empty(L.shape[1])
    vec[0:8] = (axb, ayb, a2, rate_ref, ub, vb, wb, 0.0)
    vec[8:8 + N_STATES] = x[:N_STATES]
    vec[8 + N_STATES] = psi_err
    vec[8 + N_LQI_STATES:] = (z0, z1, z2, z3)
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
