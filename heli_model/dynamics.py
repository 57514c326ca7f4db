"""Pure RK4 integration of the hover model plus yaw and NED position kinematics.

Paper section 2.1: the 13-state hover model (eq. 4, :mod:`heli_model.model`) extended by the
heading ``psi`` (``dpsi/dt = r``, the paper's 14th state) and by the position in the local NED
frame. Physics runs at 400 Hz of simulated time in the SITL (DESIGN section 5).

Full simulation state, one float64 vector of length :data:`STATE_SIZE` = 17::

    [u v w p q r phi theta a b r_fb c d | psi | north east down]

(body FRD velocities in m/s, rates in rad/s, angles in rad, position in m). When the profile
has a servo lag (``model.servo_tau_s > 0``) the vector is *extended* by the four lagged actuator
positions, length 21 (:func:`state_size`); then ``delta`` passed to :func:`step_rk4` is the
commanded input and the actuators follow ``d(act)/dt = (clip(delta) - act) / servo_tau_s``
inside the same RK4 step. :func:`hover_state` builds a state of the right length.

Modelling choices
-----------------
* **Trim.** The model is a perturbation model about trimmed hover: zero state and zero input is
  hover at rest, so no trim offset is added anywhere.
* **Saturation.** The input is clipped to ``|delta| <= 1`` (full stick travel) before use.
* **Kinematics: yaw-only rotation.** NED velocity is the body velocity rotated by the heading
  only, ``vel_ned = Rz(psi) [u, v, w]``, and ``dpsi/dt = r``. The hover model is linearised
  with small roll and pitch (its ``u`` and ``v`` rows already hold the linearised gravity
  projection ``-g theta``, ``g phi``); tilting the velocity by roll and pitch as well would add
  second-order terms the linear model does not have (a 5-degree trim pitch at 12 m/s would turn
  into a spurious 1 m/s climb). Heading, which is not small, is treated exactly.
* **Wind** enters as an airspeed difference: the aerodynamic derivatives (the ``u, v, w``
  columns of A) act on the velocity relative to the air, ``x' = A x + B delta - A[:, :3] w_b``
  with ``w_b = Rz(psi)^T wind_ned``. The wind in body axes is held constant over one physics
  step (evaluated at the step's initial heading; at 400 Hz a yaw rate of 1 rad/s turns it by
  0.14 degree per step).

Speed
-----
The 13-state core (with the servo states, if any) is linear and the input is constant over a
step, so the RK4 update of the core, *and* the RK4 stage values of ``u, v, w, r`` needed by the
kinematics, are fixed linear maps of ``[x, delta, w_b]``: one matrix per ``(model, dt)`` is
precomputed (cached on the model) and a step costs one small matrix-vector product plus a few
dozen float operations for the heading and position, whose RK4 stages then use exactly the
same stage states a textbook RK4 of the full 17-state system would use. :func:`step_rk4` is
therefore a classical RK4 step of the whole nonlinear system, equal to one of
:func:`derivative` up to rounding (with the body-axes wind of the step's start heading).

:func:`step_rk4` is the reference implementation, in numpy. The vehicle update runs the same
step compiled (:mod:`heli_model.rk4_kernel`, all sub-steps of an update in one call), bit for
bit equal to it; :func:`compiled_kernels` gives that module where it is (numba imported on the
first call, its BLAS products checked against numpy's once per matrix shape).
"""

from __future__ import annotations

import logging
import math
from types import ModuleType

import numpy as np

from heli_model.model import N_INPUTS, N_STATES, HeliModel

__all__ = [
    "ACT_SLICE",
    "IDX_PSI",
    "POS_SLICE",
    "STATE_SIZE",
    "DynamicsError",
    "actuator",
    "body_rates_rad_s",
    "check_state",
    "compiled_kernels",
    "derivative",
    "euler_rad",
    "hover_state",
    "pos_ned_m",
    "rk4_matrices",
    "state_size",
    "step_rk4",
    "vel_ned_m_s",
]

log = logging.getLogger(__name__)

STATE_SIZE = 17
"""Length of the simulation state without servo lag."""
IDX_PSI = 13
"""Index of the heading psi in the state."""
POS_SLICE = slice(14, 17)
"""North, east, down position in the state."""
ACT_SLICE = slice(17, 21)
"""Lagged actuator positions (only in the extended state of a servo-lag profile)."""

_U, _V, _W, _P, _Q, _R, _PHI, _THETA = range(8)
_KIN_ROWS = (_U, _V, _W, _R)


