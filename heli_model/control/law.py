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

Speed: a control period is one call of a compiled kernel (:func:`heli_model.control_kernel.law_step`)
that gives the Python code's results to the bit (:meth:`ControlLaw.step_python`: the outer loop
of :mod:`~heli_model.control.outer_loop`, the linear part in numpy, :func:`law_output`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from heli_model.control.lqi import control_law_matrix, design_lqi
from heli_model.control.outer_loop import heading_reference, limit_command, velocity_command, wrap_pi
from heli_model.control.settings import N_LQI_STATES, ControlError, ControllerSettings, Setpoint, setpoint_axes
from heli_model.dynamics import IDX_PSI, STATE_SIZE, compiled_kernels, hover_state
from heli_model.model import N_INPUTS, N_STATES, HeliModel

__all__ = ["ControlLaw", "ControllerState", "initial_controller_state", "law_output"]

_FLOAT64 = np.dtype(np.float64)
_NAN = math.nan
_NOT_COMMANDED = (_NAN, _NAN, _NAN)
_SHAPE3 = (3,)
_NDARRAY = np.ndarray
_empty = np.empty
_KERNEL: list = []
"""The module :mod:`heli_model.control_kernel`, once loaded."""


def _control_kernel():
    """:mod:`heli_model.control_kernel`, imported on the first call (it imports numba)."""
    if not _KERNEL:
        from heli_model import control_kernel

        _KERNEL.append(control_kernel)
    return _KERNEL[0]


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
    return ControllerState(
        z=(0.0, 0.0, 0.0, 0.0),
        pos_integral_m=(0.0, 0.0, 0.0),
        yaw_ref_rad=0.0,
        cmd_prev_ned_m_s=(0.0, 0.0, 0.0),
        delta=np.zeros(N_INPUTS),
        delta_unclipped=np.zeros(N_INPUTS),
        saturated=False,
        vel_cmd_ned_m_s=np.zeros(3),
    )


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
        self.matrix = model.cached(
            ("law", s.control_dt_s, self.gains.q_weights, self.gains.r_weights), lambda: control_law_matrix(self.gains)
        )
        self._matrix_shape = self.matrix.shape
        self._params_of: ControllerSettings | None = None  # the settings self._params packs
        self._params: np.ndarray | None = None
        hover = hover_state(model)
        self.step(self.reset(hover), hover, Setpoint(), s.control_dt_s)

    def reset(self, x: np.ndarray) -> ControllerState:
        """Integrators cleared, heading held, velocity command = the current velocity (taking over)."""
        yaw = float(x[IDX_PSI])
        c, s = math.cos(yaw), math.sin(yaw)
        u, v, w = float(x[0]), float(x[1]), float(x[2])
        cmd_prev = (c * u - s * v, s * u + c * v, w)
        return ControllerState(
            z=(0.0, 0.0, 0.0, 0.0),
            pos_integral_m=(0.0, 0.0, 0.0),
            yaw_ref_rad=yaw,
            cmd_prev_ned_m_s=cmd_prev,
            delta=np.zeros(N_INPUTS),
            delta_unclipped=np.zeros(N_INPUTS),
            saturated=False,
            vel_cmd_ned_m_s=np.array(cmd_prev),
        )

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
        The whole period runs in one call of a compiled kernel,
        :func:`heli_model.control_kernel.law_step`, that gives the Python code's results to the
        bit (:meth:`step_python`: the outer loop of :mod:`~heli_model.control.outer_loop` in
        Python, the linear part in numpy, :func:`law_output`, or compiled,
        :func:`heli_model.control_kernel.law_output`). The Python code runs where the compiled
        product would not be numpy's to the bit, for settings that are not all floats, and where
        it raises (the kernel says so rather than raising itself).
        """
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
        if type(x) is not np.ndarray or x.dtype is not _FLOAT64:
            x = np.asarray(x, dtype=float)
        if compiled_kernels(self._matrix_shape) is not None:
            params = self._params if self._params_of is self.settings else self._pack_settings()
            if params is not None and x.ndim == 1 and x.shape[0] >= STATE_SIZE:
                out = _step_compiled(_KERNEL[0], params, self.matrix, state, x, setpoint, float(dt_s))
                if out is not None:
                    return out
        return self.step_python(state, x, setpoint, dt_s)

    def _pack_settings(self) -> np.ndarray | None:
        """The settings as the kernel reads them (kept until ``settings`` is replaced); loads the kernel."""
        if not _KERNEL:
            _control_kernel()
        self._params_of = self.settings
        self._params = _KERNEL[0].pack_settings(self.settings)
        return self._params

    def compiled_arguments(self, state: ControllerState, x: np.ndarray, setpoint: Setpoint):
        """What :func:`heli_model.periods_kernel.fly_periods` needs to run :meth:`step` compiled, or None.

        Returns
        -------
        tuple (params, matrix, setpoint (13,), controller (11,)) or None
            None where :meth:`step` would not run its kernel (no compiled kernels, settings the
            kernel cannot read, a state or setpoint of another kind): the caller steps instead.
        """
        if (
            compiled_kernels(self._matrix_shape) is None
            or type(x) is not np.ndarray
            or x.dtype is not _FLOAT64
            or x.ndim != 1
            or x.shape[0] < STATE_SIZE
        ):
            return None
        params = self._params if self._params_of is self.settings else self._pack_settings()
        if params is None:
            return None
        try:
            sp = np.array(
                [
                    *_kernel_axes(setpoint.pos_ned_m, "pos_ned_m"),
                    *_kernel_axes(setpoint.vel_ned_m_s, "vel_ned_m_s"),
                    *_kernel_axes(setpoint.acc_ned_m_s2, "acc_ned_m_s2"),
                    setpoint.yaw_rad is not None,
                    0.0 if setpoint.yaw_rad is None else float(setpoint.yaw_rad),
                    setpoint.yaw_rate_rad_s is not None,
                    0.0 if setpoint.yaw_rate_rad_s is None else float(setpoint.yaw_rate_rad_s),
                ],
                dtype=float,
            )
            controller = np.array(
                [*state.z, *state.pos_integral_m, state.yaw_ref_rad, *state.cmd_prev_ned_m_s], dtype=float
            )
        except Exception:  # noqa: BLE001 - an argument of another kind: step's own checks say what is wrong
            return None
        if controller.shape != (11,):
            return None
        return params, self.matrix, sp, controller

    def step_python(self, state: ControllerState, x: np.ndarray, setpoint: Setpoint, dt_s: float) -> ControllerState:
        """:meth:`step` in Python (the reference of the compiled kernel), after its checks of ``dt_s`` and ``x``.

        ``x`` is a float array here. The outer loop runs in Python
        (:mod:`~heli_model.control.outer_loop`); the linear part (references in body axes, the
        LQI with its feed-forward, clipping, integrators) runs compiled,
        :func:`heli_model.control_kernel.law_output`, or in numpy, :func:`law_output`, where the
        compiled product would not be numpy's to the bit: the same results either way.
        """
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
        kernel = None if compiled_kernels(self._matrix_shape) is None else _control_kernel()
        saturated, z = (law_output if kernel is None else kernel.law_output)(
            self.matrix,
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


def _step_compiled(
    kernel, params: np.ndarray, L: np.ndarray, state: ControllerState, x: np.ndarray, sp: Setpoint, dt_s: float
) -> ControllerState | None:
    """:meth:`ControlLaw.step` in one call of :func:`heli_model.control_kernel.law_step`; None where the Python code must run.

    The setpoint and the controller state go in as floats (NaN: an axis not commanded), the
    outputs come back as the fields of the next :class:`ControllerState`. None where an argument
    is not of the usual kinds or the kernel says the Python code raises here: the caller runs
    it, and it raises as before.
    """
    try:
        pos, vel, acc, yaw, rate = sp.pos_ned_m, sp.vel_ned_m_s, sp.acc_ned_m_s2, sp.yaw_rad, sp.yaw_rate_rad_s
        # float arrays of 3 (the fast-time flights' setpoints) inline, anything else through _kernel_axes
        p0, p1, p2 = (
            pos.tolist()
            if type(pos) is _NDARRAY and pos.dtype is _FLOAT64 and pos.shape == _SHAPE3
            else _kernel_axes(pos, "pos_ned_m")
        )
        v0, v1, v2 = (
            vel.tolist()
            if type(vel) is _NDARRAY and vel.dtype is _FLOAT64 and vel.shape == _SHAPE3
            else _kernel_axes(vel, "vel_ned_m_s")
        )
        a0, a1, a2 = (
            acc.tolist()
            if type(acc) is _NDARRAY and acc.dtype is _FLOAT64 and acc.shape == _SHAPE3
            else _kernel_axes(acc, "acc_ned_m_s2")
        )
        has_yaw, has_rate = yaw is not None, rate is not None
        yaw = float(yaw) if yaw is not None else 0.0
        rate = float(rate) if rate is not None else 0.0
        z0, z1, z2, z3 = state.z
        i0, i1, i2 = state.pos_integral_m
        prev0, prev1, prev2 = state.cmd_prev_ned_m_s
        delta, raw, vel_cmd = _empty(N_INPUTS), _empty(N_INPUTS), _empty(3)
        status, saturated, z, integral, yaw_ref, cmd = kernel.law_step(
            params,
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
            state.yaw_ref_rad,
            prev0,
            prev1,
            prev2,
            dt_s,
            delta,
            raw,
            vel_cmd,
        )
    except Exception:  # noqa: BLE001 - an argument of another kind: the Python code says what is wrong
        return None
    if status != kernel.OK:
        return None
    # positional: the fields in their order (z, pos_integral_m, yaw_ref_rad, cmd_prev_ned_m_s, delta,
    # delta_unclipped, saturated, vel_cmd_ned_m_s), a little faster than keywords at 100 Hz
    return ControllerState(z, integral, yaw_ref, cmd, delta, raw, saturated, vel_cmd)


def _kernel_axes(v, name: str) -> tuple[float, float, float]:
    """The 3 axes of a setpoint vector as floats, NaN where not commanded (None: all three); infinities kept."""
    if v is None:
        return _NOT_COMMANDED
    if type(v) is np.ndarray and v.dtype is _FLOAT64 and v.shape == _SHAPE3:
        return v.tolist()
    axes = setpoint_axes(v, name)  # not None: v is not None here
    return _NOT_COMMANDED if axes is None else axes


def law_output(
    L: np.ndarray,
    x: np.ndarray,
    c: float,
    s: float,
    cmd0: float,
    cmd1: float,
    cmd2: float,
    vf0: float,
    vf1: float,
    a0: float,
    a1: float,
    a2: float,
    rate_ref: float,
    psi_err: float,
    z0: float,
    z1: float,
    z2: float,
    z3: float,
    dt_s: float,
    integrate_vel: bool,
    integrate_yaw: bool,
    delta: np.ndarray,
    raw: np.ndarray,
) -> tuple[bool, tuple]:
    """The linear part of a control period in numpy: references in body axes, ``L @ vec``, clip, integrators.

    The reference implementation of :func:`heli_model.control_kernel.law_output` (same arguments,
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
    vec[8 : 8 + N_STATES] = x[:N_STATES]
    vec[8 + N_STATES] = psi_err
    vec[8 + N_LQI_STATES :] = (z0, z1, z2, z3)
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
