"""Compiled kernels of the pure vehicle update (numba): the RK4 sub-steps.

:func:`integrate_rk4` runs the ``n`` RK4 sub-steps of one update, with the ground stop after
each, in one call. It gives, bit for bit, what the numpy code gives
(:func:`heli_model.dynamics.step_rk4`, the reference implementation); the control law's kernels
are in :mod:`heli_model.control_kernel`:

* every expression is the numpy code's, in the same order, with the same grouping; numba
  compiles without fast-math, so LLVM neither reassociates nor fuses a multiply and an add;
* the matrix-vector products are ``np.dot``, which numba hands to BLAS's ``dgemv`` with the
  same transposition, scaling and kernel as numpy's ``@`` (OpenBLAS sums a row in its own
  order, which a hand-written loop would not reproduce). Whether numba's BLAS (scipy's) sums
  like numpy's on this machine is checked once per matrix shape: :func:`matvec_matches_numpy`;
* ``math.cos`` and ``math.sin`` are the C library's, the functions CPython's ``math`` calls.

This module imports numba: import it lazily (:func:`heli_model.dynamics.compiled_kernels`), so
that importing :mod:`heli_model` stays cheap. The kernels compile on their first call and stay in
numba's cache (``cache=True``, beside this file) for the next processes.

Shapes: ``M`` (n_core + 12, n_core + 7) from :func:`heli_model.dynamics.rk4_matrices`, ``x``
(17,) or (21,), ``delta`` (4,), ``wind`` (3 k,) (k rows of 3).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "OK",
    "BAD_ANGLE",
    "BAD_DELTA",
    "WIND_CALM",
    "WIND_CONSTANT",
    "WIND_PER_SUBSTEP",
    "integrate_rk4",
    "matvec",
    "matvec_matches_numpy",
]

N_STATES = 13
"""Hover-model states (:data:`heli_model.model.N_STATES`)."""
STATE_SIZE = 17
"""Simulation state without servo lag (:data:`heli_model.dynamics.STATE_SIZE`)."""

WIND_CALM = 0
"""``wind`` is ignored: calm air (the wind entries of the RK4 vector are zero, not computed)."""
WIND_CONSTANT = 1
"""The first row of ``wind`` for every sub-step."""
WIND_PER_SUBSTEP = 2
"""Row ``i`` of ``wind`` for sub-step ``i``."""

OK = -1
"""Status of :func:`integrate_rk4`: all sub-steps done."""
BAD_DELTA = -2
"""Status of :func:`integrate_rk4`: an input is not finite (a status >= 0 is the first wind row that is not)."""
BAD_ANGLE = -3
"""Status of :func:`integrate_rk4`: a heading of an RK4 stage is infinite (where ``math.cos`` raises)."""


@njit(cache=True)
def matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``M @ v`` through BLAS, as the kernels compute it."""
    return np.dot(M, v)


def matvec_matches_numpy(shape: tuple[int, int], trials: int = 16) -> bool:
    """Whether :func:`matvec` equals numpy's ``@`` bit for bit for matrices of ``shape`` (random ones).

    BLAS picks its summation kernel by shape and machine, once per process; a handful of random
    products with magnitudes over eight decades tells a different kernel apart at once.
    """
    rng = np.random.default_rng(20240611)
    for _ in range(trials):
        M = rng.normal(size=shape) * 10.0 ** rng.uniform(-4.0, 4.0, size=shape)
        v = rng.normal(size=shape[1]) * 10.0 ** rng.uniform(-4.0, 4.0, size=shape[1])
        if not np.array_equal(matvec(M, v), M @ v):
            return False
    return True


@njit(cache=True)
def _clip_unit(d: float) -> float:
    """``d`` clipped to [-1, 1], NaN kept (the numpy code's conditional expression)."""
    return -1.0 if d < -1.0 else (1.0 if d > 1.0 else d)


@njit(cache=True)
def _core_vector(M, x, d, wn, we, wd, calm, c1, s1):
    """``[z, delta, w_b]``, (n_core + 7,): the vector the RK4 matrix maps."""
    n_core = M.shape[1] - 7
    vec = np.empty(n_core + 7)
    vec[:N_STATES] = x[:N_STATES]
    if n_core > N_STATES:
        vec[N_STATES:n_core] = x[STATE_SIZE:]
    for k in range(4):
        vec[n_core + k] = d[k]
    if calm:
        vec[n_core + 4 :] = 0.0
    else:
        vec[n_core + 4] = c1 * wn + s1 * we
        vec[n_core + 5] = -s1 * wn + c1 * we
        vec[n_core + 6] = wd
    return vec


