"""Bezier maths of one curve: Bernstein evaluation, derivatives, curvature, arc length, splitting.

Paper section 3.2, eq. (8): a degree-n Bezier curve with control points P_0..P_n is

    B(u) = sum_i C(n, i) (1 - u)^(n - i) u^i P_i,     u in [0, 1],

its derivative is the degree-(n-1) curve of the control points n (P_{i+1} - P_i), and its
curvature is kappa = |B' x B''| / |B'|^3 (in 2D the cross product is the scalar
x' y'' - y' x''). Arc length is integrated by composite Gauss-Legendre quadrature, a curve is
split with de Casteljau's algorithm, and degree elevation raises a piece to the common degree
of a chain (``bezier_path.BezierPath``) without changing it.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from companion.errors import SmoothingError

# ``clip_ufunc(a, lo, hi)``: the ufunc that ``np.clip`` calls, without its Python wrappers (a few
# microseconds a call); the same results, NaN and signed zeros included (``np.minimum(np.maximum(
# a, lo), hi)`` would turn -0.0 into 0.0).
if TYPE_CHECKING:  # numpy's stubs do not declare the private umath.clip
    clip_ufunc: np.ufunc
else:
    try:  # numpy >= 2
        from numpy._core.umath import clip as clip_ufunc
    except ImportError:  # numpy 1.26
        from numpy.core.umath import clip as clip_ufunc

__all__ = [
    "bernstein",
    "bernstein_family",
    "clip_ufunc",
    "evaluate",
    "derivative_control_points",
    "derivative",
    "norm_rows",
    "curvature_from_derivatives",
    "curvature",
    "gauss_legendre",
    "arc_length",
    "split",
    "elevate",
    "lower_degree",
    "evaluate_many",
    "elevate_lines",
    "as_control_points",
    "GAUSS_ORDER",
]

GAUSS_ORDER = 4


def as_control_points(ctrl: np.ndarray, name: str = "ctrl") -> np.ndarray:
    arr = np.asarray(ctrl, dtype=float)
    if arr.ndim != 2 or arr.shape[0] < 2 or arr.shape[1] < 1:
        raise SmoothingError(f"{name}: expected control points of shape (n+1, d) with n >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SmoothingError(f"{name}: control points must be finite (no NaN or inf)")
    return arr


@lru_cache(maxsize=32)
def _binomial_row(n: int) -> np.ndarray:
    """C(n, i) for i = 0..n, shape (n+1,) (a read-only constant)."""
    row = np.array([math.comb(n, i) for i in range(n + 1)], dtype=float)
    row.setflags(write=False)
    return row


def _powers(n: int, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """u^i and (1 - u)^i for i = 0..n, each shape (K, n+1), by repeated multiplication.

    One running product (``multiply.accumulate``) over [1, u, u, ...] and [1, v, v, ...]:
    u^i = u^(i-1) * u exactly as a loop over the columns would compute it.
    """
    factors = np.empty((2, u.size, n + 1))
    factors[:, :, 0] = 1.0
    factors[0, :, 1:] = u[:, None]
    factors[1, :, 1:] = (1.0 - u)[:, None]
    up, vp = np.multiply.accumulate(factors, axis=2)
    return up, vp


def bernstein(n: int, u: np.ndarray) -> np.ndarray:
    """Bernstein basis of degree ``n`` (paper eq. 8).

    Parameters
    ----------
    n : int
        Degree (>= 0).
    u : array_like, shape (K,)
        Curve parameters in [0, 1].

    Returns
    -------
    ndarray, shape (K, n + 1)
        ``C(n, i) (1 - u)^(n - i) u^i`` for i = 0..n.
    """
    up, vp = _powers(n, np.asarray(u, dtype=float).reshape(-1))
    return _binomial_row(n) * up * vp[:, ::-1]


def bernstein_family(degrees, u: np.ndarray) -> list[np.ndarray]:
    """Bernstein bases of several degrees at the same parameters, from one table of powers.

    Every basis equals ``bernstein(n, u)`` bit for bit (the powers of a lower degree are the
    first columns of those of a higher one).

    Parameters
    ----------
    degrees : sequence of int
        Degrees (>= 0).
    u : array_like, shape (K,)

    Returns
    -------
    list of ndarray, shapes (K, n + 1)
        One basis per degree, in the order of ``degrees``.
    """
    up, vp = _powers(max(degrees), np.asarray(u, dtype=float).reshape(-1))
    return [_binomial_row(n) * up[:, : n + 1] * vp[:, n::-1] for n in degrees]


def evaluate(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Points of one Bezier curve.

    Parameters
    ----------
    ctrl : array_like, shape (n+1, d)
        Control points.
    u : array_like, shape (K,)
        Parameters in [0, 1].

    Returns
    -------
    ndarray, shape (K, d)
    """
    ctrl = as_control_points(ctrl)
    return bernstein(ctrl.shape[0] - 1, u) @ ctrl


