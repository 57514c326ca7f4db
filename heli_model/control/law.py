"""The flight controller's per-tick law, pure: PID position loop around the LQI (paper section 2.2).

:meth:`ControlLaw.step` maps ``(controller state, vehicle state, setpoint, dt)`` to the next
controller state, whose ``delta`` are the rotor inputs; it keeps no state of its own
(:class:`heli_model.control.FlightController` is the stateful wrapper). The LQI tracks body
velocities and heading (:mod:`heli_model.control.lqi`); around it sits the outer loop:


Around the LQI (which tracks body velocities and heading) sits the outer loop of section 2.2:

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
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from heli_model.control.lqi import control_law_matrix, design_lqi
from heli_model.control.outer_loop import heading_reference, limit_command, velocity_command, wrap_pi
from heli_model.control.settings import N_LQI_STATES, ControlError, ControllerSettings, Setpoint
from heli_model.dynamics import IDX_PSI
from heli_model.model import N_INPUTS, N_STATES, HeliModel


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
    """

    def __init__(self, model: HeliModel, settings: ControllerSettings | None = None) -> None:
        self.settings = settings if settings is not None else ControllerSettings()
        s = self.settings
        self.gains = design_lqi(model, s.control_dt_s, s.q_weights, s.r_weights)
        self.matrix = model.cached(("law", s.control_dt_s, self.gains.q_weights, self.gains.r_weights),
                                   lambda: control_law_matrix(self.gains))
        self._n_law_inputs = int(self.matrix.shape[1])

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
        """
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
        st = self.settings
        psi = float(x[IDX_PSI])
        c, s = math.cos(psi), math.sin(psi)
        pos_integral = list(state.pos_integral_m)
        cmd, acc_ff, vel_ff, pid_active, pos = velocity_command(st, pos_integral, x, setpoint, c, s)
        cmd, acc_ff, limited = limit_command(st, state.cmd_prev_ned_m_s, cmd, acc_ff, dt_s)
        yaw_ref, rate_ref, yaw_limited = heading_reference(st, state.yaw_ref_rad, setpoint, dt_s)
        vel_cmd = np.array(cmd)

        # references in body axes
        ub = c * cmd[0] + s * cmd[1]
        vb = -s * cmd[0] + c * cmd[1]
        wb = cmd[2]
        # body acceleration of the feed-forward: Rz^T a_ff - r_ref x (Rz^T v_ff)
        vfx = c * vel_ff[0] + s * vel_ff[1]
        vfy = -s * vel_ff[0] + c * vel_ff[1]
        axb = c * acc_ff[0] + s * acc_ff[1] + rate_ref * vfy
        ayb = -s * acc_ff[0] + c * acc_ff[1] - rate_ref * vfx
        azb = acc_ff[2]
        psi_err = wrap_pi(psi - yaw_ref)

        vec = np.empty(self._n_law_inputs)
        vec[0:8] = (axb, ayb, azb, rate_ref, ub, vb, wb, 0.0)
        vec[8:8 + N_STATES] = x[:N_STATES]
        vec[8 + N_STATES] = psi_err
        vec[8 + N_LQI_STATES:] = state.z
        raw = (self.matrix @ vec).tolist()
        delta = [(-1.0 if d < -1.0 else (1.0 if d > 1.0 else d)) for d in raw]
        saturated = any(abs(d) > 1.0 for d in raw)

        # integrators with conditional-integration anti-windup
        z = state.z
        if not saturated:
            z0, z1, z2, z3 = z
            if not (limited[0] or limited[1] or limited[2]):
                # a slewing or speed-limited command is a ramp the integrators must not chase
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
        # positional: the fields in their order (z, pos_integral_m, yaw_ref_rad, cmd_prev_ned_m_s, delta,
        # delta_unclipped, saturated, vel_cmd_ned_m_s), a little faster than keywords at 100 Hz
        return ControllerState(z, tuple(pos_integral), yaw_ref, tuple(cmd), np.array(delta), np.array(raw),
                               saturated, vel_cmd)
