"""Solvers of the closed-loop recursion: modal form with C-level IIR filters, or a per-period loop.

The closed loop of :func:`heli_model.control.closed_loop.simulate_closed_loop` is linear in the
reference heading frame: its time-invariant part, diagonalised once per design, runs mode by
mode through ``scipy.signal.lfilter`` (``run_modal``), the rotation by the change of reference
heading entering as a correction input iterated to a fixed point; where that does not apply
(PID integrators on a turning trajectory, heading jumps) ``run_recursion`` steps one
matrix-vector product and a 2-D rotation per period. Both give the same result.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from heli_model.control.closed_loop_model import ClosedLoopModel

log = logging.getLogger(__name__)


def tall_matmul(a: np.ndarray, b: np.ndarray, rows: int = 256) -> np.ndarray:
    """``a @ b`` for a tall ``a`` (n, k) and a small ``b`` (k, m), in blocks of rows.

    Blocks keep each BLAS call below the size at which OpenBLAS starts worker threads; on a
    loaded machine those threads wait for a core and make a 0.1 ms product take 10 ms.
    """
    n = a.shape[0]
    if n <= rows:
        return a @ b
    out = np.empty((n, b.shape[1]))
    for i in range(0, n, rows):
        np.matmul(a[i : i + rows], b, out=out[i : i + rows])
    return out


def _filter_modes(h_r: np.ndarray, h_c: np.ndarray, real_lam, cplx_lam) -> None:
    """Run every mode's first-order recursion ``q[k] = lam q[k-1] + h[k]`` in place."""
    from scipy.signal import lfilter

    for j, lam in enumerate(real_lam):
        h_r[j] = lfilter([1.0], [1.0, -lam], h_r[j])
    for j, lam in enumerate(cplx_lam):
        h_c[j] = lfilter([1.0], [1.0, -lam], h_c[j])


def run_modal(
    cl: ClosedLoopModel, G: np.ndarray, dpsi: np.ndarray, s0: np.ndarray, max_iterations: int = 12, tol_m: float = 1e-7
) -> np.ndarray | None:
    """The recursion solved in modal form, each mode by a C-level IIR filter (``lfilter``).

    The non-rotating part is linear time-invariant, ``s+ = Phi s + g``; with
    ``Phi = V diag(lam) V^-1`` every mode is a first-order recursion (a conjugate pair is
    filtered once). The small rotations of the reference-heading axes enter as a correction
    input on the two horizontal error states, iterated to a fixed point: the error dynamics
    forget in about a second, during which the axes turn by a fraction of a radian, so each
    iteration shrinks the correction's change several times. By linearity an iteration only
    filters the correction's own response and evaluates the four outputs the correction
    needs. Returns None (use :func:`run_recursion`) if the modal form is unavailable, the PID
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
    h_r = np.ascontiguousarray(tall_matmul(drive, np.ascontiguousarray(W_r.T)).T)  # (n_real, n)
    h_c = np.ascontiguousarray(
        tall_matmul(drive, np.ascontiguousarray(W_c.real.T)).T
        + 1j * tall_matmul(drive, np.ascontiguousarray(W_c.imag.T)).T
    )
    _filter_modes(h_r, h_c, real_lam, cplx_lam)
    q_r, q_c = h_r, h_c
    if turning:
        # outputs the correction needs: e_x, e_y (rows 14, 15) and I_x, I_y (rows n_s, n_s + 1)
        cols = [14, 15, n_s, n_s + 1]
        Phi4 = cl.Ms[cols].T  # (n_s, 4)
        out_r = V_r.T @ Phi4  # (n_real, 4)
        out_re, out_im = 2.0 * V_c.real.T @ Phi4, -2.0 * V_c.imag.T @ Phi4  # (n_pairs, 4)
        in_r = np.ascontiguousarray(W_r[:, 14:16])  # response to e_x, e_y
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
    return (
        tall_matmul(np.ascontiguousarray(q_r.T), np.ascontiguousarray(V_r.T))
        + tall_matmul(np.ascontiguousarray(q_c.real.T), np.ascontiguousarray(2.0 * V_c.real.T))
        + tall_matmul(np.ascontiguousarray(q_c.imag.T), np.ascontiguousarray(-2.0 * V_c.imag.T))
    )


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


def run_recursion(Ms: np.ndarray, G: np.ndarray, dpsi: np.ndarray, s0: np.ndarray) -> np.ndarray:
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
