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


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (K, d) scaled to unit length."""
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.maximum(n, 1e-300)


def tangent_jumps(ctrl: np.ndarray, dist_from_start: np.ndarray | None = None) -> np.ndarray:
    """Which joints of a chain have a discontinuous tangent.

    Parameters
    ----------
    ctrl : ndarray, shape (P, N+1, d)
        Control points of the chain's pieces, in order.
    dist_from_start : ndarray, shape (P, N+1), optional
        ``|ctrl[:, i] - ctrl[:, 0]|`` if already known.

    Returns
    -------
    ndarray of bool, shape (P-1,)
        True at joint i (between pieces i and i+1) when the tangent turns by more than
        ``TANGENT_JUMP_RAD`` there.
    """
    n_pieces, n1 = ctrl.shape[:2]
    if n_pieces < 2:
        return np.zeros(0, dtype=bool)
    if dist_from_start is None:
        dist_from_start = norm_rows(ctrl - ctrl[:, :1])
    tol = 1e-12 * np.maximum(1.0, np.abs(ctrl).max(axis=(1, 2)))[:, None]
    differs_start = dist_from_start[1:] > tol[1:]
    differs_start[:, 0] = False
    differs_end = norm_rows(ctrl[:-1, ::-1] - ctrl[:-1, -1:]) > tol[:-1]
    differs_end[:, 0] = False
    first = np.argmax(differs_start, axis=1)
    last = n1 - 1 - np.argmax(differs_end, axis=1)
    rows = np.arange(n_pieces - 1)
    t_out = _unit(ctrl[:-1, -1] - ctrl[rows, last])
    t_in = _unit(ctrl[rows + 1, first] - ctrl[1:, 0])
    angle = np.arccos(np.clip(np.sum(t_out * t_in, axis=1), -1.0, 1.0))
    return angle > TANGENT_JUMP_RAD
