"""The discrete LQI design (paper section 2.2, eqs. 5-7) and the per-tick control-law matrix.

Paper section 2.2, eqs. 5-7. The 13-state hover model (:mod:`heli_model.model`) plus the
heading ``psi`` (``dpsi/dt = r``) is discretised with a zero-order hold at the control rate
(100 Hz) and augmented with four integrators of the tracking error of the outputs
``y = [u, v, w, psi]``; the discrete LQR of the system augmented with the integrators
(``dlqr_integral``: python-control's ``dlqr(sys, Q, R, integral_action=C dt)``, its
operations on scipy's DARE solver) gives the gain ``K = [Kx Kz]`` (4 x 18) of ``delta = -Kx (x - x_ff) - Kz z + delta_ff``, with
``z[k+1] = z[k] + dt (y[k] - y_ref[k])``.

The quasi-steady feed-forward map solves, once per design, the linear trim equations

    [A14 B; C 0] [x_ff; delta_ff] = [xdot_ff; y_ref],
    xdot_ff = (u', v', w' = body acceleration, 0 ... 0, psi' = r_ref).

Pure numerics (numpy and scipy; python-control is not needed, so neither is the matplotlib
it requires).
"""

from __future__ import annotations

import logging
import math
from typing import NamedTuple

import numpy as np
import scipy.linalg

from heli_model.control.settings import N_LQI_STATES, N_TRACKED, TRACKED_INDICES, ControlError, check_weights
from heli_model.dynamics import IDX_PSI
from heli_model.model import N_INPUTS, N_STATES, HeliModel

log = logging.getLogger(__name__)


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
    """Design the discrete LQI (``dlqr_integral``; cached per model, step and weights).

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
    q = check_weights(q_weights, N_LQI_STATES + N_TRACKED, "q_weights", allow_zero=True)
    r = check_weights(r_weights, N_INPUTS, "r_weights", allow_zero=False)
    return model.cached(("lqi", dt_s, q, r), lambda: _design(model, dt_s, q, r))


def dlqr_integral(
    Ad: np.ndarray, Bd: np.ndarray, integral_action: np.ndarray, Q: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The discrete LQR of ``(Ad, Bd)`` augmented with integrators ``z+ = z + integral_action x``.

    The operations of python-control's ``dlqr(sys, Q, R, integral_action=...)`` (0.10, its
    scipy method: the DARE by ``scipy.linalg.solve_discrete_are`` with a zero cross term), in
    the same order, so the gains are bit-identical (``tests/unit/heli_model``) without
    python-control and the matplotlib it requires on a companion computer.

    Parameters
    ----------
    Ad : (n, n) array
    Bd : (n, m) array
    integral_action : (p, n) array
    Q : (n + p, n + p) array
    R : (m, m) array

    Returns
    -------
    K : (m, n + p) array
        The gain: ``u = -K [x, z]``.
    E : (n + p,) complex array
        The closed-loop eigenvalues.
    """
    n, m, p = Ad.shape[0], Bd.shape[1], integral_action.shape[0]
    A = np.block([[np.array(Ad, ndmin=2, dtype=float), np.zeros((n, p))], [integral_action, np.eye(p)]])
    B = np.vstack([np.array(Bd, ndmin=2, dtype=float), np.zeros((p, m))])
    S = np.zeros((n + p, m))
    X = scipy.linalg.solve_discrete_are(A, B, Q, R, e=None, s=S)
    K = scipy.linalg.solve(B.T @ X @ B + R, B.T @ X @ A + S.T)
    return K, scipy.linalg.eigvals(A - B @ K)


def _design(model: HeliModel, dt_s: float, q: tuple, r: tuple) -> LqiGains:
    A14, B14 = model_14(model)
    Ad, Bd = zoh(A14, B14, dt_s)
    C = tracked_output_matrix()
    K, E = dlqr_integral(
        Ad, Bd, C * dt_s, np.array(np.diag(q), ndmin=2, dtype=float), np.array(np.diag(r), ndmin=2, dtype=float)
    )
    K = np.asarray(K, dtype=float)
    E = np.asarray(E)
    if np.max(np.abs(E)) >= 1.0:
        raise ControlError(
            "q_weights: the LQI design is not stabilising (closed-loop eigenvalue outside the unit circle)"
        )
    for arr in (K, Ad, Bd, C):
        arr.setflags(write=False)
    log.debug("LQI designed: dt %.4f s, max |eig| %.4f", dt_s, float(np.max(np.abs(E))))
    return LqiGains(
        K=K,
        Kx=K[:, :N_LQI_STATES],
        Kz=K[:, N_LQI_STATES:],
        Ad=Ad,
        Bd=Bd,
        C=C,
        dt_s=dt_s,
        closed_loop_eigenvalues=E,
        ff_map=feedforward_map(model),
        q_weights=q,
        r_weights=r,
    )


def control_law_matrix(gains: LqiGains) -> np.ndarray:
    """``delta = L @ [ref8, x14_err, z]``, (4, 26); ref8 as ``ff_map``'s input with psi_ref = 0."""
    F = gains.ff_map
    Nx, Nd = F[:N_LQI_STATES], F[N_LQI_STATES:]
    G = Nd + gains.Kx @ Nx
    L = np.hstack([G, -gains.Kx, -gains.Kz])
    L.setflags(write=False)
    return L