def derivative_control_points(ctrl: np.ndarray, order: int = 1) -> np.ndarray:
    """Control points of the ``order``-th derivative curve (hodograph).

    Parameters
    ----------
    ctrl : array_like, shape (n+1, d)
    order : int
        Derivative order >= 0. Beyond the degree the derivative is identically zero.

    Returns
    -------
    ndarray, shape (max(n+1-order, 1), d)
    """
    ctrl = np.asarray(ctrl, dtype=float)
    if order < 0:
        raise SmoothingError(f"order: must be >= 0, got {order}")
    n = ctrl.shape[0] - 1
    if order > n:
        return np.zeros((1, ctrl.shape[1]))
    out = ctrl
    for k in range(order):
        out = (n - k) * np.diff(out, axis=0)
    return out


def derivative(ctrl: np.ndarray, u: np.ndarray, order: int = 1) -> np.ndarray:
    """``order``-th derivative d^order B / du^order of one Bezier curve.

    Parameters
    ----------
    ctrl : array_like, shape (n+1, d)
    u : array_like, shape (K,)
    order : int

    Returns
    -------
    ndarray, shape (K, d)
    """
    ctrl = as_control_points(ctrl)
    dctrl = derivative_control_points(ctrl, order)
    return bernstein(dctrl.shape[0] - 1, u) @ dctrl


def norm_rows(a: np.ndarray) -> np.ndarray:
    """Euclidean norm along the last axis (faster than numpy.linalg.norm for small d)."""
    return np.sqrt(np.einsum("...i,...i->...", a, a))


