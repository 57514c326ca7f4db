"""The flight controller: LQI on the 14-state hover model and a PID position loop.

Paper section 2.2, eqs. 5-7. The 13-state hover model (:mod:`sim_vehicle.model`) plus the
heading ``psi`` (``dpsi/dt = r``) is discretised with a zero-order hold at the control rate
(100 Hz) and augmented with four integrators of the tracking error of the outputs
``y = [u, v, w, psi]``; python-control's ``dlqr(sys, Q, R, integral_action=C dt)`` gives the
gain ``K = [Kx Kz]`` (4 x 18) of ``delta = -Kx (x - x_ff) - Kz z + delta_ff``, with
``z[k+1] = z[k] + dt (y[k] - y_ref[k])``.

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
   slewed the short way round at most at ``max_yaw_rate_rad_s`` (the heading integrator is
   frozen meanwhile); ``yaw_rate_rad_s`` alone integrates a heading reference; neither holds
   the last heading.

Choice of Q and R (Bryson's rule)
---------------------------------
``Q = diag(1 / dx_max^2)`` and ``R = diag(1 / delta_max^2)`` with the largest acceptable
excursion of each state and input during a manoeuvre (:data:`BRYSON_STATE_MAX`,
:data:`BRYSON_INTEGRATOR_MAX`, :data:`BRYSON_INPUT_MAX`):

=========================  ==============  ==============================================
state                      max excursion   why
=========================  ==============  ==============================================
u, v, w                    0.5 m/s         velocity tracking error budget
p, q, r                    1.0 rad/s       rates are free to move, lightly weighted
phi, theta                 0.35 rad        20 degrees of bank / pitch
a, b                       0.1 rad         rotor flapping (tip-path plane) deflection
r_fb, c, d                 1.0             internal rotor / damper states, lightly weighted
psi                        0.2 rad         heading error
int(u, v, w) dt            0.3 m           integral of the velocity error (a position drift)
int(psi) dt                0.2 rad s
inputs d_lat .. d_col      0.4             40 % of full stick for a typical manoeuvre,
                                           so steps and 5 m/s turns stay clear of |delta| = 1
=========================  ==============  ==============================================

With these defaults the 1 m / 2 m position steps and the 5 m/s circle of 30 m radius are flown
without saturation (``tests/unit/sim_vehicle/test_sim_control.py``,
``benchmarks/sitl_realtime.py``).

Fast prediction
---------------
:func:`simulate_closed_loop` predicts how the vehicle tracks a reference trajectory without
stepping :class:`FlightController` and RK4: the closed loop (plant, with its servo lag if any,
ZOH-discretised at the control rate, LQI, PID, feed-forward) is one linear system in the *reference heading frame*
(position error and PID integrator expressed in axes turned by the reference heading). Its
time-invariant part is diagonalised once per design and every mode is run through a C-level
first-order filter (``scipy.signal.lfilter``); the small rotation of those axes by the change
of reference heading enters as a correction input iterated to a fixed point. Where that does
not apply (PID integrators on a turning trajectory, heading jumps) a per-period recursion (one
matrix-vector product and a 2-D rotation per period) gives the same result. It neglects the
heading tracking error in the rotations, the command limits (speed, slew and heading-rate
limits, inactive on a feasible trajectory) and the input clipping
(``saturated`` reports whether the real loop would clip); it agrees with the full loop to
about a centimetre on unsaturated trajectories, and takes 10-30 ms of CPU for 60 s.

Pure numerics; python-control is imported lazily (it costs about 1.6 s).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg

from sim_vehicle.dynamics import IDX_PSI
from sim_vehicle.model import N_INPUTS, N_STATES, HeliModel
from sim_vehicle.typed_config import from_dict as _typed_from_dict
from sim_vehicle.typed_config import require_numbers

log = logging.getLogger(__name__)

N_LQI_STATES = N_STATES + 1
"""14: the hover model plus the heading."""
N_TRACKED = 4
"""Tracked outputs u, v, w, psi."""
TRACKED_INDICES = (0, 1, 2, IDX_PSI)

BRYSON_STATE_MAX: tuple[float, ...] = (
    0.5, 0.5, 0.5,        # u v w   (m/s)
    1.0, 1.0, 1.0,        # p q r   (rad/s)
    0.35, 0.35,           # phi theta (rad)
    0.1, 0.1,             # a b (rad)
    1.0, 1.0, 1.0,        # r_fb c d
    0.2,                  # psi (rad)
)
BRYSON_INTEGRATOR_MAX: tuple[float, ...] = (0.3, 0.3, 0.3, 0.2)
BRYSON_INPUT_MAX: tuple[float, ...] = (0.4, 0.4, 0.4, 0.4)


def bryson_weights(state_max, integrator_max, input_max) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Diagonal Q (18) and R (4) weights from the largest acceptable excursions (Bryson's rule)."""
    q = tuple(1.0 / float(v) ** 2 for v in (*state_max, *integrator_max))
    r = tuple(1.0 / float(v) ** 2 for v in input_max)
    return q, r


DEFAULT_Q_WEIGHTS, DEFAULT_R_WEIGHTS = bryson_weights(BRYSON_STATE_MAX, BRYSON_INTEGRATOR_MAX, BRYSON_INPUT_MAX)


class ControlError(ValueError):
    """Wrong controller arguments or settings; the message names the argument or key."""