@njit(cache=True)
def rk4_substep(M, x, d, h, wn, we, wd, calm, x_next) -> bool:
    """One step of :func:`heli_model.dynamics.step_rk4` from ``x`` into ``x_next`` (same shape, not ``x``).

    False, ``x_next`` left undefined, where a stage heading is infinite: ``math.cos`` raises
    there in the numpy code (the heading of the step's start is checked by the caller).
    """
    n_core = M.shape[1] - 7
    psi = x[13]
    c1, s1 = math.cos(psi), math.sin(psi)
    out = np.dot(M, _core_vector(M, x, d, wn, we, wd, calm, c1, s1))
    u2, v2, w2, r2 = out[n_core], out[n_core + 1], out[n_core + 2], out[n_core + 3]
    u3, v3, w3, r3 = out[n_core + 4], out[n_core + 5], out[n_core + 6], out[n_core + 7]
    u4, v4, w4, r4 = out[n_core + 8], out[n_core + 9], out[n_core + 10], out[n_core + 11]
    u1, v1, w1, r1 = x[0], x[1], x[2], x[5]
    psi2 = psi + 0.5 * h * r1
    psi3 = psi + 0.5 * h * r2
    psi4 = psi + h * r3
    if math.isinf(psi2) or math.isinf(psi3) or math.isinf(psi4):
        return False
    c2, s2 = math.cos(psi2), math.sin(psi2)
    c3, s3 = math.cos(psi3), math.sin(psi3)
    c4, s4 = math.cos(psi4), math.sin(psi4)
    h6 = h / 6.0
    dn = h6 * ((c1 * u1 - s1 * v1) + 2.0 * (c2 * u2 - s2 * v2) + 2.0 * (c3 * u3 - s3 * v3) + (c4 * u4 - s4 * v4))
    de = h6 * ((s1 * u1 + c1 * v1) + 2.0 * (s2 * u2 + c2 * v2) + 2.0 * (s3 * u3 + c3 * v3) + (s4 * u4 + c4 * v4))
    dd = h6 * (w1 + 2.0 * w2 + 2.0 * w3 + w4)
    x_next[:N_STATES] = out[:N_STATES]
    x_next[13] = psi + h6 * (r1 + 2.0 * r2 + 2.0 * r3 + r4)
    x_next[14] = x[14] + dn
    x_next[15] = x[15] + de
    x_next[16] = x[16] + dd
    if n_core > N_STATES:
        x_next[STATE_SIZE:] = out[N_STATES:n_core]
    return True


@njit(cache=True)
def _stop_on_ground(x) -> None:
    """:func:`heli_model.vehicle_update.stop_on_ground`, in place on a fresh state."""
    if x[16] >= 0.0:
        x[16] = 0.0
        if x[2] > 0.0:
            x[2] = 0.0


@njit(cache=True)
def integrate_rk4(M, x, delta, h, n, wind, wind_mode, x_next):
    """``n`` RK4 sub-steps of ``h`` with the input held, each followed by the ground stop.

    Parameters
    ----------
    M : ndarray, shape (n_core + 12, n_core + 7)
        :func:`heli_model.dynamics.rk4_matrices` for ``h``.
    x : ndarray, shape (17,) or (21,)
        Not modified.
    delta : ndarray, shape (4,)
        Commanded input (clipped here).
    h : float
    n : int
    wind : ndarray, shape (3 k,)
        NED wind rows one after the other, used as ``wind_mode`` says (``k >= n`` for
        :data:`WIND_PER_SUBSTEP`).
    wind_mode : int
    x_next : ndarray, same shape as ``x``
        Output: the state after the ``n`` sub-steps (undefined unless the status is :data:`OK`).

    Returns
    -------
    status : int
        :data:`OK`, :data:`BAD_DELTA`, :data:`BAD_ANGLE`, or the index of the first wind row
        that is not finite (the first problem in the order the numpy code meets them).
    """
    for k in range(4):
        if not delta[k] - delta[k] == 0.0:
            return BAD_DELTA
    d = np.empty(4)
    for k in range(4):
        d[k] = _clip_unit(delta[k])
    calm = wind_mode == WIND_CALM
    src = x.copy()
    dst = np.empty(x.shape[0])
    for i in range(n):
        if math.isinf(src[13]):
            return BAD_ANGLE
        row = i if wind_mode == WIND_PER_SUBSTEP else 0
        wn, we, wd = wind[3 * row], wind[3 * row + 1], wind[3 * row + 2]
        if not calm and not (wn - wn == 0.0 and we - we == 0.0 and wd - wd == 0.0):
            return row
        if not rk4_substep(M, src, d, h, wn, we, wd, calm, dst):
            return BAD_ANGLE
        _stop_on_ground(dst)
        src, dst = dst, src
    x_next[:] = src
    return OK