def _cross_norm(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """|a x b| for rows of (K, d) arrays, exact formulas for d = 2 and 3."""
    dim = d1.shape[-1]
    if dim == 2:
        return np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    if dim == 3:
        return norm_rows(np.cross(d1, d2))
    gram = np.sum(d1 * d1, -1) * np.sum(d2 * d2, -1) - np.sum(d1 * d2, -1) ** 2
    return np.sqrt(np.maximum(gram, 0.0))


def curvature_from_derivatives(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Curvature |r' x r''| / |r'|^3 from first and second derivatives.

    Parameters
    ----------
    d1, d2 : ndarray, shape (K, d)
        First and second derivatives with respect to any regular parameter.

    Returns
    -------
    ndarray, shape (K,)
        Curvature (1/m); 0 where the speed |r'| vanishes.
    """
    speed = norm_rows(d1)
    num = _cross_norm(d1, d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.maximum(speed, 1e-300)
        kappa = np.where(speed > 0.0, num / (safe * safe * safe), 0.0)
    return kappa


def curvature(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Curvature (1/m) of one Bezier curve at parameters ``u`` (K,) -> (K,)."""
    ctrl = as_control_points(ctrl)
    return curvature_from_derivatives(derivative(ctrl, u, 1), derivative(ctrl, u, 2))


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1] (read-only constants for the default order)."""
    if n == GAUSS_ORDER:
        return _GL_NODES, _GL_WEIGHTS
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _frozen_gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


_GL_NODES, _GL_WEIGHTS = _frozen_gauss_legendre(GAUSS_ORDER)


def arc_length(ctrl: np.ndarray, u0: float = 0.0, u1: float = 1.0, intervals: int = 8) -> float:
    """Arc length of one Bezier curve between parameters ``u0`` and ``u1`` (m).

    Composite Gauss-Legendre quadrature (``GAUSS_ORDER`` nodes on each of ``intervals``
    sub-intervals) of the speed |B'(u)|.
    """
    ctrl = as_control_points(ctrl)
    x, w = gauss_legendre(GAUSS_ORDER)
    edges = np.linspace(u0, u1, intervals + 1)
    h = np.diff(edges)
    nodes = (edges[:-1, None] + h[:, None] * x[None, :]).ravel()
    speed = norm_rows(derivative(ctrl, nodes, 1)).reshape(intervals, -1)
    return float(np.sum(h * (speed @ w)))


def split(ctrl: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Split one Bezier curve at parameter ``u`` (de Casteljau).

    Returns
    -------
    left, right : ndarray, shape (n+1, d)
        Control points of the curve on [0, u] and on [u, 1], each re-parameterised to [0, 1].
    """
    ctrl = as_control_points(ctrl)
    n = ctrl.shape[0] - 1
    left = [ctrl[0]]
    right = [ctrl[-1]]
    level = ctrl
    for _ in range(n):
        level = (1.0 - u) * level[:-1] + u * level[1:]
        left.append(level[0])
        right.append(level[-1])
    return np.array(left), np.array(right[::-1])


def elevate(ctrl: np.ndarray, degree: int) -> np.ndarray:
    """Raise the degree of a Bezier curve without changing the curve or its parameterisation.

    Parameters
    ----------
    ctrl : array_like, shape (n+1, d)
    degree : int
        Target degree >= n.

    Returns
    -------
    ndarray, shape (degree+1, d)
    """
    out = np.asarray(ctrl, dtype=float)
    n = out.shape[0] - 1
    if degree < n:
        raise SmoothingError(f"degree: cannot lower the degree from {n} to {degree}")
    while n < degree:
        i = np.arange(1, n + 1)[:, None] / (n + 1)
        inner = i * out[:-1] + (1.0 - i) * out[1:]
        out = np.vstack([out[:1], inner, out[-1:]])
        n += 1
    return out


def lower_degree(ctrl: np.ndarray, degree: int) -> np.ndarray:
    """Exact degree reduction of a curve that was elevated from ``degree`` (interpolation)."""
    u = np.linspace(0.0, 1.0, degree + 1)
    pts = evaluate(ctrl, u)
    return np.linalg.solve(bernstein(degree, u), pts)


def elevate_lines(a: np.ndarray, b: np.ndarray, degree: int) -> np.ndarray:
    """Straight lines from ``a`` to ``b`` (K, d) as degree-``degree`` curves, shape (K, N+1, d)."""
    w, one_minus_w = _line_weights(degree)
    return a[:, None, :] * one_minus_w + b[:, None, :] * w


@lru_cache(maxsize=16)
def _line_weights(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Control-point weights w and 1 - w, shape (1, N+1, 1), of a line elevated to ``degree``."""
    w = np.linspace(0.0, 1.0, degree + 1)[None, :, None]
    out = (w, 1.0 - w)
    for x in out:
        x.setflags(write=False)
    return out


def evaluate_many(basis: np.ndarray, hod: np.ndarray) -> np.ndarray:
    """Many curves of one degree at the same parameters, as one matrix product.

    Parameters
    ----------
    basis : ndarray, shape (K, n+1)
        Bernstein basis of degree n at K parameters (``bernstein(n, u)``).
    hod : ndarray, shape (P, n+1, d)
        Control points of P curves of degree n (pieces or their hodographs).

    Returns
    -------
    ndarray, shape (K, P, d)
        Points of every curve at every parameter (parameter first: ``transpose(1, 0, 2)``
        gives the (P, K, d) view).
    """
    n_pieces, n1, d = hod.shape
    flat = np.ascontiguousarray(hod.transpose(1, 0, 2)).reshape(n1, n_pieces * d)
    return (basis @ flat).reshape(basis.shape[0], n_pieces, d)
