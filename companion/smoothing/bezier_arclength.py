"""Arc-length addressing of a chain of Bezier pieces: the knot table and its inverse.

Every piece's parameter range [0, 1] is cut into ``TABLE_INTERVALS`` equal intervals. For each
interval the table holds its arc length (composite Gauss-Legendre quadrature of the speed
|B'(u)|, ``GAUSS_ORDER`` nodes) and, at both ends, the exact derivatives du/ds = 1 / |B'| and
d2u/ds2 = -(B' . B'') / |B'|^4. Within an interval u(s) is the quintic Hermite interpolant of
these values, so a batch of K arc lengths is addressed by one ``searchsorted`` and one
polynomial evaluation (``locate``); ``arc_length_at`` inverts it exactly.

The table is built for all pieces at once: the Bernstein bases at the quadrature nodes and at
the knots are constants of the degree, and each evaluation is one matrix product over all
pieces and coordinates. The squared speed at the quadrature nodes comes from the Gram matrices
of the hodograph control points, which keeps the temporaries small (arrays of a few hundred
kilobytes cost fresh pages, and page faults, on every call).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TypeVar, cast

import numpy as np

from companion.smoothing.bezier_maths import (
    GAUSS_ORDER,
    bernstein,
    clip_ufunc,
    curvature_from_derivatives,
    gauss_legendre,
    norm_rows,
)

__all__ = [
    "TABLE_INTERVALS",
    "ArcLengthTable",
    "build_table",
    "knot_curvature",
    "locate",
    "arc_length_at",
    "arc_derivatives",
]

TABLE_INTERVALS = 16


@dataclass(frozen=True)
class ArcLengthTable:
    """Knot table of a chain of P pieces, G = ``TABLE_INTERVALS`` intervals per piece.

    Attributes
    ----------
    piece_start_s : ndarray, shape (P+1,)
        Arc length at the start of every piece, and the total length last (m).
    s_lo, h : ndarray, shape (P G,)
        Arc length at the start of every interval and its length (m).
    u_s, u_ss : ndarray, shape (P (G+1),)
        G du/ds and d2u/ds2 at the knots, piece after piece (G+1 knots each). Interval j is
        in piece j // G, starts at parameter (j % G) / G and at knot j + j // G.
    """

    piece_start_s: np.ndarray
    s_lo: np.ndarray
    h: np.ndarray
    u_s: np.ndarray
    u_ss: np.ndarray

    def hermite_args(self, j: np.ndarray) -> tuple[np.ndarray, ...]:
        """End slopes and second derivatives (m0, m1, c0, c1) of u(s) in intervals ``j`` (K,),
        scaled to the interval: the coefficients of ``_hermite_quintic``."""
        knot = j + j // TABLE_INTERVALS
        h = self.h[j]
        hh = h * (TABLE_INTERVALS * h)
        return h * self.u_s[knot], h * self.u_s[knot + 1], hh * self.u_ss[knot], hh * self.u_ss[knot + 1]


@lru_cache(maxsize=16)
def _bases(degree: int) -> tuple[np.ndarray, ...]:
    """Bernstein bases of the hodographs of a degree-``degree`` curve (read-only constants).

    With B_i the basis of the first hodograph (control points h_i) and C_j that of the second
    (control points k_j), |B'(u)|^2 = sum_ij B_i B_j (h_i . h_j) and B' . B'' =
    sum_ij B_i C_j (h_i . k_j): one matrix product each with the Gram matrices of the pieces.

    Returns
    -------
    squared_at_nodes : ndarray, shape (G GAUSS_ORDER, degree^2)
        B_i B_j at the quadrature nodes of every interval.
    squared_at_knots : ndarray, shape (G+1, degree^2)
    mixed_at_knots : ndarray, shape (G+1, degree (degree-1))
        B_i C_j at the knots.
    first_at_knots, second_at_knots : ndarray, shapes (G+1, degree) and (G+1, degree-1)
    """
    g = TABLE_INTERVALS
    knots = np.linspace(0.0, 1.0, g + 1)
    x, _ = gauss_legendre(GAUSS_ORDER)
    nodes = (knots[:-1, None] + (1.0 / g) * x[None, :]).ravel()
    at_nodes = bernstein(degree - 1, nodes)
    first, second = bernstein(degree - 1, knots), bernstein(degree - 2, knots)
    out = (
        (at_nodes[:, :, None] * at_nodes[:, None, :]).reshape(nodes.size, -1),
        (first[:, :, None] * first[:, None, :]).reshape(g + 1, -1),
        (first[:, :, None] * second[:, None, :]).reshape(g + 1, -1),
        first,
        second,
    )
    for a in out:
        a.setflags(write=False)
    return out


def _components(basis: np.ndarray, hod: np.ndarray) -> np.ndarray:
    """Curves ``hod`` (P', n, d) at the parameters of ``basis`` (K, n), as (K, d, P'): one matrix
    product, and every coordinate a contiguous (K, P') block."""
    n_pieces, n, d = hod.shape
    flat = np.ascontiguousarray(hod.transpose(1, 2, 0)).reshape(n, d * n_pieces)
    return (basis @ flat).reshape(basis.shape[0], d, n_pieces)


def _curved_knots(hod1: np.ndarray, hod2: np.ndarray) -> tuple[np.ndarray, ...]:
    """Interval lengths and knot values of P' curved pieces of one degree.

    Returns
    -------
    seg_len : ndarray, shape (P', G)
        Arc length of every interval (quadrature of the speed).
    speed, u_ss : ndarray, shape (P', G+1)
        |B'| and d2u/ds2 = -(B' . B'') / |B'|^4 at the knots.
    """
    g = TABLE_INTERVALS
    _, w = gauss_legendre(GAUSS_ORDER)
    squared_at_nodes, squared_at_knots, mixed_at_knots = _bases(hod1.shape[1])[:3]
    n_pieces = hod1.shape[0]
    gram = (hod1 @ hod1.transpose(0, 2, 1)).reshape(n_pieces, -1)  # (P', n^2)
    speed_nodes = squared_at_nodes @ gram.T  # (G Q, P')
    np.sqrt(np.maximum(speed_nodes, 0.0, out=speed_nodes), out=speed_nodes)
    seg_len = np.einsum("gqp,q->pg", speed_nodes.reshape(g, w.size, -1), w) / g
    del speed_nodes
    speed = squared_at_knots @ gram.T  # (G+1, P')
    np.sqrt(np.maximum(speed, 0.0, out=speed), out=speed)
    dot = mixed_at_knots @ (hod1 @ hod2.transpose(0, 2, 1)).reshape(n_pieces, -1).T
    safe = np.maximum(speed, 1e-300)
    u_ss = -dot / (safe * safe * safe * safe)
    return seg_len, speed.T, u_ss.T


def knot_curvature(hod1: np.ndarray, hod2: np.ndarray) -> np.ndarray:
    """Curvature (1/m) at the table knots of P' curved pieces of one degree, shape (P', G+1).

    Parameters
    ----------
    hod1, hod2 : ndarray, shapes (P', N, d) and (P', N-1, d)
        First and second hodographs.
    """
    first_at_knots, second_at_knots = _bases(hod1.shape[1])[3:]
    d1 = _components(first_at_knots, hod1).transpose(2, 0, 1)  # (P', G+1, d)
    return curvature_from_derivatives(d1, _components(second_at_knots, hod2).transpose(2, 0, 1))


def build_table(ctrl: np.ndarray, degrees: np.ndarray, hod1: np.ndarray, hod2: np.ndarray) -> ArcLengthTable:
    """Build the arc-length table of a chain.

    Parameters
    ----------
    ctrl : ndarray, shape (P, N+1, d)
        Control points, every piece elevated to degree N.
    degrees : ndarray of int, shape (P,)
        True degree of every piece: 1 for a straight line (its speed is constant), else N.
    hod1, hod2 : ndarray, shapes (P, N, d) and (P, N-1, d)
        First and second hodographs (N >= 2 if any piece is curved).

    Returns
    -------
    ArcLengthTable
    """
    n_pieces = ctrl.shape[0]
    g = TABLE_INTERVALS
    curved, line = degrees >= 2, degrees < 2
    seg_len = np.empty((n_pieces, g))
    speed_knots = np.empty((n_pieces, g + 1))
    u_ss_knots = np.zeros((n_pieces, g + 1))
    seg_len[line] = norm_rows(ctrl[line, -1] - ctrl[line, 0])[:, None] / g
    speed_knots[line] = norm_rows(hod1[line, 0])[:, None]
    if np.any(curved):
        seg_len[curved], speed_knots[curved], u_ss_knots[curved] = _curved_knots(hod1[curved], hod2[curved])
    piece_start_s = np.zeros(n_pieces + 1)
    np.cumsum(seg_len.sum(axis=1), out=piece_start_s[1:])
    s_lo = np.zeros((n_pieces, g))
    np.cumsum(seg_len[:, :-1], axis=1, out=s_lo[:, 1:])
    s_lo += piece_start_s[:-1, None]
    u_s = np.maximum(speed_knots, 1e-9 * max(float(piece_start_s[-1]), 1.0), out=speed_knots)
    np.divide(g, u_s, out=u_s)  # G du/ds
    return ArcLengthTable(
        piece_start_s=piece_start_s, s_lo=s_lo.ravel(), h=seg_len.ravel(), u_s=u_s.ravel(), u_ss=u_ss_knots.ravel()
    )


_Num = TypeVar("_Num", float, np.ndarray)  # all floats (one setpoint) or all arrays


def _hermite_quintic(x: _Num, m0: _Num, m1: _Num, c0: _Num, c1: _Num) -> _Num:
    """Quintic Hermite on [0, 1] from 0 to 1 with end slopes m0, m1 and second derivatives c0, c1."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    x5 = x4 * x
    return (
        (x - 6 * x3 + 8 * x4 - 3 * x5) * m0
        + (0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5) * c0
        + (0.5 * x3 - x4 + 0.5 * x5) * c1
        + (-4 * x3 + 7 * x4 - 3 * x5) * m1
        + (10 * x3 - 15 * x4 + 6 * x5)
    )


def _hermite_quintic_dx(x: np.ndarray, m0: np.ndarray, m1: np.ndarray, c0: np.ndarray, c1: np.ndarray) -> np.ndarray:
    """Derivative with respect to x of ``_hermite_quintic``."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    return (
        (1 - 18 * x2 + 32 * x3 - 15 * x4) * m0
        + (x - 4.5 * x2 + 6 * x3 - 2.5 * x4) * c0
        + (1.5 * x2 - 4 * x3 + 2.5 * x4) * c1
        + (-12 * x2 + 28 * x3 - 15 * x4) * m1
        + (30 * x2 - 60 * x3 + 30 * x4)
    )


