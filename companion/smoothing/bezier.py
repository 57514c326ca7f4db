"""Bezier curve machinery: Bernstein evaluation, derivatives, curvature, arc length, splitting.

Paper section 3.2, eq. (8): a degree-n Bezier curve with control points P_0..P_n is

    B(u) = sum_i C(n, i) (1 - u)^(n - i) u^i P_i,     u in [0, 1],

its derivative is the degree-(n-1) curve of the control points n (P_{i+1} - P_i), and its
curvature is kappa = |B' x B''| / |B'|^3 (in 2D the cross product is the scalar
x' y'' - y' x''). Arc length is integrated by composite Gauss-Legendre quadrature, and a curve
is split with de Casteljau's algorithm.

``BezierPath`` chains pieces (possibly of different degrees) end to end and is addressed by
**arc length in metres**: ``evaluate(s)``, ``derivative(s, order)`` (derivatives with respect
to arc length) and ``curvature(s)``. A table of (u, s) knots per piece with the exact speed
|B'(u)| at every knot gives a cubic-Hermite inverse s -> u, so addressing a batch of K arc
lengths costs one ``searchsorted`` plus one Bernstein evaluation.
"""

from __future__ import annotations

import logging
import math
from functools import cached_property

import numpy as np

from companion.errors import SmoothingError

__all__ = [
    "bernstein",
    "evaluate",
    "derivative_control_points",
    "derivative",
    "curvature_from_derivatives",
    "curvature",
    "arc_length",
    "split",
    "elevate",
    "BezierPath",
]

logger = logging.getLogger(__name__)

_GAUSS_ORDER = 4
_TABLE_INTERVALS = 16
_TANGENT_JUMP_RAD = 1e-6