# ============================================================================ settings
@dataclasses.dataclass(frozen=True)
class ControllerSettings:
    """Tunables of the flight controller (all have defaults; TOML tables override them).

    Attributes
    ----------
    control_dt_s : float
        Control period the LQI is designed for, s (100 Hz).
    q_weights : tuple of 18 float
        Diagonal of Q: 14 states ``[u v w p q r phi theta a b r_fb c d psi]`` then the 4
        integrators of ``u v w psi`` (Bryson defaults, see the module docstring).
    r_weights : tuple of 4 float
        Diagonal of R for ``[d_lat d_lon d_ped d_col]``.
    kp_xy_1_s, ki_xy_1_s2, kd_xy : float
        Horizontal PID position gains (velocity command per metre, per metre-second, and per
        m/s of velocity error).
    kp_z_1_s, ki_z_1_s2, kd_z : float
        Vertical PID position gains.
    pos_integral_max_m_s : float
        Clamp of each PID integrator's contribution to the velocity command, m/s.
    max_speed_xy_m_s : float
        Horizontal speed limit of the velocity command.
    max_climb_m_s, max_descent_m_s : float
        Vertical speed limits (up, down), m/s.
    max_accel_m_s2 : float
        Limit of the acceleration feed-forward magnitude, m/s^2.
    cmd_accel_xy_m_s2, cmd_accel_z_m_s2 : float
        Slew-rate limit of the velocity command (horizontal vector, vertical), m/s^2: a
        position step becomes a velocity ramp instead of a velocity step, so the rotor inputs
        do not saturate. Keep them above the trajectory's accelerations so they only act on
        steps and large errors.
    max_yaw_rate_rad_s : float
        Limit of the yaw-rate feed-forward and slew-rate limit of the heading reference,
        rad/s (a heading step is flown as a turn at this rate).
    """

    control_dt_s: float = 0.01
    q_weights: tuple[float, ...] = DEFAULT_Q_WEIGHTS
    r_weights: tuple[float, ...] = DEFAULT_R_WEIGHTS
    kp_xy_1_s: float = 1.0
    ki_xy_1_s2: float = 0.0
    kd_xy: float = 0.0
    kp_z_1_s: float = 1.0
    ki_z_1_s2: float = 0.0
    kd_z: float = 0.0
    pos_integral_max_m_s: float = 1.0
    max_speed_xy_m_s: float = 12.0
    max_climb_m_s: float = 3.0
    max_descent_m_s: float = 2.0
    max_accel_m_s2: float = 5.0
    cmd_accel_xy_m_s2: float = 3.0
    cmd_accel_z_m_s2: float = 2.0
    max_yaw_rate_rad_s: float = 1.5

    def __post_init__(self) -> None:
        positive = ("control_dt_s", "max_speed_xy_m_s", "max_climb_m_s", "max_descent_m_s",
                    "max_accel_m_s2", "max_yaw_rate_rad_s", "cmd_accel_xy_m_s2", "cmd_accel_z_m_s2")
        non_negative = ("kp_xy_1_s", "ki_xy_1_s2", "kd_xy", "kp_z_1_s", "ki_z_1_s2", "kd_z",
                        "pos_integral_max_m_s")
        require_numbers(ControlError, "controller", self, positive=positive, non_negative=non_negative)
        _check_weights(self.q_weights, N_LQI_STATES + N_TRACKED, "q_weights", allow_zero=True)
        _check_weights(self.r_weights, N_INPUTS, "r_weights", allow_zero=False)

    @classmethod
    def from_dict(cls, data: Any, prefix: str = "") -> "ControllerSettings":
        """Build from a (TOML) table; wrong keys or values raise :class:`ControlError` naming them."""
        return _typed_from_dict(cls, data, prefix, ControlError)


def _check_weights(w: Any, n: int, name: str, *, allow_zero: bool) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in w)
    except (TypeError, ValueError):
        raise ControlError(f"{name}: expected {n} numbers, got {w!r}") from None
    if len(values) != n:
        raise ControlError(f"{name}: expected {n} weights, got {len(values)}")
    for i, v in enumerate(values):
        if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
            bound = ">= 0" if allow_zero else "> 0"
            raise ControlError(f"{name}[{i}]: expected a finite weight {bound}, got {v!r}")
    return values


# ============================================================================ setpoints
@dataclasses.dataclass(frozen=True)
class Setpoint:
    """What the vehicle is asked to do; ``None`` = not commanded.

    A NaN entry inside a vector leaves that axis alone (MAVLink type_mask per axis). An axis
    with a position is position-controlled (the velocity and acceleration are its
    feed-forward); an axis with only a velocity is velocity-controlled (its position integrator
    is reset); an axis with neither brakes to zero velocity.

    Attributes
    ----------
    pos_ned_m : (3,) or None
    vel_ned_m_s : (3,) or None
    acc_ned_m_s2 : (3,) or None
    yaw_rad : float or None
    yaw_rate_rad_s : float or None
    """

    pos_ned_m: Any = None
    vel_ned_m_s: Any = None
    acc_ned_m_s2: Any = None
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None


def _axes(v: Any, name: str) -> tuple[float, float, float] | None:
    if v is None:
        return None
    try:
        a, b, c = (float(x) for x in v)
    except (TypeError, ValueError):
        raise ControlError(f"setpoint.{name}: expected 3 numbers, got {v!r}") from None
    for x in (a, b, c):
        if math.isinf(x):
            raise ControlError(f"setpoint.{name}: expected finite numbers (NaN = axis not commanded), got {v!r}")
    return a, b, c


# ============================================================================ LQI design
class LqiGains(NamedTuple):
    """A discrete LQI design (paper eqs. 5-7).

    Attributes
    ----------
    K : ndarray, shape (4, 18)
        ``delta = -K [x14 - x_ff; z]``.
    Kx : ndarray, shape (4, 14)
    Kz : ndarray, shape (4, 4)
    Ad : ndarray, shape (14, 14)
        ZOH discretisation of the 14-state model.
    Bd : ndarray, shape (14, 4)
    C : ndarray, shape (4, 14)
        Tracked outputs u, v, w, psi.
    dt_s : float
    closed_loop_eigenvalues : ndarray, shape (18,)
        Discrete closed-loop eigenvalues (all inside the unit circle).
    ff_map : ndarray, shape (18, 8)
        ``[x_ff; delta_ff] = ff_map @ [u', v', w', r_ref, u_ref, v_ref, w_ref, psi_ref]``.
    q_weights, r_weights : tuple of float
    """

    K: np.ndarray
    Kx: np.ndarray
    Kz: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    C: np.ndarray
    dt_s: float
    closed_loop_eigenvalues: np.ndarray
    ff_map: np.ndarray
    q_weights: tuple
    r_weights: tuple


def model_14(model: HeliModel) -> tuple[np.ndarray, np.ndarray]:
    """The paper's 14-state model: the hover model plus ``dpsi/dt = r``.

    Returns
    -------
    A14 : ndarray, shape (14, 14)
    B14 : ndarray, shape (14, 4)
    """
    A14 = np.zeros((N_LQI_STATES, N_LQI_STATES))
    A14[:N_STATES, :N_STATES] = model.A
    A14[IDX_PSI, 5] = 1.0
    B14 = np.zeros((N_LQI_STATES, N_INPUTS))
    B14[:N_STATES] = model.B
    return A14, B14


