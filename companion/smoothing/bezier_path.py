"""A chain of Bezier pieces addressed by arc length (paper section 3.2).

``BezierPath`` holds a smoothed path's pieces (lines, G1 quartics or G2 cubic spirals) at one
common degree, addressed by **arc length in metres**: ``evaluate(s)``, ``derivative(s, order)``
(with respect to arc length) and ``curvature(s)``. Its steps have their own modules: one
curve's maths (``bezier_maths``), the arc-length table and its inverse (``bezier_arclength``),
the curvature peak search (``bezier_peaks``), the tangent jumps at joints (``bezier_joints``).
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from companion.errors import SmoothingError
from companion.smoothing.bezier_arclength import (
    TABLE_INTERVALS,
    arc_derivatives,
    arc_length_at,
    build_table,
    knot_curvature,
    locate,
)
from companion.smoothing.bezier_joints import tangent_jumps
from companion.smoothing.bezier_maths import (
    as_control_points,
    bernstein,
    bernstein_family,
    curvature_from_derivatives,
    elevate,
    lower_degree,
    norm_rows,
)
from companion.smoothing.bezier_peaks import interior_peaks, sampled_curvature

__all__ = ["BezierPath"]


class BezierPath:
    """A chain of Bezier pieces addressed by arc length.

    Parameters
    ----------
    pieces : sequence of array_like, shape (n_i+1, d)
        Control points of each piece, in order; piece i ends where piece i+1 starts. Pieces of
        (numerically) zero length are dropped.
    kappa_ok : bool
        Whether the curvature bound that was asked for (if any) holds everywhere.
    notes : sequence of str, or callable returning a list of str
        Human-readable record of what the smoother changed or could not honour; a callable is
        called on the first read of ``notes`` (most candidate curves are never reported).
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

    def __init__(
        self,
        pieces,
        *,
        kappa_ok: bool = True,
        notes=(),
        tight_corners=(),
        kappa_max_1_m: float | None = None,
        peaks_at_joints: bool = False,
    ) -> None:
        arrays = [as_control_points(p, f"pieces[{i}]") for i, p in enumerate(pieces)]
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
    def from_stacked(
        cls,
        ctrl: np.ndarray,
        degrees: np.ndarray,
        *,
        kappa_ok: bool = True,
        notes=(),
        tight_corners=(),
        kappa_max_1_m: float | None = None,
        peaks_at_joints: bool = False,
    ) -> BezierPath:
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
        obj._init_arrays(
            np.asarray(ctrl, dtype=float),
            np.asarray(degrees),
            kappa_ok,
            notes,
            tight_corners,
            kappa_max_1_m,
            peaks_at_joints,
        )
        return obj

    def _init_arrays(self, ctrl, degrees, kappa_ok, notes, tight_corners, kappa_max_1_m, peaks_at_joints) -> None:
        abs_max = np.abs(ctrl).max(axis=(1, 2))  # (P,)
        keep = np.max(norm_rows(ctrl - ctrl[:, :1]), axis=1) > 1e-10 * max(1.0, float(abs_max.max()))
        if not np.any(keep):
            raise SmoothingError("pieces: every piece has zero length")
        if not np.all(keep):
            ctrl, degrees, abs_max = ctrl[keep], degrees[keep], abs_max[keep]
        self._ctrl = ctrl  # (P, N+1, d)
        self._degrees = degrees
        self.degree: int = ctrl.shape[1] - 1
        self.d: int = ctrl.shape[2]
        self.kappa_ok: bool = bool(kappa_ok)
        if callable(notes):
            self._notes_source = notes
        else:
            self.__dict__["notes"] = list(notes)
        self.tight_corners: list[int] = list(tight_corners)
        self.kappa_max_1_m = kappa_max_1_m
        self._peaks_at_joints = bool(peaks_at_joints)
        self._hodographs: list[np.ndarray] = [ctrl]
        self._table = build_table(ctrl, degrees, self._hodograph(1), self._hodograph(2))
        self.piece_start_s: np.ndarray = self._table.piece_start_s
        self.length_m: float = float(self.piece_start_s[-1])
        self.stop_s: np.ndarray = self.piece_start_s[1:-1][tangent_jumps(ctrl, abs_max)]

    @cached_property
    def notes(self) -> list[str]:
        """What the smoother changed or could not honour, one sentence per corner (formatted on
        first read when the smoother gave a callable)."""
        return list(self._notes_source())

    def __getstate__(self) -> dict:
        """Pickle with the notes formatted (the callable that formats them may be a closure)."""
        state = dict(self.__dict__)
        state["notes"] = self.notes
        state.pop("_notes_source", None)
        return state

    @cached_property
    def pieces(self) -> list[np.ndarray]:
        """Control points of every piece in its own degree, list of (n_i+1, d) arrays."""
        return [
            c[[0, -1]].copy() if n == 1 else c.copy() if n == self.degree else lower_degree(c, int(n))
            for c, n in zip(self._ctrl, self._degrees)
        ]

    def _hodograph(self, order: int) -> np.ndarray:
        """Derivative control points of every piece, shape (P, N+1-order, d) (computed once)."""
        hods = self._hodographs
        while len(hods) <= order:
            k = len(hods) - 1  # order of the last one computed
            hods.append(
                (self.degree - k) * np.diff(hods[-1], axis=1)
                if k < self.degree
                else np.zeros((self._ctrl.shape[0], 1, self.d))
            )
        return hods[order]

    def _piece_derivative(self, piece: np.ndarray, u: np.ndarray, order: int) -> np.ndarray:
        """d^order B_piece / du^order at (piece (K,), u (K,)) -> (K, d)."""
        hod = self._hodograph(order)
        basis = bernstein(hod.shape[1] - 1, u)
        return np.einsum("kn,knd->kd", basis, hod[piece], optimize=False)

    def _piece_derivatives(self, piece: np.ndarray, u: np.ndarray, orders) -> list[np.ndarray]:
        """``_piece_derivative`` of every order of ``orders`` at (piece (K,), u (K,)) -> list of
        (K, d), from one table of the powers of u (``bernstein_family``)."""
        hods = [self._hodograph(k) for k in orders]
        bases = bernstein_family([hod.shape[1] - 1 for hod in hods], u)
        return [np.einsum("kn,knd->kd", basis, hod[piece], optimize=False) for basis, hod in zip(bases, hods)]

    def arc_length_at(self, piece: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Arc length (m) that ``locate`` maps to (piece (K,), u (K,)): its exact inverse.

        Found by Newton's method within the table interval (bisection where it does not
        converge), so ``locate(arc_length_at(p, u))`` returns (p, u) to about 1e-12.
        """
        return arc_length_at(self._table, piece, u)

    @cached_property
    def curvature_peaks_s(self) -> np.ndarray:
        """Arc lengths of the interior curvature maxima of the pieces, shape (P',).

        G2 spirals peak at their ends, which are joints (``peaks_at_joints``); a G1 corner
        peaks inside its piece, found to within 1e-5 of the parameter (``bezier_peaks``). A
        speed-profile grid that includes these points resolves even the narrow curvature peak
        of a sharp G1 corner.
        """
        curved = np.nonzero(self._degrees >= 2)[0]
        if curved.size == 0 or self._peaks_at_joints:
            return np.zeros(0)
        index, u = interior_peaks(self._hodograph(1)[curved], self._hodograph(2)[curved])
        return self.arc_length_at(curved[index], u)

    def knots_with_curvature(self) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths and curvatures of the table knots of the curved pieces, both ends included.

        Returns
        -------
        s_m : ndarray, shape (17 P',)
        kappa_1_m : ndarray, shape (17 P',)
        """
        curved = np.nonzero(self._degrees >= 2)[0]
        if curved.size == 0:
            return np.zeros(0), np.zeros(0)
        s_all = np.hstack([self._table.s_lo.reshape(-1, TABLE_INTERVALS)[curved], self.piece_start_s[curved + 1, None]])
        return s_all.ravel(), knot_curvature(self._hodograph(1)[curved], self._hodograph(2)[curved]).ravel()

    @property
    def curved_piece(self) -> np.ndarray:
        """True for every piece that is not a straight line, shape (P,)."""
        return self._degrees >= 2

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
        return locate(self._table, np.asarray(s_m, dtype=float).reshape(-1))

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
        out = self._arc_derivatives(piece, u, order, position=order == 0)[order]
        assert out is not None  # only the position can be None, and it is evaluated for order 0
        return out[0] if scalar else out

    def _arc_derivatives(
        self, piece: np.ndarray, u: np.ndarray, order: int, *, position: bool = True
    ) -> list[np.ndarray | None]:
        """[r, r_s, r_ss, r_sss] up to ``order`` (>= 1 without the position) at (piece, u) by the
        chain rule; ``position=False`` does not evaluate r (its entry is None)."""
        if position:
            return arc_derivatives(self._piece_derivatives(piece, u, range(order + 1)))
        return arc_derivatives([None, *self._piece_derivatives(piece, u, range(1, order + 1))])

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
        best = float(np.max(sampled_curvature(self._hodograph(1)[curved], self._hodograph(2)[curved])))
        peaks = self.curvature_peaks_s
        if peaks.size:
            best = max(best, float(np.max(self.curvature(peaks))))
        return best

    def polyline(self, step_m: float = 0.5) -> np.ndarray:
        """Points every ``step_m`` metres of arc (plus both ends), shape (K, d), for plots."""
        n = max(2, int(math.ceil(self.length_m / step_m)) + 1)
        return self.evaluate(np.linspace(0.0, self.length_m, n))

    def __repr__(self) -> str:
        return (
            f"BezierPath(d={self.d}, pieces={len(self.pieces)}, length_m={self.length_m:.3f}, "
            f"kappa_ok={self.kappa_ok}, stops={self.stop_s.size})"
        )
