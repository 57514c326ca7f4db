"""The closed loop of the flight controller as one linear recursion (for :mod:`heli_model.control.closed_loop`).

The plant (with its servo lag if any) is ZOH-discretised at the control rate together with the
integral of its body velocity over the step (the position increment); the LQI, the PID position
loop and the feed-forward close it. The state ``s`` holds the 14 LQI states with ``psi``
replaced by ``psi - psi_ref``, the position error and the PID integrators in reference-heading
axes, the LQI integrators and, with servo lag, the actuator positions; the exogenous input
``w`` per control period is ``[acc_b (3), r_ref, vff_b (3), dp_ref_b (3), dpsi_ref]``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from heli_model.control.lqi import control_law_matrix, design_lqi, model_14
from heli_model.control.settings import N_LQI_STATES, ControllerSettings
from heli_model.dynamics import IDX_PSI
from heli_model.model import N_INPUTS, HeliModel

# closed-loop state layout of the fast prediction
S_X = slice(0, 14)  # x14 with psi replaced by psi - psi_ref
S_E = slice(14, 17)  # position error p_ref - p in reference-heading axes
S_Z = slice(17, 21)  # LQI integrators
S_I = slice(21, 24)  # PID integrators in reference-heading axes
N_S = 24  # then, with servo lag, the 4 actuator positions (24:28)
# exogenous input per control period: [acc_b (3), r_ref, vff_b (3), dp_ref_b (3), dpsi_ref]
N_W = 11


class ClosedLoopModel(NamedTuple):
    """The closed loop ``s+ = Ms s + Mw w`` of one design, with its modal form (cached per model and settings)."""

    Ms: np.ndarray  # (n_s + 3, n_s) rows: x14+, e + dp - I, z+, zeta+, act+, I (position increment)
    Mw: np.ndarray  # (n_s + 3, 11)
    Ks: np.ndarray  # (4, n_s) delta = Ks s + Kw w
    Kw: np.ndarray  # (4, 11)
    Nx: np.ndarray  # (18, 8) trim map (for the initial state)
    dt_s: float
    n_s: int  # closed-loop state size: 24, or 28 with servo lag
    modal: tuple | None  # modal form of Ms[:n_s, :n_s] (None: ill-conditioned)
    pid_integral: bool  # PID integrators active (Ki > 0)


def _integral_zoh(A: np.ndarray, B: np.ndarray, C: np.ndarray, dt_s: float):
    """ZOH of (A, B) plus the integral over the step of ``C x``: returns Ad, Bd, Jx, Jd."""
    n, m = B.shape
    p = C.shape[0]
    blk = np.zeros((n + m + p, n + m + p))
    blk[:n, :n] = A
    blk[:n, n : n + m] = B
    blk[n + m :, :n] = C
    E = scipy.linalg.expm(blk * dt_s)
    return E[:n, :n], E[:n, n : n + m], E[n + m :, :n], E[n + m :, n : n + m]


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


def build_closed_loop(model: HeliModel, settings: ControllerSettings) -> ClosedLoopModel:
    """The closed loop as ``s+ = Ms s + Mw w`` (before the rotation of the heading axes)."""
    gains = design_lqi(model, settings.control_dt_s, settings.q_weights, settings.r_weights)
    L = control_law_matrix(gains)
    dt = settings.control_dt_s
    A_p, B_p, n_act = _plant_with_servos(model)
    n_s = N_S + n_act
    plant = list(range(N_LQI_STATES)) + list(range(N_S, n_s))  # plant states inside s
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
    cmd_s[:, S_E] = kp
    cmd_s[:, S_I] = ki
    cmd_w = np.zeros((3, N_W))
    cmd_w[:, 4:7] = np.eye(3) + kd
    Ks = Lcmd @ cmd_s
    Ks[:, S_X] += L[:, 8 : 8 + N_LQI_STATES]
    Ks[:, S_Z] += L[:, 8 + N_LQI_STATES :]
    Kw = Lcmd @ cmd_w
    Kw[:, 0:4] += L[:, 0:4]
    # open-loop rows as maps of [s, delta, w]; rows n_s:n_s+3 are the position increment I
    nrow = n_s + 3
    inc = slice(n_s, n_s + 3)
    Ps = np.zeros((nrow, n_s))
    Pd = np.zeros((nrow, N_INPUTS))
    Pw = np.zeros((nrow, N_W))
    Ps[np.ix_(plant, plant)] = Ad
    Pd[plant] = Bd
    Pw[IDX_PSI, 10] = -1.0  # psi error loses the reference's turn
    Ps[14:17, S_E] = np.eye(3)
    Pw[14:17, 7:10] = np.eye(3)  # e + dp_ref (the increment I is removed below)
    Ps[inc, plant] = Jx
    Pd[inc] = Jd  # I = integral of body velocity over the step
    Ps[17:21, S_Z] = np.eye(4)
    Ps[17:20, 0:3] += dt * np.eye(3)  # z += dt (x[0:3] - cmd_b)
    Ps[17:20] -= dt * cmd_s
    Pw[17:20] -= dt * cmd_w
    Ps[20, IDX_PSI] += dt  # z_psi += dt psi_err
    Ps[21:24, S_I] = np.eye(3)
    Ps[21:24, S_E] += dt * np.eye(3)  # zeta += dt e
    Ms = Ps + Pd @ Ks
    Mw = Pw + Pd @ Kw
    Ms[14:17] -= Ms[inc]
    Mw[14:17] -= Mw[inc]
    for arr in (Ms, Mw, Ks, Kw):
        arr.setflags(write=False)
    return ClosedLoopModel(
        Ms=Ms,
        Mw=Mw,
        Ks=Ks,
        Kw=Kw,
        Nx=gains.ff_map,
        dt_s=dt,
        n_s=n_s,
        modal=modal_form(Ms[:n_s, :n_s]),
        pid_integral=settings.ki_xy_1_s2 > 0.0 or settings.ki_z_1_s2 > 0.0,
    )


def modal_form(Phi: np.ndarray) -> tuple | None:
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
    return (real_idx, lam[real].real, Vinv[real].real, V[:, real].real, lam[upper], Vinv[upper], V[:, upper])