def zoh(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation via the block matrix exponential."""
    n, m = B.shape
    blk = np.zeros((n + m, n + m))
    blk[:n, :n] = A * dt_s
    blk[:n, n:] = B * dt_s
    E = scipy.linalg.expm(blk)
    return E[:n, :n], E[:n, n:]


def tracked_output_matrix() -> np.ndarray:
    """C (4, 14) selecting u, v, w, psi."""
    C = np.zeros((N_TRACKED, N_LQI_STATES))
    for row, col in enumerate(TRACKED_INDICES):
        C[row, col] = 1.0
    return C


def feedforward_map(model: HeliModel) -> np.ndarray:
    """Quasi-steady trim map, (18, 8): ``[x_ff; delta_ff] = F @ [u', v', w', r, u, v, w, psi]``.

    Solves ``A14 x + B delta = xdot_ff`` and ``C x = y_ref`` with ``xdot_ff`` zero except the
    body accelerations (rows u, v, w) and ``psi' = r_ref``.
    """
    A14, B14 = model_14(model)
    C = tracked_output_matrix()
    n, m = B14.shape
    S = np.zeros((n + N_TRACKED, n + m))
    S[:n, :n] = A14
    S[:n, n:] = B14
    S[n:, :n] = C
    rhs = np.zeros((n + N_TRACKED, 8))
    rhs[0, 0] = rhs[1, 1] = rhs[2, 2] = 1.0
    rhs[IDX_PSI, 3] = 1.0
    rhs[n:, 4:] = np.eye(N_TRACKED)
    try:
        return np.linalg.solve(S, rhs)
    except np.linalg.LinAlgError:
        raise ControlError("model: the trim equations are singular (u, v, w, psi cannot be held)") from None


def design_lqi(model: HeliModel, dt_s: float, q_weights, r_weights) -> LqiGains:
    """Design the discrete LQI with python-control (cached per model, step and weights).

    Parameters
    ----------
    model : HeliModel
    dt_s : float
        Control period, s.
    q_weights : sequence of 18 float
        Diagonal of Q over the 14 states and the 4 integrators (>= 0).
    r_weights : sequence of 4 float
        Diagonal of R (> 0).

    Returns
    -------
    LqiGains
    """
    dt_s = float(dt_s)
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ControlError(f"dt_s: expected a control period > 0 s, got {dt_s!r}")
    q = _check_weights(q_weights, N_LQI_STATES + N_TRACKED, "q_weights", allow_zero=True)
    r = _check_weights(r_weights, N_INPUTS, "r_weights", allow_zero=False)
    return model.cached(("lqi", dt_s, q, r), lambda: _design(model, dt_s, q, r))


def _design(model: HeliModel, dt_s: float, q: tuple, r: tuple) -> LqiGains:
    import control  # lazy: about 1.6 s

    A14, B14 = model_14(model)
    Ad, Bd = zoh(A14, B14, dt_s)
    C = tracked_output_matrix()
    sysd = control.ss(Ad, Bd, C, np.zeros((N_TRACKED, N_INPUTS)), dt_s)
    K, _S, E = control.dlqr(sysd, np.diag(q), np.diag(r), integral_action=C * dt_s)
    K = np.asarray(K, dtype=float)
    E = np.asarray(E)
    if np.max(np.abs(E)) >= 1.0:
        raise ControlError("q_weights: the LQI design is not stabilising "
                           "(closed-loop eigenvalue outside the unit circle)")
    for arr in (K, Ad, Bd, C):
        arr.setflags(write=False)
    log.debug("LQI designed: dt %.4f s, max |eig| %.4f", dt_s, float(np.max(np.abs(E))))
    return LqiGains(
        K=K, Kx=K[:, :N_LQI_STATES], Kz=K[:, N_LQI_STATES:], Ad=Ad, Bd=Bd, C=C, dt_s=dt_s,
        closed_loop_eigenvalues=E, ff_map=feedforward_map(model), q_weights=q, r_weights=r,
    )


# ============================================================================ controller
def _sqrt_gain(err_m: float, kp: float, accel: float) -> float:
    """Ratio command/error of the square-root position controller (see ``_proportional_term``)."""
    if kp <= 0.0:
        return 0.0
    linear_m = accel / (kp * kp)
    if err_m <= linear_m:
        return kp
    return math.sqrt(2.0 * accel * (err_m - 0.5 * linear_m)) / err_m


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi]."""
    return math.remainder(angle_rad, 2.0 * math.pi)


def _control_law(gains: LqiGains) -> np.ndarray:
    """``delta = L @ [ref8, x14_err, z]``, (4, 26); ref8 as ``ff_map``'s input with psi_ref = 0."""
    F = gains.ff_map
    Nx, Nd = F[:N_LQI_STATES], F[N_LQI_STATES:]
    G = Nd + gains.Kx @ Nx
    L = np.hstack([G, -gains.Kx, -gains.Kz])
    L.setflags(write=False)
    return L


class FlightController:
    """The vehicle's flight controller: PID position loop around the LQI (paper section 2.2).

    Parameters
    ----------
    model : HeliModel
    settings : ControllerSettings, optional

    Notes
    -----
    Call :meth:`reset` with the current state when the controller takes over (arming, mode
    change), then :meth:`update` once per control period. The LQI is designed for
    ``settings.control_dt_s``; :meth:`update` integrates with the ``dt_s`` it is given. The
    design uses the paper's 14-state model; a profile's servo lag is not part of it (the
    vehicle flies with it all the same, see the tests).

    Attributes
    ----------
    delta : ndarray, shape (4,)
        Last output, clipped to [-1, 1].
    delta_unclipped : ndarray, shape (4,)
        Last output before clipping (``|.| > 1`` where the rotor saturated).
    saturated : bool
        Whether the last output was clipped.
    vel_cmd_ned_m_s : ndarray, shape (3,)
        Last velocity command of the position loop (after its limits).
    yaw_ref_rad : float
        Heading reference the LQI tracks.
    """

    def __init__(self, model: HeliModel, settings: ControllerSettings | None = None) -> None:
        self.model = model
        self.settings = settings if settings is not None else ControllerSettings()
        s = self.settings
        self.gains = design_lqi(model, s.control_dt_s, s.q_weights, s.r_weights)
        self._law = model.cached(("law", s.control_dt_s, self.gains.q_weights, self.gains.r_weights),
                                 lambda: _control_law(self.gains))
        self._vec = np.zeros(self._law.shape[1])
        self.z = np.zeros(N_TRACKED)
        self.pos_integral_m = [0.0, 0.0, 0.0]
        self.yaw_ref_rad = 0.0
        self.saturated = False
        self.delta = np.zeros(N_INPUTS)
        self.delta_unclipped = np.zeros(N_INPUTS)
        self.vel_cmd_ned_m_s = np.zeros(3)
        self._cmd_prev = [0.0, 0.0, 0.0]

    def reset(self, x: np.ndarray) -> None:
        """Clear the integrators and hold the current heading (call when taking over)."""
        self.z = np.zeros(N_TRACKED)
        self.pos_integral_m = [0.0, 0.0, 0.0]
        self.yaw_ref_rad = float(x[IDX_PSI])
        self.saturated = False
        self.delta = np.zeros(N_INPUTS)
        self.delta_unclipped = np.zeros(N_INPUTS)
        c, s = math.cos(self.yaw_ref_rad), math.sin(self.yaw_ref_rad)
        u, v, w = float(x[0]), float(x[1]), float(x[2])
        self._cmd_prev = [c * u - s * v, s * u + c * v, w]
        self.vel_cmd_ned_m_s = np.array(self._cmd_prev)

    # ------------------------------------------------------------------ outer loop
    def _velocity_command(self, x, sp: Setpoint, dt_s: float, c: float, s: float):
        """PID position loop + velocity feed-forward.

        Returns the NED velocity command, acceleration and velocity feed-forward (3 each), which
        axes are position-controlled, and the position setpoint (or None).
        """
        st = self.settings
        pos = _axes(sp.pos_ned_m, "pos_ned_m")
        vel = _axes(sp.vel_ned_m_s, "vel_ned_m_s")
        acc = _axes(sp.acc_ned_m_s2, "acc_ned_m_s2")
        u, v, w = float(x[0]), float(x[1]), float(x[2])
        vel_now = (c * u - s * v, s * u + c * v, w)
        cmd = [0.0, 0.0, 0.0]
        acc_ff = [0.0, 0.0, 0.0]
        vel_ff = [0.0, 0.0, 0.0]
        pid_active = [False, False, False]
        p_term = self._proportional_term(x, pos)
        for i in range(3):
            ki, kd = (st.ki_xy_1_s2, st.kd_xy) if i < 2 else (st.ki_z_1_s2, st.kd_z)
            v_ff = vel[i] if vel is not None and vel[i] == vel[i] else None
            a_ff = acc[i] if acc is not None and acc[i] == acc[i] else 0.0
            if pos is not None and pos[i] == pos[i]:
                vf = 0.0 if v_ff is None else v_ff
                cmd[i] = vf + p_term[i] + ki * self.pos_integral_m[i] + kd * (vf - vel_now[i])
                pid_active[i] = True
                acc_ff[i] = a_ff
                vel_ff[i] = vf
            elif v_ff is not None:
                cmd[i] = v_ff
                self.pos_integral_m[i] = 0.0
                acc_ff[i] = a_ff
                vel_ff[i] = v_ff
            else:
                self.pos_integral_m[i] = 0.0
        return cmd, acc_ff, vel_ff, pid_active, pos

    def _proportional_term(self, x, pos) -> list:
        """P term of the position loop: linear near the target, square root far from it.

        ArduPilot's ``sqrt_controller``: beyond ``a / kp^2`` the velocity command grows as
        ``sqrt(2 a (|e| - a / (2 kp^2)))`` so that the vehicle can stop from it at deceleration
        ``a`` without overshoot; within it, it is ``kp e`` (small errors and trajectory tracking
        stay linear). ``a`` is half the command slew limit, which leaves the inner loop margin
        to follow the braking ramp. Horizontal error is treated as a vector.
        """
        st = self.settings
        out = [0.0, 0.0, 0.0]
        if pos is None:
            return out
        ex = pos[0] - float(x[14]) if pos[0] == pos[0] else 0.0
        ey = pos[1] - float(x[15]) if pos[1] == pos[1] else 0.0
        gain = _sqrt_gain(math.hypot(ex, ey), st.kp_xy_1_s, 0.5 * st.cmd_accel_xy_m_s2)
        out[0], out[1] = gain * ex, gain * ey
        if pos[2] == pos[2]:
            ez = pos[2] - float(x[16])
            out[2] = _sqrt_gain(abs(ez), st.kp_z_1_s, 0.5 * st.cmd_accel_z_m_s2) * ez
        return out

    def _limit(self, cmd: list, acc_ff: list, dt_s: float) -> tuple[list, list, list]:
        """Slew-rate, speed and acceleration limits; returns which axes were limited."""
        st = self.settings
        limited = [False, False, False]
        prev = self._cmd_prev
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
        self._cmd_prev = list(cmd)
        return cmd, acc_ff, limited

    def _heading_reference(self, x, sp: Setpoint, dt_s: float) -> tuple[float, float, bool]:
        """Heading reference (rad), yaw-rate feed-forward (rad/s), and whether it was slewed.

        A commanded heading is approached at most at ``max_yaw_rate_rad_s`` (a heading step
        becomes a ramp, so the pedal does not saturate); a yaw rate alone integrates the
        reference; neither holds it.
        """
        lim = self.settings.max_yaw_rate_rad_s
        rate = 0.0
        if sp.yaw_rate_rad_s is not None:
            rate = float(sp.yaw_rate_rad_s)
            if not math.isfinite(rate):
                raise ControlError(f"setpoint.yaw_rate_rad_s: expected a finite number, got {sp.yaw_rate_rad_s!r}")
            rate = max(-lim, min(lim, rate))
        limited = False
        if sp.yaw_rad is not None:
            yaw = float(sp.yaw_rad)
            if not math.isfinite(yaw):
                raise ControlError(f"setpoint.yaw_rad: expected a finite number, got {sp.yaw_rad!r}")
            # slew the reference the short way round at most at the yaw-rate limit
            turn = wrap_pi(yaw - self.yaw_ref_rad)
            max_turn = lim * dt_s
            if abs(turn) > max_turn:
                self.yaw_ref_rad = wrap_pi(self.yaw_ref_rad + math.copysign(max_turn, turn))
                limited = True
            else:
                self.yaw_ref_rad = yaw
        elif sp.yaw_rate_rad_s is not None:
            self.yaw_ref_rad = wrap_pi(self.yaw_ref_rad + rate * dt_s)
        return self.yaw_ref_rad, rate, limited

    # ------------------------------------------------------------------ the update
    def update(self, x: np.ndarray, setpoint: Setpoint, dt_s: float) -> np.ndarray:
        """One control period: setpoint and state in, rotor inputs out.

        Parameters
        ----------
        x : ndarray, shape (17,) or (21,)
            Simulation state (see :mod:`sim_vehicle.dynamics`).
        setpoint : Setpoint
        dt_s : float
            Time since the previous update, s.

        Returns
        -------
        delta : ndarray, shape (4,)
            ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1]. ``self.saturated`` tells whether it
            was clipped.
        """
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"dt_s: expected a period > 0 s, got {dt_s!r}")
        psi = float(x[IDX_PSI])
        c, s = math.cos(psi), math.sin(psi)
        cmd, acc_ff, vel_ff, pid_active, pos = self._velocity_command(x, setpoint, dt_s, c, s)
        cmd, acc_ff, limited = self._limit(cmd, acc_ff, dt_s)
        yaw_ref, rate_ref, yaw_limited = self._heading_reference(x, setpoint, dt_s)
        self.vel_cmd_ned_m_s = np.array(cmd)

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

        vec = self._vec
        vec[0:8] = (axb, ayb, azb, rate_ref, ub, vb, wb, 0.0)
        vec[8:8 + N_STATES] = x[:N_STATES]
        vec[8 + N_STATES] = psi_err
        vec[8 + N_LQI_STATES:] = self.z
        raw = (self._law @ vec).tolist()
        delta = [(-1.0 if d < -1.0 else (1.0 if d > 1.0 else d)) for d in raw]
        saturated = any(abs(d) > 1.0 for d in raw)
        self.saturated = saturated

        # integrators with conditional-integration anti-windup
        if not saturated:
            z = self.z
            if not (limited[0] or limited[1] or limited[2]):
                # a slewing or speed-limited command is a ramp the integrators must not chase
                z[0] += dt_s * (float(x[0]) - ub)
                z[1] += dt_s * (float(x[1]) - vb)
                z[2] += dt_s * (float(x[2]) - wb)
            if not yaw_limited:
                z[3] += dt_s * psi_err
        st = self.settings
        for i in range(3):
            if pid_active[i] and not saturated and not limited[i]:
                ki = st.ki_xy_1_s2 if i < 2 else st.ki_z_1_s2
                e = pos[i] - float(x[14 + i])
                new = self.pos_integral_m[i] + dt_s * e
                if ki > 0:
                    cap = st.pos_integral_max_m_s / ki
                    new = max(-cap, min(cap, new))
                self.pos_integral_m[i] = new
        self.delta = np.array(delta)
        self.delta_unclipped = np.array(raw)
        return self.delta


# ============================================================================ fast prediction
@dataclasses.dataclass(frozen=True)
class ClosedLoopResult:
    """Predicted tracking of a reference trajectory (:func:`simulate_closed_loop`).

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        The sample times asked for.
    pos_ned_m : ndarray, shape (K, 3)
        Predicted vehicle position.
    delta : ndarray, shape (K, 4)
        Predicted rotor inputs *before* clipping (``|delta| > 1`` means the real controller
        would saturate there).
    tracking_error_m : ndarray, shape (K,)
        Distance between the vehicle and the reference position.
    saturated : bool
        True if any ``|delta| > 1``: the trajectory asks more than the rotor can give; after
        the first saturation the (linear) prediction is optimistic.
    max_abs_delta : float
        Largest ``|delta|`` over the trajectory.
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    delta: np.ndarray
    tracking_error_m: np.ndarray
    saturated: bool
    max_abs_delta: float

    @property
    def rms_tracking_error_m(self) -> float:
        """Root mean square of :attr:`tracking_error_m`."""
        return float(np.sqrt(np.mean(self.tracking_error_m ** 2)))

    @property
    def max_tracking_error_m(self) -> float:
        """Largest tracking error."""
        return float(np.max(self.tracking_error_m))


# closed-loop state layout of the fast prediction
_S_X = slice(0, 14)        # x14 with psi replaced by psi - psi_ref
_S_E = slice(14, 17)       # position error p_ref - p in reference-heading axes
_S_Z = slice(17, 21)       # LQI integrators
_S_I = slice(21, 24)       # PID integrators in reference-heading axes
_N_S = 24                  # then, with servo lag, the 4 actuator positions (24:28)
# exogenous input per control period: [acc_b (3), r_ref, vff_b (3), dp_ref_b (3), dpsi_ref]
_N_W = 11


class _ClosedLoop(NamedTuple):
    Ms: np.ndarray      # (n_s + 3, n_s) rows: x14+, e + dp - I, z+, zeta+, act+, I (position increment)
    Mw: np.ndarray      # (n_s + 3, 11)
    Ks: np.ndarray      # (4, n_s) delta = Ks s + Kw w
    Kw: np.ndarray      # (4, 11)
    Nx: np.ndarray      # (18, 8) trim map (for the initial state)
    dt_s: float
    n_s: int                      # closed-loop state size: 24, or 28 with servo lag
    modal: tuple | None           # modal form of Ms[:n_s, :n_s] (None: ill-conditioned)
    pid_integral: bool            # PID integrators active (Ki > 0)


def _integral_zoh(A: np.ndarray, B: np.ndarray, C: np.ndarray, dt_s: float):
    """ZOH of (A, B) plus the integral over the step of ``C x``: returns Ad, Bd, Jx, Jd."""
    n, m = B.shape
    p = C.shape[0]
    blk = np.zeros((n + m + p, n + m + p))
    blk[:n, :n] = A
    blk[:n, n:n + m] = B
    blk[n + m:, :n] = C
    E = scipy.linalg.expm(blk * dt_s)
    return E[:n, :n], E[:n, n:n + m], E[n + m:, :n], E[n + m:, n:n + m]


def _plant_with_servos(model: HeliModel) -> tuple[np.ndarray, np.ndarray, int]:
    """The 14-state model, extended by first-order servos if the profile has a lag."""
    A14, B14 = model_14(model)
    if model.servo_tau_s <= 0.0:
        return A14, B14, 0
    k = 1.0 / model.servo_tau_s
    n = N_LQI_STATES + N_INPUTS
    A = np.zeros((n, n))
    A[:N_LQI_STATES, :N_LQI_STATES] = A14
    A[:N_LQI_STATES, N_LQI_STATES:] = B14
    A[N_LQI_STATES:, N_LQI_STATES:] = -k * np.eye(N_INPUTS)
    B = np.zeros((n, N_INPUTS))
    B[N_LQI_STATES:] = k * np.eye(N_INPUTS)
    return A, B, N_INPUTS


def _build_closed_loop(model: HeliModel, settings: ControllerSettings) -> _ClosedLoop:
    """The closed loop as ``s+ = Ms s + Mw w`` (before the rotation of the heading axes)."""
    gains = design_lqi(model, settings.control_dt_s, settings.q_weights, settings.r_weights)
    L = _control_law(gains)
    dt = settings.control_dt_s
    A_p, B_p, n_act = _plant_with_servos(model)
    n_s = _N_S + n_act
    plant = list(range(N_LQI_STATES)) + list(range(_N_S, n_s))     # plant states inside s
    C3 = np.zeros((3, A_p.shape[0]))
    C3[0, 0] = C3[1, 1] = C3[2, 2] = 1.0
    Ad, Bd, Jx, Jd = _integral_zoh(A_p, B_p, C3, dt)
    kp = np.diag([settings.kp_xy_1_s, settings.kp_xy_1_s, settings.kp_z_1_s])
    ki = np.diag([settings.ki_xy_1_s2, settings.ki_xy_1_s2, settings.ki_z_1_s2])
    kd = np.diag([settings.kd_xy, settings.kd_xy, settings.kd_z])
    Lcmd = L[:, 4:7]
    # cmd_b = (I + Kd) vff_b + Kp e + Ki zeta - Kd x[0:3]  -> as maps of s and w
    cmd_s = np.zeros((3, n_s))
    cmd_s[:, 0:3] = -kd
    cmd_s[:, _S_E] = kp
    cmd_s[:, _S_I] = ki
    cmd_w = np.zeros((3, _N_W))
    cmd_w[:, 4:7] = np.eye(3) + kd
    Ks = Lcmd @ cmd_s
    Ks[:, _S_X] += L[:, 8:8 + N_LQI_STATES]
    Ks[:, _S_Z] += L[:, 8 + N_LQI_STATES:]
    Kw = Lcmd @ cmd_w
    Kw[:, 0:4] += L[:, 0:4]
    # open-loop rows as maps of [s, delta, w]; rows n_s:n_s+3 are the position increment I
    nrow = n_s + 3
    inc = slice(n_s, n_s + 3)
    Ps = np.zeros((nrow, n_s))
    Pd = np.zeros((nrow, N_INPUTS))
    Pw = np.zeros((nrow, _N_W))
    Ps[np.ix_(plant, plant)] = Ad
    Pd[plant] = Bd
    Pw[IDX_PSI, 10] = -1.0                       # psi error loses the reference's turn
    Ps[14:17, _S_E] = np.eye(3)
    Pw[14:17, 7:10] = np.eye(3)                  # e + dp_ref (the increment I is removed below)
    Ps[inc, plant] = Jx
    Pd[inc] = Jd                                 # I = integral of body velocity over the step
    Ps[17:21, _S_Z] = np.eye(4)
    Ps[17:20, 0:3] += dt * np.eye(3)             # z += dt (x[0:3] - cmd_b)
    Ps[17:20] -= dt * cmd_s
    Pw[17:20] -= dt * cmd_w
    Ps[20, IDX_PSI] += dt                        # z_psi += dt psi_err
    Ps[21:24, _S_I] = np.eye(3)
    Ps[21:24, _S_E] += dt * np.eye(3)            # zeta += dt e
    Ms = Ps + Pd @ Ks
    Mw = Pw + Pd @ Kw
    Ms[14:17] -= Ms[inc]
    Mw[14:17] -= Mw[inc]
    for arr in (Ms, Mw, Ks, Kw):
        arr.setflags(write=False)
    return _ClosedLoop(Ms=Ms, Mw=Mw, Ks=Ks, Kw=Kw, Nx=gains.ff_map, dt_s=dt, n_s=n_s,
                       modal=_modal_form(Ms[:n_s, :n_s]),
                       pid_integral=settings.ki_xy_1_s2 > 0.0 or settings.ki_z_1_s2 > 0.0)


def _modal_form(Phi: np.ndarray) -> tuple | None:
    """Real modes and one of each conjugate pair of ``Phi``, or None if ill-conditioned.

    Returns ``(real_idx, real_lam, W_r, V_r, pair_lam, W_c, V_c)`` with ``Phi = V diag(lam)
    V^-1`` split so that ``s = V_r q_r + 2 Re(V_c q_c)`` and ``q = W s`` per group.
    """
    try:
        lam, V = np.linalg.eig(Phi)
        if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > 1e6:
            return None
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:
        return None
    real = np.abs(lam.imag) <= 1e-12
    upper = lam.imag > 1e-12
    if int(np.count_nonzero(upper)) * 2 + int(np.count_nonzero(real)) != lam.size:
        return None
    real_idx = np.nonzero(real)[0]
    return (real_idx, lam[real].real, Vinv[real].real, V[:, real].real,
            lam[upper], Vinv[upper], V[:, upper])


def _check_reference(t_s, pos, vel, acc, yaw) -> tuple[np.ndarray, ...]:
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ControlError(f"t_s: expected shape (K,) with K >= 2, got {t.shape}")
    k = t.size
    out = [t]
    for name, arr, shape in (("pos_ned_m", pos, (k, 3)), ("vel_ned_m_s", vel, (k, 3)),
                             ("acc_ned_m_s2", acc, (k, 3)), ("yaw_rad", yaw, (k,))):
        a = np.asarray(arr, dtype=float)
        if a.shape != shape:
            raise ControlError(f"{name}: expected shape {shape}, got {a.shape}")
        out.append(a)
    for name, a in zip(("t_s", "pos_ned_m", "vel_ned_m_s", "acc_ned_m_s2", "yaw_rad"), out):
        if not np.all(np.isfinite(a)):
            raise ControlError(f"{name}: contains NaN or infinite values")
    if np.any(np.diff(t) <= 0):
        raise ControlError("t_s: sample times must be strictly increasing")
    return tuple(out)


def _resample(t_s: np.ndarray, grid: np.ndarray, arr: np.ndarray) -> np.ndarray:
    if grid.shape == t_s.shape and np.allclose(grid, t_s, rtol=0.0, atol=1e-9):
        return arr
    if arr.ndim == 1:
        return np.interp(grid, t_s, arr)
    return np.stack([np.interp(grid, t_s, arr[:, j]) for j in range(arr.shape[1])], axis=1)


def simulate_closed_loop(
    model: HeliModel,
    t_s,
    pos_ned_m,
    vel_ned_m_s,
    acc_ned_m_s2,
    yaw_rad,
    settings: ControllerSettings | None = None,
    *,
    yaw_rate_rad_s=None,
    x0: np.ndarray | None = None,
) -> ClosedLoopResult:
    """Predict how the flight controller tracks a reference trajectory (fast, no RK4 loop).

    The reference is resampled at the control rate; the closed loop (ZOH plant, LQI, PID,
    feed-forward) runs as one linear recursion in reference-heading axes (see the module
    docstring). A 60 s trajectory takes 10-30 ms of CPU.

    Parameters
    ----------
    model : HeliModel
    t_s : array_like, shape (K,)
        Strictly increasing sample times, s.
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : array_like, shape (K, 3)
        Reference position, velocity and acceleration (the setpoint stream).
    yaw_rad : array_like, shape (K,)
        Reference heading.
    settings : ControllerSettings, optional
    yaw_rate_rad_s : array_like, shape (K,), optional
        Yaw-rate feed-forward, if the setpoints carry one (None: not sent, as in
        ``Setpoint(yaw_rate_rad_s=None)``).
    x0 : ndarray, shape (17,) or (21,), optional
        Initial vehicle state; default: trimmed on the reference at ``t_s[0]`` (zero error).

    Returns
    -------
    ClosedLoopResult
    """
    settings = settings if settings is not None else ControllerSettings()
    t, pos, vel, acc, yaw = _check_reference(t_s, pos_ned_m, vel_ned_m_s, acc_ned_m_s2, yaw_rad)
    if yaw_rate_rad_s is None:
        rate = np.zeros_like(t)
    else:
        rate = np.asarray(yaw_rate_rad_s, dtype=float)
        if rate.shape != t.shape or not np.all(np.isfinite(rate)):
            raise ControlError(f"yaw_rate_rad_s: expected {t.shape} finite values, got shape {rate.shape}")
    cl = model.cached(("closed_loop", settings), lambda: _build_closed_loop(model, settings))
    dt = cl.dt_s
    n = int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    grid = t[0] + dt * np.arange(n)
    yaw_u = np.unwrap(yaw)
    g_pos = _resample(t, grid, pos)
    g_vel = _resample(t, grid, vel)
    g_acc = _resample(t, grid, acc)
    g_yaw = _resample(t, grid, yaw_u)
    g_rate = _resample(t, grid, rate)

    # exogenous inputs in reference-heading axes
    c, s = np.cos(g_yaw), np.sin(g_yaw)
    w = np.zeros((n, _N_W))
    vfx = c * g_vel[:, 0] + s * g_vel[:, 1]
    vfy = -s * g_vel[:, 0] + c * g_vel[:, 1]
    w[:, 0] = c * g_acc[:, 0] + s * g_acc[:, 1] + g_rate * vfy
    w[:, 1] = -s * g_acc[:, 0] + c * g_acc[:, 1] - g_rate * vfx
    w[:, 2] = g_acc[:, 2]
    w[:, 3] = g_rate
    w[:, 4], w[:, 5], w[:, 6] = vfx, vfy, g_vel[:, 2]
    dp = np.zeros((n, 3))
    dp[:-1] = np.diff(g_pos, axis=0)
    w[:, 7] = c * dp[:, 0] + s * dp[:, 1]
    w[:, 8] = -s * dp[:, 0] + c * dp[:, 1]
    w[:, 9] = dp[:, 2]
    dpsi = np.zeros(n)
    dpsi[:-1] = np.diff(g_yaw)
    w[:, 10] = dpsi
    G = _tall_matmul(w, np.ascontiguousarray(cl.Mw.T))             # (n, n_s + 3)

    s0 = _initial_closed_loop_state(cl, x0, w[0], g_pos[0], g_yaw[0])
    states = _run_modal(cl, G, dpsi, s0)
    if states is None:
        states = _run_recursion(cl.Ms, G, dpsi, s0)

    delta = (_tall_matmul(states, np.ascontiguousarray(cl.Ks.T))
             + _tall_matmul(w, np.ascontiguousarray(cl.Kw.T)))
    e_b = states[:, _S_E]
    err = np.sqrt(np.sum(e_b * e_b, axis=1))
    p = np.empty((n, 3))
    p[:, 0] = g_pos[:, 0] - (c * e_b[:, 0] - s * e_b[:, 1])
    p[:, 1] = g_pos[:, 1] - (s * e_b[:, 0] + c * e_b[:, 1])
    p[:, 2] = g_pos[:, 2] - e_b[:, 2]
    max_abs = float(np.max(np.abs(delta)))
    return ClosedLoopResult(
        t_s=t,
        pos_ned_m=_resample(grid, t, p) if n > 1 else np.repeat(p, t.size, axis=0),
        delta=_resample(grid, t, delta) if n > 1 else np.repeat(delta, t.size, axis=0),
        tracking_error_m=_resample(grid, t, err) if n > 1 else np.repeat(err, t.size),
        saturated=max_abs > 1.0,
        max_abs_delta=max_abs,
    )


def _initial_closed_loop_state(cl: _ClosedLoop, x0, w0: np.ndarray, pos0: np.ndarray, yaw0: float) -> np.ndarray:
    """Closed-loop state at the first control period: trimmed on the reference, or from ``x0``."""
    s0 = np.zeros(cl.n_s)
    ref8 = np.array([w0[0], w0[1], w0[2], w0[3], w0[4], w0[5], w0[6], 0.0])
    trim = cl.Nx @ ref8                                  # [x_ff (14), delta_ff (4)]
    if x0 is None:
        s0[_S_X] = trim[:N_LQI_STATES]
        s0[IDX_PSI] = 0.0
        if cl.n_s > _N_S:
            s0[_N_S:] = np.clip(trim[N_LQI_STATES:], -1.0, 1.0)
        return s0
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim != 1 or x0.size not in (17, 21) or not np.all(np.isfinite(x0)):
        raise ControlError(f"x0: expected a finite state of shape (17,) or (21,), got {x0.shape}")
    s0[0:N_STATES] = x0[:N_STATES]
    s0[IDX_PSI] = wrap_pi(float(x0[IDX_PSI]) - yaw0)
    e = pos0 - x0[14:17]
    c, s = math.cos(yaw0), math.sin(yaw0)
    s0[14] = c * e[0] + s * e[1]
    s0[15] = -s * e[0] + c * e[1]
    s0[16] = e[2]
    if cl.n_s > _N_S:
        s0[_N_S:] = x0[17:21] if x0.size == 21 else 0.0
    return s0


def _tall_matmul(a: np.ndarray, b: np.ndarray, rows: int = 256) -> np.ndarray:
    """``a @ b`` for a tall ``a`` (n, k) and a small ``b`` (k, m), in blocks of rows.

    Blocks keep each BLAS call below the size at which OpenBLAS starts worker threads; on a
    loaded machine those threads wait for a core and make a 0.1 ms product take 10 ms.
    """
    n = a.shape[0]
    if n <= rows:
        return a @ b
    out = np.empty((n, b.shape[1]))
    for i in range(0, n, rows):
        np.matmul(a[i:i + rows], b, out=out[i:i + rows])
    return out


def _filter_modes(h_r: np.ndarray, h_c: np.ndarray, real_lam, cplx_lam) -> None:
    """Run every mode's first-order recursion ``q[k] = lam q[k-1] + h[k]`` in place."""
    from scipy.signal import lfilter

    for j, lam in enumerate(real_lam):
        h_r[j] = lfilter([1.0], [1.0, -lam], h_r[j])
    for j, lam in enumerate(cplx_lam):
        h_c[j] = lfilter([1.0], [1.0, -lam], h_c[j])


def _run_modal(cl: _ClosedLoop, G: np.ndarray, dpsi: np.ndarray, s0: np.ndarray,
               max_iterations: int = 12, tol_m: float = 1e-7) -> np.ndarray | None:
    """The recursion solved in modal form, each mode by a C-level IIR filter (``lfilter``).

    The non-rotating part is linear time-invariant, ``s+ = Phi s + g``; with
    ``Phi = V diag(lam) V^-1`` every mode is a first-order recursion (a conjugate pair is
    filtered once). The small rotations of the reference-heading axes enter as a correction
    input on the two horizontal error states, iterated to a fixed point: the error dynamics
    forget in about a second, during which the axes turn by a fraction of a radian, so each
    iteration shrinks the correction's change several times. By linearity an iteration only
    filters the correction's own response and evaluates the four outputs the correction
    needs. Returns None (use :func:`_run_recursion`) if the modal form is unavailable, the PID
    integrators are active on a turning trajectory (their slow modes make the iteration
    converge too slowly), the heading reference jumps, or the iteration does not reach
    ``tol_m``.
    """
    turning = bool(np.any(dpsi != 0.0))
    if cl.modal is None or (turning and (cl.pid_integral or float(np.max(np.abs(dpsi))) > 0.05)):
        return None
    _real_idx, real_lam, W_r, V_r, cplx_lam, W_c, V_c = cl.modal
    n = G.shape[0]
    n_s = cl.n_s
    drive = np.empty((n, n_s))
    drive[0] = s0
    drive[1:] = G[:-1, :n_s]
    # only real matrix products (a real-by-complex product is many times slower in numpy)
    h_r = np.ascontiguousarray(_tall_matmul(drive, np.ascontiguousarray(W_r.T)).T)       # (n_real, n)
    h_c = np.ascontiguousarray(_tall_matmul(drive, np.ascontiguousarray(W_c.real.T)).T
                               + 1j * _tall_matmul(drive, np.ascontiguousarray(W_c.imag.T)).T)
    _filter_modes(h_r, h_c, real_lam, cplx_lam)
    q_r, q_c = h_r, h_c
    if turning:
        # outputs the correction needs: e_x, e_y (rows 14, 15) and I_x, I_y (rows n_s, n_s + 1)
        cols = [14, 15, n_s, n_s + 1]
        Phi4 = cl.Ms[cols].T                                                 # (n_s, 4)
        out_r = V_r.T @ Phi4                                                 # (n_real, 4)
        out_re, out_im = 2.0 * V_c.real.T @ Phi4, -2.0 * V_c.imag.T @ Phi4   # (n_pairs, 4)
        in_r = np.ascontiguousarray(W_r[:, 14:16])                           # response to e_x, e_y
        in_c_re, in_c_im = np.ascontiguousarray(W_c[:, 14:16].real), np.ascontiguousarray(W_c[:, 14:16].imag)
        G4 = G[:, cols]
        trig = (np.cos(dpsi) - 1.0, np.sin(dpsi), np.cos(0.5 * dpsi) - 1.0, np.sin(0.5 * dpsi))
        corr = np.zeros((n, 2))
        dq_r = np.zeros_like(q_r)
        dq_c = np.zeros_like(q_c)
        converged = False
        for _ in range(max_iterations):
            tq_r, tq_c = q_r + dq_r, q_c + dq_c
            out = tq_r.T @ out_r + tq_c.real.T @ out_re + tq_c.imag.T @ out_im + G4
            new = _rotation_correction_xy(out, trig)
            change = float(np.max(np.abs(new - corr)))
            corr = new
            if change < tol_m:
                converged = True
                q_r, q_c = tq_r, tq_c
                break
            shifted = np.zeros((2, n))
            shifted[:, 1:] = corr[:-1].T
            dq_r = in_r @ shifted
            dq_c = in_c_re @ shifted + 1j * (in_c_im @ shifted)
            _filter_modes(dq_r, dq_c, real_lam, cplx_lam)
        if not converged:
            log.debug("modal prediction did not converge (last change %.3g m); stepping the recursion", change)
            return None
    return (_tall_matmul(np.ascontiguousarray(q_r.T), np.ascontiguousarray(V_r.T))
            + _tall_matmul(np.ascontiguousarray(q_c.real.T), np.ascontiguousarray(2.0 * V_c.real.T))
            + _tall_matmul(np.ascontiguousarray(q_c.imag.T), np.ascontiguousarray(-2.0 * V_c.imag.T)))


def _rotation_correction_xy(out4: np.ndarray, trig: tuple) -> np.ndarray:
    """Correction of the horizontal error for the turning reference axes.

    ``out4`` (n, 4) holds ``[e + dp - I (x, y), I (x, y)]`` of the non-rotating recursion;
    ``trig`` is ``(cos(dpsi) - 1, sin(dpsi), cos(dpsi/2) - 1, sin(dpsi/2))``. Returns (n, 2):
    ``(Rz(-dpsi) - 1)(e + dp) - (Rz(-dpsi/2) - 1) I``.
    """
    corr = np.empty((out4.shape[0], 2))
    cf, sf, ch, sh = trig
    ix, iy = out4[:, 2], out4[:, 3]
    ex, ey = out4[:, 0] + ix, out4[:, 1] + iy
    corr[:, 0] = cf * ex + sf * ey - (ch * ix + sh * iy)
    corr[:, 1] = -sf * ex + cf * ey - (-sh * ix + ch * iy)
    return corr


def _run_recursion(Ms: np.ndarray, G: np.ndarray, dpsi: np.ndarray, s0: np.ndarray) -> np.ndarray:
    """The per-period loop: ``s+ = rot(Ms s + G[k])``; one mat-vec and a few float operations.

    ``Ms`` (n_s + 3, n_s) and ``G`` give the next state in its own layout with the position
    error already reduced by the increment ``I`` (rows 14:17 = ``e + dp - I``), then ``I``
    itself (rows n_s:n_s + 3). On a turning period the error and the PID integrator are
    rotated by ``-dpsi`` and the increment by ``-dpsi / 2`` (midpoint heading).
    """
    n = G.shape[0]
    n_s = Ms.shape[1]
    rows = np.empty((n, Ms.shape[0]))
    rows[0, :n_s] = s0
    rows[0, n_s:] = 0.0
    cos_full, sin_full = np.cos(dpsi).tolist(), np.sin(dpsi).tolist()
    cos_half, sin_half = np.cos(0.5 * dpsi).tolist(), np.sin(0.5 * dpsi).tolist()
    turning = (dpsi != 0.0).tolist()
    matmul = np.matmul
    for k in range(n - 1):
        out = rows[k + 1]
        matmul(Ms, rows[k, :n_s], out=out)
        out += G[k]
        if turning[k]:
            o = out.tolist()
            ix, iy = o[n_s], o[n_s + 1]
            ex, ey = o[14] + ix, o[15] + iy
            zx, zy = o[21], o[22]
            cf, sf, ch, sh = cos_full[k], sin_full[k], cos_half[k], sin_half[k]
            # rotations by -dpsi and -dpsi/2: [c s; -s c]
            out[14] = cf * ex + sf * ey - (ch * ix + sh * iy)
            out[15] = -sf * ex + cf * ey - (-sh * ix + ch * iy)
            out[21] = cf * zx + sf * zy
            out[22] = -sf * zx + cf * zy
    return rows[:, :n_s]
