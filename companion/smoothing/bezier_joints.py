"""Tangent discontinuities at the joints of a chain of Bezier pieces.

The tangent leaving a piece is the direction from its last control point that differs from
its end point to the end point; the tangent entering the next piece is the direction from its
start to its first distinct control point (a G1/G2 smoother may repeat control points, so the
neighbouring one is not enough). Where the two differ by more than ``TANGENT_JUMP_RAD``, the
joint is a kept polyline corner and a trajectory must come to rest there.
"""

from __future__ import annotations

import numpy as np

from companion.smoothing.bezier_maths import norm_rows

__all__ = ["TANGENT_JUMP_RAD", "tangent_jumps"]

TANGENT_JUMP_RAD = 1e-6


def _first_distinct(ctrl: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """Index of the first control point of each piece (P', N+1, d) farther than ``tol`` (P',) from
    its first point (0 if none is)."""
    differs = norm_rows(ctrl - ctrl[:, :1]) > tol[:, None]
    differs[:, 0] = False
    return np.argmax(differs, axis=1)


def _tangents(ctrl: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """Unit tangent at the start of each piece (P', N+1, d), from its first distinct control point.

    The neighbouring control point is taken where it is farther than the largest tolerance;
    only the other pieces are searched.
    """
    step = ctrl[:, 1] - ctrl[:, 0]
    length = norm_rows(step)
    near = np.nonzero(length <= tol.max())[0]
    if near.size:
        first = _first_distinct(ctrl[near], tol[near])
        step[near] = ctrl[near, first] - ctrl[near, 0]
        length[near] = norm_rows(step[near])
    return step / np.maximum(length, 1e-300)[:, None]


def tangent_jumps(ctrl: np.ndarray, abs_max: np.ndarray | None = None) -> np.ndarray:
    """Which joints of a chain have a discontinuous tangent.

    Parameters
    ----------
    ctrl : ndarray, shape (P, N+1, d)
        Control points of the chain's pieces, in order.
    abs_max : ndarray, shape (P,), optional
        Largest absolute coordinate of every piece, if already known.

    Returns
    -------
    ndarray of bool, shape (P-1,)
        True at joint i (between pieces i and i+1) when the tangent turns by more than
        ``TANGENT_JUMP_RAD`` there.
    """
    if ctrl.shape[0] < 2:
        return np.zeros(0, dtype=bool)
    if abs_max is None:
        abs_max = np.abs(ctrl).max(axis=(1, 2))
    tol = 1e-12 * np.maximum(1.0, abs_max)  # (P,)
    t_out = -_tangents(ctrl[:-1, ::-1], tol[:-1])
    t_in = _tangents(ctrl[1:], tol[1:])
    cosang = np.clip(np.einsum("ij,ij->i", t_out, t_in), -1.0, 1.0)
    return np.arccos(cosang) > TANGENT_JUMP_RAD