class DynamicsError(ValueError):
    """Wrong arguments to the dynamics (bad shape, non-finite input, dt <= 0); names the argument."""


# ---------------------------------------------------------------------------- state helpers
def state_size(model: HeliModel) -> int:
    """Length of the simulation state for ``model``: 17, or 21 with servo lag."""
    return STATE_SIZE + (N_INPUTS if model.servo_tau_s > 0.0 else 0)


def hover_state(model: HeliModel, pos_ned_m=(0.0, 0.0, 0.0), yaw_rad: float = 0.0) -> np.ndarray:
    """Trimmed hover at rest at a position and heading.

    Returns
    -------
    x : ndarray, shape (state_size(model),)
    """
    x = np.zeros(state_size(model))
    x[IDX_PSI] = float(yaw_rad)
    x[POS_SLICE] = np.asarray(pos_ned_m, dtype=float)
    return x


def pos_ned_m(x: np.ndarray) -> np.ndarray:
    """Position in the local NED frame, (3,) m."""
    return np.array(x[14:17], dtype=float)


def vel_ned_m_s(x: np.ndarray) -> np.ndarray:
    """Ground velocity in NED, (3,) m/s (body velocity rotated by the heading)."""
    c, s = math.cos(x[IDX_PSI]), math.sin(x[IDX_PSI])
    u, v, w = float(x[0]), float(x[1]), float(x[2])
    return np.array([c * u - s * v, s * u + c * v, w])