def locate(table: ArcLengthTable, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map arc lengths to (piece index, piece parameter).

    Parameters
    ----------
    table : ArcLengthTable
    s_m : ndarray, shape (K,)
        Arc lengths (m); clipped to [0, total length].

    Returns
    -------
    piece : ndarray of int, shape (K,)
    u : ndarray, shape (K,)
    """
    s = clip_ufunc(s_m, 0.0, table.piece_start_s[-1])
    j = clip_ufunc(np.searchsorted(table.s_lo, s, side="right") - 1, 0, table.s_lo.size - 1)
    h = table.h[j]
    x = clip_ufunc((s - table.s_lo[j]) / np.maximum(h, 1e-300), 0.0, 1.0)
    piece, k = np.divmod(j, TABLE_INTERVALS)
    knot = j + piece  # the values of ``hermite_args(j)``
    hh = h * (TABLE_INTERVALS * h)
    args = (h * table.u_s[knot], h * table.u_s[knot + 1], hh * table.u_ss[knot], hh * table.u_ss[knot + 1])
    if x.shape == (1,):  # one point (a setpoint): the same arithmetic on Python floats
        frac = np.array([_hermite_quintic(float(x[0]), *(float(a[0]) for a in args))])
    else:
        frac = _hermite_quintic(x, *args)
    return piece, (k + clip_ufunc(frac, 0.0, 1.0)) / TABLE_INTERVALS


def arc_length_at(table: ArcLengthTable, piece: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Arc length (m) that ``locate`` maps to (piece (K,), u (K,)): its exact inverse.

    Found by Newton's method within the table interval (bisection where it does not
    converge), so ``locate(arc_length_at(p, u))`` returns (p, u) to about 1e-12.
    """
    g = TABLE_INTERVALS
    u = np.asarray(u, dtype=float)
    j = np.asarray(piece) * g + np.clip((u * g).astype(int), 0, g - 1)
    target = (u - (j % g) / g) * g
    args = table.hermite_args(j)
    x = target.copy()
    for _ in range(8):  # Newton, then bisection where needed
        step = (_hermite_quintic(x, *args) - target) / np.maximum(_hermite_quintic_dx(x, *args), 1e-12)
        x = np.clip(x - step, 0.0, 1.0)
    bad = np.abs(_hermite_quintic(x, *args) - target) > 1e-12
    if np.any(bad):
        lo = np.zeros(int(bad.sum()))
        hi = np.ones_like(lo)
        sub = tuple(a[bad] for a in args)
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            below = np.clip(_hermite_quintic(mid, *sub), 0.0, 1.0) < target[bad]
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        x[bad] = 0.5 * (lo + hi)
    return table.s_lo[j] + table.h[j] * x


def arc_derivatives(du: Sequence[np.ndarray | None]) -> list[np.ndarray | None]:
    """Derivatives with respect to arc length from those with respect to the parameter.

    Parameters
    ----------
    du : list of ndarray, shape (K, d)
        [r, r_u, r_uu, r_uuu], the first 1 to 4 of them. The position r is only passed
        through: it may be None when only the derivatives are wanted.

    Returns
    -------
    list of ndarray, shape (K, d)
        [r, r_s, r_ss, r_sss], as many: the unit tangent, the curvature vector kappa n and its
        arc-length derivative (chain rule with sigma = |r_u|).
    """
    out = [du[0]]
    if len(du) == 1:
        return out
    du = cast("Sequence[np.ndarray]", du)  # only the position du[0] may be None, and it is only passed through
    add = np.add.reduce  # np.sum without its Python wrappers
    a = du[1]
    sig2 = np.maximum(add(a * a, axis=1, keepdims=True), 1e-300)
    sig = np.sqrt(sig2)
    out.append(a / sig)
    if len(du) == 2:
        return out
    b = du[2]
    g = add(a * b, axis=1, keepdims=True)
    out.append(b / sig2 - g * a / sig2**2)
    if len(du) == 3:
        return out
    c = du[3]
    gp = add(b * b, axis=1, keepdims=True) + add(a * c, axis=1, keepdims=True)
    dk_du = c / sig2 - 3.0 * g * b / sig2**2 - gp * a / sig2**2 + 4.0 * g**2 * a / sig2**3
    out.append(dk_du / sig)
    return out
