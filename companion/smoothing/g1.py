"""G1 smoothing: quartic Bezier midpoint interpolation (paper section 3.2, Fig. 3).

Every interior node W of the polyline is replaced by a quartic Bezier curve from the midpoint
M_in of the incoming segment to the midpoint M_out of the outgoing segment, with control
points

    M_in, (M_in + W) / 2, W, (W + M_out) / 2, M_out.

The first three control points lie on the incoming segment and the last three on the outgoing
one, so each curve leaves and joins its segments tangentially (and with zero curvature):
neighbouring curves meet at the midpoints with equal tangents (G1). The first and last half
segments are straight (degree-1) pieces. The curve stays in the triangle M_in W M_out; its
curvature is not bounded (it grows as the segments get shorter or the corner sharper), which
is what G2 (``g2.py``) adds. Collinear corners need no curve; a reversal (the path turns back
on itself) is kept as a stop.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from companion.smoothing.bezier_maths import bernstein, curvature_from_derivatives
from companion.smoothing.bezier_path import BezierPath
from companion.smoothing.g2 import check_kappa
from companion.smoothing.polyline import assemble_stacked, prepare_path
from companion.smoothing.repair import repair_corners

__all__ = ["smooth_g1", "midpoint_quartics"]

logger = logging.getLogger(__name__)


def _fmt_point(p: np.ndarray) -> str:
    """A node as ``[n, e(, d)]`` with 3 decimals (for notes)."""
    return "[" + ", ".join(f"{float(x):.3f}" for x in p) + "]"


def midpoint_quartics(corner: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Quartic corner curves from ``start`` (on the incoming segment) to ``end``.

    Parameters
    ----------
    corner, start, end : ndarray, shape (C, d)

    Returns
    -------
    ndarray, shape (C, 5, d)
        Control points start, (start + corner)/2, corner, (corner + end)/2, end.
    """
    return np.stack([start, 0.5 * (start + corner), corner, 0.5 * (corner + end), end], axis=1)


def smooth_g1(path, *, world=None, kappa_max_1_m: float | None = None, max_halvings: int = 12) -> BezierPath:
    """Tangent-continuous smoothing of a polyline by quartic midpoint interpolation.

    Parameters
    ----------
    path : array_like, shape (M, d)
        Polyline nodes, d = 2 or 3, M >= 2; repeated nodes are dropped.
    world : companion.world.World, optional
        When given, corners that clip an inflated obstacle are shrunk towards their node (and
        kept sharp at worst), so the result is never less safe than the polyline.
    kappa_max_1_m : float, optional
        If given, ``kappa_ok`` reports whether the curvature stays below it (G1 does not
        enforce it) and ``notes``/``tight_corners`` name the corners that exceed it.
    max_halvings : int
        How many times a clipping corner may be halved before it is kept sharp.

    Returns
    -------
    BezierPath
        Degree-1 and quartic pieces, addressed by arc length.

    Raises
    ------
    SmoothingError
        Fewer than 2 nodes, NaN, bad shape, K_max <= 0.
    """
    kappa = None if kappa_max_1_m is None else check_kappa(kappa_max_1_m)
    nodes, index, corners = prepare_path(path)
    turn = corners.kind == "turn"
    kind = np.where(turn, 2, np.where(corners.kind == "reversal", 1, 0))
    turn_ids = np.nonzero(turn)[0]
    half_in = 0.5 * corners.len_in
    half_out = 0.5 * corners.len_out

    def build(ids: np.ndarray, scale: np.ndarray) -> np.ndarray:
        w = corners.point[ids]
        sc = np.asarray(scale, dtype=float)[:, None]
        start = w + sc * half_in[ids, None] * corners.u_in[ids]
        end = w + sc * half_out[ids, None] * corners.u_out[ids]
        return midpoint_quartics(w, start, end)[:, None]

    curves = np.zeros((kind.size, 1, 5, nodes.shape[1]))
    notes: list[str] = []
    tight: list[int] = []
    if world is not None and turn_ids.size:
        built, scales, sharp = repair_corners(world, build, turn_ids, max_halvings)
        curves[turn_ids] = built
        for i, sc in zip(turn_ids, scales):
            if sc < 1.0:
                notes.append(f"corner {index[i + 1]}: shrunk to {sc:.4g} of its size to clear obstacles")
        for i in turn_ids[sharp]:
            kind[i] = 1
            tight.append(int(index[i + 1]))
            notes.append(
                f"corner {index[i + 1]} at {_fmt_point(corners.point[i])}: every smooth "
                f"corner clips an obstacle; kept the polyline corner (the vehicle stops there)"
            )
    elif turn_ids.size:
        curves[turn_ids] = build(turn_ids, np.ones(turn_ids.size))
    for i in np.nonzero(corners.kind == "reversal")[0]:
        tight.append(int(index[i + 1]))
        notes.append(
            f"corner {index[i + 1]} at {_fmt_point(corners.point[i])}: the path reverses "
            f"(heading change {math.degrees(corners.turn_rad[i]):.2f} deg); the vehicle stops there"
        )
    if kappa is not None:
        smooth_ids = turn_ids[kind[turn_ids] == 2]
        u = np.linspace(0.0, 1.0, 129)
        ctrl = curves[smooth_ids, 0]
        d1 = bernstein(3, u)[None] @ (4 * np.diff(ctrl, axis=1))
        d2 = bernstein(2, u)[None] @ (12 * np.diff(ctrl, n=2, axis=1))
        peak = np.max(curvature_from_derivatives(d1, d2), axis=1) if smooth_ids.size else np.zeros(0)
        for i, k in zip(smooth_ids, peak):
            if k > kappa * (1.0 + 1e-9):
                tight.append(int(index[i + 1]))
                notes.append(
                    f"corner {index[i + 1]}: G1 curvature {k:.4g} 1/m > K_max {kappa:.4g} 1/m (use G2 to bound it)"
                )
    tight = sorted(set(tight))
    if logger.isEnabledFor(logging.INFO):
        for note in notes:
            logger.info("smooth_g1: %s", note)
    ctrl, degrees = assemble_stacked(nodes, kind, curves)
    return BezierPath.from_stacked(
        ctrl, degrees, kappa_ok=not tight, notes=notes, tight_corners=tight, kappa_max_1_m=kappa
    )