def euler_rad(x: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw ``[phi, theta, psi]``, (3,) rad; yaw is wrapped to (-pi, pi]."""
    psi = math.remainder(float(x[IDX_PSI]), 2.0 * math.pi)
    return np.array([float(x[_PHI]), float(x[_THETA]), psi])


def body_rates_rad_s(x: np.ndarray) -> np.ndarray:
    """Body rates ``[p, q, r]``, (3,) rad/s."""
    return np.array(x[3:6], dtype=float)


def actuator(model: HeliModel, x: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    """The inputs the rotor actually sees, (4,): lagged servo positions, or ``clip(delta)``."""
    if model.servo_tau_s > 0.0:
        return np.array(x[ACT_SLICE], dtype=float)
    if delta is None:
        return np.zeros(N_INPUTS)
    return np.clip(np.asarray(delta, dtype=float), -1.0, 1.0)


# ---------------------------------------------------------------------------- continuous model
def _core_matrices(model: HeliModel) -> tuple[np.ndarray, np.ndarray]:
    """Continuous linear core ``z' = Ac z + Bc [delta, w_b]``; z is x13 (+ actuators)."""
    A, B = model.A, model.B
    E = -A[:, 0:3]
    if model.servo_tau_s > 0.0:
        k = 1.0 / model.servo_tau_s
        n = N_STATES + N_INPUTS
        Ac = np.zeros((n, n))
        Ac[:N_STATES, :N_STATES] = A
        Ac[:N_STATES, N_STATES:] = B
        Ac[N_STATES:, N_STATES:] = -k * np.eye(N_INPUTS)
        Bc = np.zeros((n, N_INPUTS + 3))
        Bc[N_STATES:, :N_INPUTS] = k * np.eye(N_INPUTS)
        Bc[:N_STATES, N_INPUTS:] = E
    else:
        Ac = np.array(A)
        Bc = np.hstack([B, E])
    return Ac, Bc


def derivative(
    model: HeliModel, x: np.ndarray, delta: np.ndarray, wind_ned_m_s=None, *, wind_heading_rad: float | None = None
) -> np.ndarray:
    """Time derivative of the full state, the right-hand side that :func:`step_rk4` integrates.

    Parameters
    ----------
    model : HeliModel
    x : ndarray, shape (state_size(model),)
    delta : ndarray, shape (4,)
        Commanded input (clipped to [-1, 1]).
    wind_ned_m_s : ndarray, shape (3,), optional
        Wind (air velocity) in NED, m/s.
    wind_heading_rad : float, optional
        Heading used to turn the wind into body axes; default the heading of ``x``
        (:func:`step_rk4` uses the heading at the start of the step for all four stages).

    Returns
    -------
    xdot : ndarray, same shape as ``x``
    """
    x = np.asarray(x, dtype=float)
    check_state(model, x)
    d = np.clip(np.asarray(delta, dtype=float), -1.0, 1.0)
    psi = x[IDX_PSI]
    c, s = math.cos(psi), math.sin(psi)
    wn, we, wd = (0.0, 0.0, 0.0) if wind_ned_m_s is None else (float(v) for v in wind_ned_m_s)
    psi_w = psi if wind_heading_rad is None else wind_heading_rad
    cw, sw = math.cos(psi_w), math.sin(psi_w)
    wb = np.array([cw * wn + sw * we, -sw * wn + cw * we, wd])
    Ac, Bc = _core_matrices(model)
    n = Ac.shape[0]
    z = np.concatenate([x[:N_STATES], x[STATE_SIZE:]]) if n > N_STATES else x[:N_STATES]
    zdot = Ac @ z + Bc @ np.concatenate([d, wb])
    xdot = np.zeros_like(x)
    xdot[:N_STATES] = zdot[:N_STATES]
    if n > N_STATES:
        xdot[STATE_SIZE:] = zdot[N_STATES:]
    u, v, w, r = x[_U], x[_V], x[_W], x[_R]
    xdot[IDX_PSI] = r
    xdot[14] = c * u - s * v
    xdot[15] = s * u + c * v
    xdot[16] = w
    return xdot


# ---------------------------------------------------------------------------- discretisation
def rk4_matrices(model: HeliModel, dt_s: float) -> np.ndarray:
    """The precomputed linear part of one RK4 step, cached per ``(model, dt_s)``.

    Returns
    -------
    M : ndarray, shape (n + 12, n + 7), read-only
        ``M @ [z, delta, w_b]`` gives the next core state ``z+`` (first ``n`` rows; ``n`` = 13,
        or 17 with servo lag) followed by ``(u, v, w, r)`` at the RK4 stage states 2, 3, 4.
    """
    dt_s = float(dt_s)
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise DynamicsError(f"dt_s: expected a step > 0 s, got {dt_s!r}")
    return model.cached(("rk4", dt_s), lambda: _build_rk4_matrices(model, dt_s))


def _build_rk4_matrices(model: HeliModel, h: float) -> np.ndarray:
    Ac, Bc = _core_matrices(model)
    n, m = Bc.shape
    S1 = np.hstack([np.eye(n), np.zeros((n, m))])
    F = np.hstack([np.zeros((n, n)), Bc])

    def slope(S: np.ndarray) -> np.ndarray:
        return Ac @ S + F

    K1 = slope(S1)
    S2 = S1 + 0.5 * h * K1
    K2 = slope(S2)
    S3 = S1 + 0.5 * h * K2
    K3 = slope(S3)
    S4 = S1 + h * K3
    K4 = slope(S4)
    nxt = S1 + (h / 6.0) * (K1 + 2.0 * K2 + 2.0 * K3 + K4)
    rows = list(_KIN_ROWS)
    M = np.vstack([nxt, S2[rows], S3[rows], S4[rows]])
    M.setflags(write=False)
    return M


def check_state(model: HeliModel, x: np.ndarray) -> None:
    """Raise :class:`DynamicsError` unless ``x`` has the shape of ``model``'s state, (17,) or (21,)."""
    want = state_size(model)
    if x.shape != (want,):
        lag = f" (servo lag {model.servo_tau_s} s adds 4 actuator states)" if want != STATE_SIZE else ""
        raise DynamicsError(f"x: expected shape ({want},){lag}, got {x.shape}")


# ---------------------------------------------------------------------------- the step
def step_rk4(model: HeliModel, x: np.ndarray, delta, dt_s: float, wind_ned_m_s=None) -> np.ndarray:
    """One classical RK4 step of the full state with the input held constant.

    Pure: ``x`` is not modified.

    Parameters
    ----------
    model : HeliModel
    x : ndarray, shape (17,) or (21,) with servo lag
        State at the start of the step (see the module docstring for the layout).
    delta : array_like, shape (4,)
        Input ``[d_lat, d_lon, d_ped, d_col]``, clipped to [-1, 1]; the *commanded* input when
        the profile has a servo lag.
    dt_s : float
        Step, s (> 0); 1/400 in the SITL.
    wind_ned_m_s : array_like, shape (3,), optional
        Air velocity in NED, m/s, constant over the step. None or zeros = calm.

    Returns
    -------
    x_next : ndarray, same shape as ``x``
    """
    M = rk4_matrices(model, dt_s)
    if not isinstance(x, np.ndarray) or x.dtype != np.float64:
        x = np.asarray(x, dtype=float)
    n_total = x.shape[0] if x.ndim == 1 else -1
    n_core = M.shape[1] - 7
    lag = n_core > N_STATES
    if n_total != STATE_SIZE + (N_INPUTS if lag else 0):
        check_state(model, np.asarray(x, dtype=float))
    if type(delta) is np.ndarray and delta.shape == (4,):
        d0, d1, d2, d3 = delta.tolist()  # the fast path of the line below (the controller's output)
    else:
        d0, d1, d2, d3 = (float(v) for v in delta) if np.ndim(delta) == 1 and len(delta) == 4 else _bad_delta(delta)
    if not (d0 - d0 == 0.0 and d1 - d1 == 0.0 and d2 - d2 == 0.0 and d3 - d3 == 0.0):
        raise DynamicsError(f"delta: expected 4 finite inputs, got {list(delta)!r}")
    d0 = -1.0 if d0 < -1.0 else (1.0 if d0 > 1.0 else d0)
    d1 = -1.0 if d1 < -1.0 else (1.0 if d1 > 1.0 else d1)
    d2 = -1.0 if d2 < -1.0 else (1.0 if d2 > 1.0 else d2)
    d3 = -1.0 if d3 < -1.0 else (1.0 if d3 > 1.0 else d3)

    psi = float(x[IDX_PSI])
    c1, s1 = math.cos(psi), math.sin(psi)
    vec = np.empty(n_core + 7)
    vec[:N_STATES] = x[:N_STATES]
    if lag:
        vec[N_STATES:n_core] = x[STATE_SIZE:]
    vec[n_core] = d0
    vec[n_core + 1] = d1
    vec[n_core + 2] = d2
    vec[n_core + 3] = d3
    if wind_ned_m_s is None:
        vec[n_core + 4 :] = 0.0
    else:
        if type(wind_ned_m_s) is np.ndarray and wind_ned_m_s.shape == (3,):
            wn, we, wd = wind_ned_m_s.tolist()  # the fast path of the line below
        else:
            wn, we, wd = (float(v) for v in wind_ned_m_s)
        if not (wn - wn == 0.0 and we - we == 0.0 and wd - wd == 0.0):
            raise DynamicsError(f"wind_ned_m_s: expected 3 finite numbers, got {list(wind_ned_m_s)!r}")
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
    x_next[:N_STATES] = out[:N_STATES]
    x_next[IDX_PSI] = psi + h6 * (r1 + 2.0 * r2 + 2.0 * r3 + r4)
    x_next[14] = x[14] + dn
    x_next[15] = x[15] + de
    x_next[16] = x[16] + dd
    if lag:
        x_next[STATE_SIZE:] = out[N_STATES:n_core]
    return x_next


def _bad_delta(delta) -> tuple:
    raise DynamicsError(f"delta: expected 4 inputs [d_lat, d_lon, d_ped, d_col], got {delta!r}")


# ---------------------------------------------------------------------------- compiled kernels
_KERNELS: list[ModuleType] = []
_EXACT_SHAPES: dict[tuple[int, int], bool] = {}


def compiled_kernels(shape: tuple[int, int]) -> ModuleType | None:
    """:mod:`heli_model.rk4_kernel` if its matrix-vector products for matrices of ``shape`` are numpy's.

    Imports the module (and numba) on the first call; checks each shape once per process
    (:func:`heli_model.rk4_kernel.matvec_matches_numpy`). None where a product differs in a bit
    (numba's BLAS summing in another order than numpy's on this machine): the caller then keeps
    the numpy code, and a warning is logged once per shape.
    """
    ok = _EXACT_SHAPES.get(shape)
    if ok is None:
        ok = _check_kernel_shape(shape)
    return _KERNELS[0] if ok else None


def _check_kernel_shape(shape: tuple[int, int]) -> bool:
    if not _KERNELS:
        try:
            from heli_model import rk4_kernel  # lazy: numba costs about 0.25 s to import
        except ImportError as exc:  # numba is a dependency; without it the numpy code still runs
            log.warning("compiled kernels unavailable (%s): the numpy code runs instead (slower, same results)", exc)
            _EXACT_SHAPES[shape] = False
            return False
        _KERNELS.append(rk4_kernel)
    ok = _KERNELS[0].matvec_matches_numpy(shape)
    if not ok:
        log.warning(
            "compiled matrix-vector product for shape %s differs from numpy's in the last bits: "
            "the numpy code runs instead (slower, same results)",
            shape,
        )
    _EXACT_SHAPES[shape] = ok
    return ok