def _as_control_points(ctrl: np.ndarray, name: str = "ctrl") -> np.ndarray:
    arr = np.asarray(ctrl, dtype=float)
    if arr.ndim != 2 or arr.shape[0] < 2 or arr.shape[1] < 1:
        raise SmoothingError(f"{name}: expected control points of shape (n+1, d) with n >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SmoothingError(f"{name}: control points must be finite (no NaN or inf)")
    return arr


def _binomial_row(n: int) -> np.ndarray:
    return np.array([math.comb(n, i) for i in range(n + 1)], dtype=float)


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
    u = np.asarray(u, dtype=float).reshape(-1)
    v = 1.0 - u
    up = np.empty((u.size, n + 1))
    vp = np.empty((u.size, n + 1))
    up[:, 0] = 1.0
    vp[:, 0] = 1.0
    for i in range(1, n + 1):
        np.multiply(up[:, i - 1], u, out=up[:, i])
        np.multiply(vp[:, i - 1], v, out=vp[:, i])
    return _binomial_row(n) * up * vp[:, ::-1]


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
    ctrl = _as_control_points(ctrl)
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
    ctrl = _as_control_points(ctrl)
    dctrl = derivative_control_points(ctrl, order)
    return bernstein(dctrl.shape[0] - 1, u) @ dctrl


def _norm(a: np.ndarray) -> np.ndarray:
    """Euclidean norm along the last axis (faster than numpy.linalg.norm for small d)."""
    return np.sqrt(np.einsum("...i,...i->...", a, a))


def _cross_norm(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """|a x b| for rows of (K, d) arrays, exact formulas for d = 2 and 3."""
    dim = d1.shape[-1]
    if dim == 2:
        return np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    if dim == 3:
        return _norm(np.cross(d1, d2))
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
    speed = _norm(d1)
    num = _cross_norm(d1, d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(speed > 0.0, num / np.maximum(speed, 1e-300) ** 3, 0.0)
    return kappa


def curvature(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Curvature (1/m) of one Bezier curve at parameters ``u`` (K,) -> (K,)."""
    ctrl = _as_control_points(ctrl)
    return curvature_from_derivatives(derivative(ctrl, u, 1), derivative(ctrl, u, 2))


def _gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1] (read-only constants for the default order)."""
    if n == _GAUSS_ORDER:
        return _GL_NODES, _GL_WEIGHTS
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _frozen_gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


_GL_NODES, _GL_WEIGHTS = _frozen_gauss_legendre(_GAUSS_ORDER)


def arc_length(ctrl: np.ndarray, u0: float = 0.0, u1: float = 1.0, intervals: int = 8) -> float:
    """Arc length of one Bezier curve between parameters ``u0`` and ``u1`` (m).

    Composite Gauss-Legendre quadrature (5 nodes on each of ``intervals`` sub-intervals) of
    the speed |B'(u)|.
    """
    ctrl = _as_control_points(ctrl)
    x, w = _gauss_legendre(_GAUSS_ORDER)
    edges = np.linspace(u0, u1, intervals + 1)
    h = np.diff(edges)
    nodes = (edges[:-1, None] + h[:, None] * x[None, :]).ravel()
    speed = _norm(derivative(ctrl, nodes, 1)).reshape(intervals, -1)
    return float(np.sum(h * (speed @ w)))


def split(ctrl: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Split one Bezier curve at parameter ``u`` (de Casteljau).

    Returns
    -------
    left, right : ndarray, shape (n+1, d)
        Control points of the curve on [0, u] and on [u, 1], each re-parameterised to [0, 1].
    """
    ctrl = _as_control_points(ctrl)
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


def _lower(ctrl: np.ndarray, degree: int) -> np.ndarray:
    """Exact degree reduction of a curve that was elevated from ``degree`` (interpolation)."""
    u = np.linspace(0.0, 1.0, degree + 1)
    pts = evaluate(ctrl, u)
    return np.linalg.solve(bernstein(degree, u), pts)


def elevate_lines(a: np.ndarray, b: np.ndarray, degree: int) -> np.ndarray:
    """Straight lines from ``a`` to ``b`` (K, d) as degree-``degree`` curves, shape (K, N+1, d)."""
    w = np.linspace(0.0, 1.0, degree + 1)[None, :, None]
    return a[:, None, :] * (1.0 - w) + b[:, None, :] * w


def _hermite_quintic_dx(x: np.ndarray, m0: np.ndarray, m1: np.ndarray, c0: np.ndarray,
                        c1: np.ndarray) -> np.ndarray:
    """Derivative with respect to x of ``_hermite_quintic``."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    return ((1 - 18 * x2 + 32 * x3 - 15 * x4) * m0
            + (x - 4.5 * x2 + 6 * x3 - 2.5 * x4) * c0
            + (1.5 * x2 - 4 * x3 + 2.5 * x4) * c1
            + (-12 * x2 + 28 * x3 - 15 * x4) * m1
            + (30 * x2 - 60 * x3 + 30 * x4))


def power_basis_matrix(n: int) -> np.ndarray:
    """M (n+1, n+1) with power coefficients a = M b of a degree-n Bernstein polynomial b."""
    m = np.zeros((n + 1, n + 1))
    for j in range(n + 1):
        for i in range(j + 1):
            m[j, i] = math.comb(n, j) * math.comb(j, i) * (-1) ** (j - i)
    return m


def _horner_grid(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate power-basis polynomials ``coeffs`` (K, n+1, d) at ``x`` (K, S) -> (K, S, d)."""
    xx = x[:, :, None]
    out = np.broadcast_to(coeffs[:, None, -1], xx.shape[:2] + coeffs.shape[2:]).copy()
    for j in range(coeffs.shape[1] - 2, -1, -1):
        out *= xx
        out += coeffs[:, None, j]
    return out


def _hermite_quintic(x: np.ndarray, m0: np.ndarray, m1: np.ndarray, c0: np.ndarray,
                     c1: np.ndarray) -> np.ndarray:
    """Quintic Hermite on [0, 1] from 0 to 1 with end slopes m0, m1 and second derivatives c0, c1."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    x5 = x4 * x
    return ((x - 6 * x3 + 8 * x4 - 3 * x5) * m0
            + (0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5) * c0
            + (0.5 * x3 - x4 + 0.5 * x5) * c1
            + (-4 * x3 + 7 * x4 - 3 * x5) * m1
            + (10 * x3 - 15 * x4 + 6 * x5))


class BezierPath:
    """A chain of Bezier pieces addressed by arc length.

    Parameters
    ----------
    pieces : sequence of array_like, shape (n_i+1, d)
        Control points of each piece, in order; piece i ends where piece i+1 starts. Pieces of
        (numerically) zero length are dropped.
    kappa_ok : bool
        Whether the curvature bound that was asked for (if any) holds everywhere.
    notes : sequence of str
        Human-readable record of what the smoother changed or could not honour.
    tight_corners : sequence of int
        Indices (in the input polyline) of corners whose curvature exceeds K_max or which were
        kept sharp; the planner can be asked for a gentler corner there.
    kappa_max_1_m : float or None
        The bound that was asked for, if any.

    Attributes
    ----------
    pieces : list of ndarray, shape (n_i+1, d)
    d : int
        Dimension (2: north-east, 3: NED).
    length_m : float
        Total arc length.
    piece_start_s : ndarray, shape (P+1,)
        Arc length at the start of every piece, and the total length last.
    stop_s : ndarray, shape (S,)
        Arc lengths of interior joints where the tangent is discontinuous (kept polyline
        corners); a trajectory must come to rest there.
    """

    def __init__(self, pieces, *, kappa_ok: bool = True, notes=(), tight_corners=(),
                 kappa_max_1_m: float | None = None, peaks_at_joints: bool = False) -> None:
        arrays = [_as_control_points(p, f"pieces[{i}]") for i, p in enumerate(pieces)]
        if not arrays:
            raise SmoothingError("pieces: a BezierPath needs at least one piece")
        dims = {a.shape[1] for a in arrays}
        if len(dims) != 1:
            raise SmoothingError(f"pieces: all pieces must have the same dimension, got {sorted(dims)}")
        degree = max(a.shape[0] - 1 for a in arrays)
        ctrl = np.stack([elevate(a, degree) for a in arrays])
        degrees = np.array([a.shape[0] - 1 for a in arrays])
        self._init_arrays(ctrl, degrees, kappa_ok, notes, tight_corners, kappa_max_1_m, peaks_at_joints)

    @classmethod
    def from_stacked(cls, ctrl: np.ndarray, degrees: np.ndarray, *, kappa_ok: bool = True, notes=(),
                     tight_corners=(), kappa_max_1_m: float | None = None,
                     peaks_at_joints: bool = False) -> "BezierPath":
        """Fast constructor from pieces already elevated to one degree (no per-piece checks).

        Parameters
        ----------
        ctrl : ndarray, shape (P, N+1, d)
            Finite control points, every piece elevated to degree N.
        degrees : ndarray of int, shape (P,)
            The true degree of every piece (1 for an elevated straight line, else N).
        peaks_at_joints : bool
            The smoother guarantees that each piece's curvature is monotone (G2 spirals), so
            ``curvature_peaks_s`` need not search inside the pieces.
        """
        obj = cls.__new__(cls)
        obj._init_arrays(np.asarray(ctrl, dtype=float), np.asarray(degrees), kappa_ok, notes, tight_corners,
                         kappa_max_1_m, peaks_at_joints)
        return obj

    def _init_arrays(self, ctrl, degrees, kappa_ok, notes, tight_corners, kappa_max_1_m,
                     peaks_at_joints) -> None:
        scale = max(1.0, float(np.max(np.abs(ctrl))))
        extent = np.max(_norm(ctrl - ctrl[:, :1]), axis=1)
        keep = extent > 1e-10 * scale
        if not np.any(keep):
            raise SmoothingError("pieces: every piece has zero length")
        if not np.all(keep):
            ctrl, degrees = ctrl[keep], degrees[keep]
        self._ctrl = ctrl                                                    # (P, N+1, d)
        self._degrees = degrees
        self.degree: int = ctrl.shape[1] - 1
        self.d: int = ctrl.shape[2]
        self.kappa_ok: bool = bool(kappa_ok)
        self.notes: list[str] = list(notes)
        self.tight_corners: list[int] = list(tight_corners)
        self.kappa_max_1_m = kappa_max_1_m
        self._peaks_at_joints = bool(peaks_at_joints)
        self._build_arc_length_table()
        self.stop_s: np.ndarray = self._find_stops()

    @cached_property
    def pieces(self) -> list[np.ndarray]:
        """Control points of every piece in its own degree, list of (n_i+1, d) arrays."""
        out = []
        for c, n in zip(self._ctrl, self._degrees):
            out.append(c[[0, -1]].copy() if n == 1 else c.copy() if n == self.degree else _lower(c, int(n)))
        return out

    # ------------------------------------------------------------------ construction helpers
    def _hodograph(self, order: int) -> np.ndarray:
        """Derivative control points of every piece, shape (P, N+1-order, d)."""
        out = self._ctrl
        n = self.degree
        if order > n:
            return np.zeros((out.shape[0], 1, self.d))
        for k in range(order):
            out = (n - k) * np.diff(out, axis=1)
        return out

    @cached_property
    def _hodographs(self) -> tuple[np.ndarray, ...]:
        return tuple(self._hodograph(k) for k in range(4))

    def _piece_derivative(self, piece: np.ndarray, u: np.ndarray, order: int) -> np.ndarray:
        """d^order B_piece / du^order at (piece (K,), u (K,)) -> (K, d)."""
        if order < 4:
            hod = self._hodographs[order]
        else:
            hod = self._hodograph(order)
        basis = bernstein(hod.shape[1] - 1, u)
        return np.einsum("kn,knd->kd", basis, hod[piece], optimize=False)

    def _build_arc_length_table(self) -> None:
        n_pieces = self._ctrl.shape[0]
        g = _TABLE_INTERVALS
        u_knots = np.linspace(0.0, 1.0, g + 1)
        h = 1.0 / g
        hod1 = self._hodographs[1]
        hod2 = self._hodographs[2]
        curved = self._degrees >= 2
        seg_len = np.empty((n_pieces, g))
        d1_knots = np.empty((n_pieces, g + 1, self.d))
        u_ss_knots = np.zeros((n_pieces, g + 1))
        line_len = _norm(self._ctrl[~curved, -1] - self._ctrl[~curved, 0])
        seg_len[~curved] = line_len[:, None] * h
        d1_knots[~curved] = hod1[~curved, :1]
        if np.any(curved):
            x, w = _gauss_legendre(_GAUSS_ORDER)
            nodes = (u_knots[:-1, None] + h * x[None, :]).ravel()
            hc1 = hod1[curved]
            speed_nodes = _norm(bernstein(hc1.shape[1] - 1, nodes)[None] @ hc1)
            seg_len[curved] = h * (speed_nodes.reshape(hc1.shape[0], g, -1) @ w)
            d1c = bernstein(hc1.shape[1] - 1, u_knots)[None] @ hc1
            d2c = bernstein(hod2.shape[1] - 1, u_knots)[None] @ hod2[curved]
            d1_knots[curved] = d1c
            sig_c = np.maximum(_norm(d1c), 1e-300)
            u_ss_knots[curved] = -np.sum(d1c * d2c, axis=2) / sig_c**4
            self._knot_kappa_curved = curvature_from_derivatives(d1c, d2c)          # (Pc, g+1)
        else:
            self._knot_kappa_curved = np.zeros((0, g + 1))
        piece_len = seg_len.sum(axis=1)
        self.piece_start_s = np.concatenate([[0.0], np.cumsum(piece_len)])
        self.length_m = float(self.piece_start_s[-1])
        s_lo = self.piece_start_s[:-1, None] + np.concatenate(
            [np.zeros((n_pieces, 1)), np.cumsum(seg_len, axis=1)[:, :-1]], axis=1)
        self._tab_s_lo = s_lo.ravel()
        self._tab_h = seg_len.ravel()
        self._tab_piece = np.repeat(np.arange(n_pieces), g)
        self._tab_u_lo = np.tile(u_knots[:-1], n_pieces)
        floor = 1e-9 * max(self.length_m, 1.0)
        sig = np.maximum(_norm(d1_knots), floor)
        u_s = 1.0 / sig                                              # du/ds
        hh = seg_len
        self._tab_m0 = (hh * u_s[:, :-1] / h).ravel()
        self._tab_m1 = (hh * u_s[:, 1:] / h).ravel()
        self._tab_c0 = (hh**2 * u_ss_knots[:, :-1] / h).ravel()
        self._tab_c1 = (hh**2 * u_ss_knots[:, 1:] / h).ravel()
        self._tab_du = h

    def arc_length_at(self, piece: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Arc length (m) that ``locate`` maps to (piece (K,), u (K,)): its exact inverse.

        Found by Newton's method within the table interval (bisection where it does not
        converge), so ``locate(arc_length_at(p, u))`` returns (p, u) to about 1e-12.
        """
        g = _TABLE_INTERVALS
        k = np.clip((np.asarray(u) * g).astype(int), 0, g - 1)
        j = np.asarray(piece) * g + k
        target = (np.asarray(u, dtype=float) - self._tab_u_lo[j]) / self._tab_du
        args = (self._tab_m0[j], self._tab_m1[j], self._tab_c0[j], self._tab_c1[j])
        x = target.copy()
        for _ in range(8):                                   # Newton, then bisection where needed
            x = np.clip(x - (_hermite_quintic(x, *args) - target) / np.maximum(_hermite_quintic_dx(x, *args),
                                                                              1e-12), 0.0, 1.0)
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
        return self._tab_s_lo[j] + self._tab_h[j] * x

    @cached_property
    def curvature_peaks_s(self) -> np.ndarray:
        """Arc lengths of the interior curvature maxima of the pieces, shape (P',).

        Each curved piece is sampled at 65 parameters; where the largest sample is not at an
        end (a G1 corner; G2 spirals peak at their ends, which are joints), the maximum is
        refined by four rounds of 17 samples in the bracket around the best sample (the bracket
        shrinks 8 times per round, to under 1e-5 of the parameter). A speed-profile grid that
        includes these points resolves even the narrow curvature peak of a sharp G1 corner.
        """
        curved = np.nonzero(self._degrees >= 2)[0]
        if curved.size == 0 or self._peaks_at_joints:
            return np.zeros(0)
        u = np.linspace(0.0, 1.0, 65)
        d1 = bernstein(self.degree - 1, u)[None] @ self._hodographs[1][curved]
        d2 = bernstein(self.degree - 2, u)[None] @ self._hodographs[2][curved]
        kappa = curvature_from_derivatives(d1, d2)                                  # (P', 65)
        i = np.argmax(kappa, axis=1)
        interior = (i > 0) & (i < u.size - 1)
        if not np.any(interior):
            return np.zeros(0)
        piece = curved[interior]
        lo = u[i[interior] - 1]
        hi = u[i[interior] + 1]
        h1 = self._hodographs[1][piece]
        h2 = self._hodographs[2][piece]
        c1 = power_basis_matrix(h1.shape[1] - 1)[None] @ h1
        c2 = power_basis_matrix(h2.shape[1] - 1)[None] @ h2

        rows = np.arange(piece.size)
        grid = np.linspace(0.0, 1.0, 17)
        for _ in range(4):                       # each round narrows the bracket 8 times
            x = lo[:, None] + (hi - lo)[:, None] * grid[None, :]                   # (P', 17)
            k = curvature_from_derivatives(_horner_grid(c1, x), _horner_grid(c2, x))
            best = np.clip(np.argmax(k, axis=1), 1, grid.size - 2)
            lo, hi = x[rows, best - 1], x[rows, best + 1]
        return self.arc_length_at(piece, 0.5 * (lo + hi))

    def knots_with_curvature(self) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths and curvatures of the table knots of the curved pieces, both ends included.

        Returns
        -------
        s_m : ndarray, shape (17 P',)
        kappa_1_m : ndarray, shape (17 P',)
        """
        g = _TABLE_INTERVALS
        curved = np.nonzero(self._degrees >= 2)[0]
        if curved.size == 0:
            return np.zeros(0), np.zeros(0)
        s_lo = self._tab_s_lo.reshape(-1, g)[curved]
        s_all = np.hstack([s_lo, self.piece_start_s[curved + 1][:, None]])
        return s_all.ravel(), self._knot_kappa_curved.ravel()

    @property
    def curved_piece(self) -> np.ndarray:
        """True for every piece that is not a straight line, shape (P,)."""
        return self._degrees >= 2

    def _find_stops(self) -> np.ndarray:
        if self._ctrl.shape[0] < 2:
            return np.zeros(0)
        t_out = self._unit(self._ctrl[:-1, -1] - self._last_distinct(self._ctrl[:-1]))
        t_in = self._unit(self._first_distinct(self._ctrl[1:]) - self._ctrl[1:, 0])
        cosang = np.clip(np.sum(t_out * t_in, axis=1), -1.0, 1.0)
        angle = np.arccos(cosang)
        return self.piece_start_s[1:-1][angle > _TANGENT_JUMP_RAD]

    @staticmethod
    def _unit(v: np.ndarray) -> np.ndarray:
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return v / np.maximum(n, 1e-300)

    @staticmethod
    def _last_distinct(ctrl: np.ndarray) -> np.ndarray:
        """For each piece (P, N+1, d), the last control point that differs from the end point."""
        return BezierPath._first_distinct(ctrl[:, ::-1])

    @staticmethod
    def _first_distinct(ctrl: np.ndarray) -> np.ndarray:
        """For each piece (P, N+1, d), the first control point that differs from the start."""
        scale = 1e-12 * np.maximum(1.0, np.abs(ctrl).max(axis=(1, 2)))
        differs = _norm(ctrl - ctrl[:, :1]) > scale[:, None]
        differs[:, 0] = False
        idx = np.argmax(differs, axis=1)
        return ctrl[np.arange(ctrl.shape[0]), idx]

    # ------------------------------------------------------------------ addressing
    def locate(self, s_m) -> tuple[np.ndarray, np.ndarray]:
        """Map arc lengths to (piece index, piece parameter).

        Parameters
        ----------
        s_m : array_like, shape (K,)
            Arc lengths (m); clipped to [0, length_m].

        Returns
        -------
        piece : ndarray of int, shape (K,)
        u : ndarray, shape (K,)
        """
        s = np.clip(np.asarray(s_m, dtype=float).reshape(-1), 0.0, self.length_m)
        j = np.searchsorted(self._tab_s_lo, s, side="right") - 1
        j = np.clip(j, 0, self._tab_s_lo.size - 1)
        h = self._tab_h[j]
        x = np.clip((s - self._tab_s_lo[j]) / np.maximum(h, 1e-300), 0.0, 1.0)
        frac = _hermite_quintic(x, self._tab_m0[j], self._tab_m1[j], self._tab_c0[j], self._tab_c1[j])
        u = self._tab_u_lo[j] + self._tab_du * np.clip(frac, 0.0, 1.0)
        return self._tab_piece[j], u

    def _check_s(self, s_m) -> tuple[np.ndarray, bool]:
        arr = np.asarray(s_m, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise SmoothingError("s_m: arc lengths must be finite (no NaN or inf)")
        return arr.reshape(-1), arr.ndim == 0

    def evaluate(self, s_m) -> np.ndarray:
        """Points at arc lengths ``s_m`` (K,) -> (K, d) (a scalar gives (d,))."""
        s, scalar = self._check_s(s_m)
        piece, u = self.locate(s)
        out = self._piece_derivative(piece, u, 0)
        return out[0] if scalar else out

    def derivative(self, s_m, order: int = 1) -> np.ndarray:
        """Derivative with respect to arc length, d^order r / ds^order, orders 0 to 3.

        Order 1 is the unit tangent, order 2 the curvature vector kappa * n, order 3 its
        arc-length derivative.

        Parameters
        ----------
        s_m : array_like, shape (K,)
        order : int

        Returns
        -------
        ndarray, shape (K, d) (a scalar ``s_m`` gives (d,))
        """
        if order not in (0, 1, 2, 3):
            raise SmoothingError(f"order: arc-length derivatives of order 0..3 are supported, got {order}")
        s, scalar = self._check_s(s_m)
        piece, u = self.locate(s)
        out = self._arc_derivatives(piece, u, order)[order]
        return out[0] if scalar else out

    def _arc_derivatives(self, piece: np.ndarray, u: np.ndarray, order: int) -> list[np.ndarray]:
        """[r, r_s, r_ss, r_sss] up to ``order`` at (piece, u) by the chain rule."""
        out = [self._piece_derivative(piece, u, 0)]
        if order == 0:
            return out
        a = self._piece_derivative(piece, u, 1)
        sig2 = np.maximum(np.sum(a * a, axis=1, keepdims=True), 1e-300)
        sig = np.sqrt(sig2)
        out.append(a / sig)
        if order == 1:
            return out
        b = self._piece_derivative(piece, u, 2)
        g = np.sum(a * b, axis=1, keepdims=True)
        k_vec = b / sig2 - g * a / sig2**2
        out.append(k_vec)
        if order == 2:
            return out
        c = self._piece_derivative(piece, u, 3)
        gp = np.sum(b * b, axis=1, keepdims=True) + np.sum(a * c, axis=1, keepdims=True)
        dk_du = c / sig2 - 3.0 * g * b / sig2**2 - gp * a / sig2**2 + 4.0 * g**2 * a / sig2**3
        out.append(dk_du / sig)
        return out

    def curvature(self, s_m, *, signed: bool = False) -> np.ndarray:
        """Curvature (1/m) at arc lengths ``s_m`` (K,) -> (K,).

        ``signed=True`` (2D only) gives positive values for turns from north towards east.
        """
        s, scalar = self._check_s(s_m)
        piece, u = self.locate(s)
        d1 = self._piece_derivative(piece, u, 1)
        d2 = self._piece_derivative(piece, u, 2)
        kappa = curvature_from_derivatives(d1, d2)
        if signed:
            if self.d != 2:
                raise SmoothingError("signed: signed curvature is defined for 2D paths only")
            kappa = kappa * np.sign(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        return kappa[0] if scalar else kappa

    # ------------------------------------------------------------------ per-piece access
    @property
    def start(self) -> np.ndarray:
        """First point, shape (d,)."""
        return self._ctrl[0, 0].copy()

    @property
    def end(self) -> np.ndarray:
        """Last point, shape (d,)."""
        return self._ctrl[-1, -1].copy()

    @cached_property
    def max_curvature_1_m(self) -> float:
        """Largest curvature over the whole path (1/m): 65 samples per curved piece, plus the
        refined interior peaks (``curvature_peaks_s``)."""
        curved = self._degrees >= 2
        if not np.any(curved):
            return 0.0
        u = np.linspace(0.0, 1.0, 65)
        d1 = bernstein(self.degree - 1, u)[None] @ self._hodographs[1][curved]
        d2 = bernstein(self.degree - 2, u)[None] @ self._hodographs[2][curved]
        best = float(np.max(curvature_from_derivatives(d1, d2)))
        peaks = self.curvature_peaks_s
        if peaks.size:
            best = max(best, float(np.max(self.curvature(peaks))))
        return best

    def polyline(self, step_m: float = 0.5) -> np.ndarray:
        """Points every ``step_m`` metres of arc (plus both ends), shape (K, d), for plots."""
        n = max(2, int(math.ceil(self.length_m / step_m)) + 1)
        return self.evaluate(np.linspace(0.0, self.length_m, n))

    def __repr__(self) -> str:
        return (f"BezierPath(d={self.d}, pieces={len(self.pieces)}, length_m={self.length_m:.3f}, "
                f"kappa_ok={self.kappa_ok}, stops={self.stop_s.size})")
