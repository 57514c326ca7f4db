"""G2 smoothing: a pair of cubic Bezier spirals at every corner (paper section 3.2, eqs. 15-19).

Yang and Sukkarieh's continuous-curvature path smoothing ("An analytical continuous-curvature
path-smoothing algorithm", IEEE T-RO 2010), as used by the paper. At a corner W with unit
vectors u_in (towards the previous node) and u_out (towards the next), heading change
2*beta, and curvature bound K_max:

    c1 = 7.2364,  c2 = 2 (sqrt(6) - 1) / 5,  c3 = (c2 + 4) / (c1 + 6)
    d  = 1.1228 sin(beta) / (K_max cos^2(beta))                         (eq. 19)
    B0 = W + d u_in,  B1 = B0 - c2 c3 d u_in,  B2 = B1 - c3 d u_in
    E0 = W + d u_out, E1 = E0 - c2 c3 d u_out, E2 = E1 - c3 d u_out
    B3 = E3 = (B2 + E2) / 2

(the paper's B3 = B2 + k u_d, k = 6 c3 cos(beta) d / (c2 + 4), is this midpoint up to the
rounding of c1; taking the midpoint makes the joint exactly tangent-continuous). The spiral
B0..B3 starts with zero curvature on the incoming line and its curvature grows monotonically
to c sin(beta) / (d cos^2(beta)) at the joint, c = (2/3) c3 / (1 - c3 (1 + c2))^2 = 1.12216 <
1.1228, so the maximum curvature is 0.9994 K_max; the mirror spiral E0..E3 is flown
backwards. 3D corners are built in the plane of u_in and u_out with the same vector formulas.

Both spirals of a corner take d metres of each adjacent segment. When the segments are too
short for the d that K_max needs, d is shrunk to fit (the two corners sharing a segment split
it: one keeps what it needs if that is at most half, the other gets the rest), the true, larger
curvature is reported, ``kappa_ok`` is False, and the node index is listed in
``tight_corners`` so the planner can be asked for a gentler corner. A reversal (heading change
of pi) cannot be smoothed: the vehicle stops and turns there (also reported).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from companion.errors import SmoothingError
from companion.smoothing.bezier_path import BezierPath
from companion.smoothing.polyline import assemble_stacked, prepare_path
from companion.smoothing.repair import repair_corners

__all__ = [
    "smooth_g2",
    "C1",
    "C2",
    "C3",
    "C4",
    "spiral_pair",
    "spiral_pairs",
    "spiral_distance_m",
    "spiral_curvature_1_m",
    "allocate_segments",
]

logger = logging.getLogger(__name__)

C1 = 7.2364
C2 = 2.0 * (math.sqrt(6.0) - 1.0) / 5.0
C3 = (C2 + 4.0) / (C1 + 6.0)
C4 = 1.1228
_C_JOINT = (2.0 / 3.0) * C3 / (1.0 - C3 * (1.0 + C2)) ** 2


def _fmt_point(p: np.ndarray) -> str:
    """A node as ``[n, e(, d)]`` with 3 decimals (for notes)."""
    return "[" + ", ".join(f"{float(x):.3f}" for x in p) + "]"


def _tight_notes(
    ids: np.ndarray,
    index: np.ndarray,
    corners,
    d_need: np.ndarray,
    d_fit: np.ndarray,
    sizes: np.ndarray,
    kappa_1_m: np.ndarray,
    kappa_max_1_m: float,
) -> list[str]:
    """One note per corner ``ids`` (C',) whose spirals are smaller than K_max needs.

    ``index`` maps cleaned nodes to the input polyline, ``corners`` is the ``Corners`` of the
    cleaned path, ``d_need``/``d_fit``/``sizes`` (C,) the sizes needed, fitted to the segments
    and built, ``kappa_1_m`` (C',) the resulting curvature. The columns are converted to
    Python values once, and the notes formatted in one comprehension.
    """
    reasons = np.where(sizes[ids] == d_fit[ids], "the adjacent segments are too short", "obstacles")
    rows = zip(
        index[ids + 1].tolist(),
        corners.point[ids].tolist(),
        np.degrees(corners.turn_rad[ids]).tolist(),
        d_need[ids].tolist(),
        sizes[ids].tolist(),
        reasons.tolist(),
        kappa_1_m.tolist(),
    )
    return [
        f"corner {node} at {_fmt_point(p)}: heading change {turn:.1f} deg needs d = {need:.3f} m, got "
        f"{got:.3f} m ({why}); curvature {k:.4g} 1/m > K_max {kappa_max_1_m:.4g} 1/m"
        for node, p, turn, need, got, why, k in rows
    ]


def check_kappa(kappa_max_1_m) -> float:
    """Validate K_max (1/m): a finite number > 0."""
    if isinstance(kappa_max_1_m, bool) or not isinstance(kappa_max_1_m, (int, float, np.floating, np.integer)):
        raise SmoothingError(f"kappa_max_1_m: expected a number, got {kappa_max_1_m!r}")
    value = float(kappa_max_1_m)
    if not math.isfinite(value) or value <= 0.0:
        raise SmoothingError(f"kappa_max_1_m: must be a finite number > 0, got {kappa_max_1_m!r}")
    return value


def spiral_distance_m(turn_rad: np.ndarray, kappa_max_1_m: float) -> np.ndarray:
    """Distance d from the corner at which the spirals start (eq. 19), shape like ``turn_rad``."""
    beta = 0.5 * np.asarray(turn_rad, dtype=float)
    return C4 * np.sin(beta) / (kappa_max_1_m * np.cos(beta) ** 2)


def spiral_curvature_1_m(turn_rad: np.ndarray, d_m: np.ndarray) -> np.ndarray:
    """Maximum curvature (at the joint) of the spiral pair of size ``d_m`` (1/m)."""
    beta = 0.5 * np.asarray(turn_rad, dtype=float)
    return _C_JOINT * np.sin(beta) / (np.asarray(d_m, dtype=float) * np.cos(beta) ** 2)


def spiral_pairs(corner: np.ndarray, u_in: np.ndarray, u_out: np.ndarray, d_m: np.ndarray) -> np.ndarray:
    """The two cubic spirals of each corner (eqs. 15-18), vectorised over corners.

    Parameters
    ----------
    corner : ndarray, shape (C, d)
        Corner nodes W.
    u_in, u_out : ndarray, shape (C, d)
        Unit vectors from W towards the previous and the next node.
    d_m : ndarray, shape (C,)
        Distance from W to B0 and E0 (m).

    Returns
    -------
    ndarray, shape (C, 2, 4, d)
        [B0, B1, B2, B3] and [E3, E2, E1, E0] of every corner, in the direction of travel.
    """
    d = np.asarray(d_m, dtype=float)[:, None]
    b0 = corner + d * u_in
    b1 = b0 - C2 * C3 * d * u_in
    b2 = b1 - C3 * d * u_in
    e0 = corner + d * u_out
    e1 = e0 - C2 * C3 * d * u_out
    e2 = e1 - C3 * d * u_out
    out = np.empty((corner.shape[0], 2, 4, corner.shape[1]))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = b0, b1, b2
    out[:, 1, 1], out[:, 1, 2], out[:, 1, 3] = e2, e1, e0
    np.multiply(0.5, b2 + e2, out=out[:, 0, 3])
    out[:, 1, 0] = out[:, 0, 3]
    return out


def spiral_pair(corner: np.ndarray, u_in: np.ndarray, u_out: np.ndarray, d_m: float) -> list[np.ndarray]:
    """The two cubic spirals of one corner: [B0..B3] and [E3..E0], each of shape (4, d)."""
    pair = spiral_pairs(corner[None], u_in[None], u_out[None], np.array([d_m]))[0]
    return [pair[0], pair[1]]


def allocate_segments(d_need: np.ndarray, len_in: np.ndarray, len_out: np.ndarray) -> np.ndarray:
    """Largest corner sizes <= ``d_need`` that fit the segments without overlapping.

    Segment j joins corner j-1 (its start) and corner j (its end); the first and last segments
    have one corner only. Where two corners together need more than the segment, the one
    needing at most half keeps it and the other gets the rest; both get half otherwise.

    Parameters
    ----------
    d_need : ndarray, shape (C,)
        Size each corner needs (0 for corners without a curve).
    len_in, len_out : ndarray, shape (C,)
        Lengths of each corner's incoming and outgoing segments.

    Returns
    -------
    ndarray, shape (C,)
    """
    n = d_need.size
    if n == 0:
        return d_need.copy()
    seg_len = np.concatenate([len_in[:1], len_out])  # (C + 1,)
    left = np.concatenate([[0.0], d_need])  # corner at the segment start
    right = np.concatenate([d_need, [0.0]])  # corner at the segment end
    fits = left + right <= seg_len
    half = 0.5 * seg_len
    left_allowed = np.where(fits, left, np.where(right <= half, seg_len - right, np.where(left <= half, left, half)))
    right_allowed = np.where(fits, right, np.where(left <= half, seg_len - left, np.where(right <= half, right, half)))
    return np.minimum(d_need, np.minimum(right_allowed[:-1], left_allowed[1:]))


def smooth_g2(path, kappa_max_1_m: float, *, world=None, max_halvings: int = 12) -> BezierPath:
    """Curvature-continuous smoothing of a polyline, bounded by K_max (paper eqs. 15-19).

    Parameters
    ----------
    path : array_like, shape (M, d)
        Polyline nodes, d = 2 (north-east) or 3 (NED), M >= 2; repeated nodes are dropped.
    kappa_max_1_m : float
        Curvature bound K_max (1/m), > 0.
    world : companion.world.World, optional
        When given, every corner is re-checked against the inflated obstacles and shrunk (or,
        at worst, kept sharp) until free: the result is never less safe than the polyline.
    max_halvings : int
        How many times a clipping corner may be halved before it is kept sharp.

    Returns
    -------
    BezierPath
        Straight (degree-1) pieces and cubic spirals, addressed by arc length.
        ``kappa_ok`` is True when the curvature never exceeds K_max; otherwise ``notes`` names
        every corner at fault and ``tight_corners`` lists their indices in ``path``.

    Raises
    ------
    SmoothingError
        Fewer than 2 nodes, NaN, bad shape, K_max <= 0.
    """
    kappa = check_kappa(kappa_max_1_m)
    nodes, index, corners = prepare_path(path)
    turn = corners.kind == "turn"
    d_need = np.where(turn, spiral_distance_m(np.where(turn, corners.turn_rad, 0.0), kappa), 0.0)
    d_fit = allocate_segments(d_need, corners.len_in, corners.len_out)
    notes: list[str] = []
    n_corners = corners.kind.size
    kind = np.where(turn, 2, np.where(corners.kind == "reversal", 1, 0))
    curves = np.zeros((n_corners, 2, 4, nodes.shape[1]))
    sizes = d_fit.copy()
    turn_ids = np.nonzero(turn)[0]

    def build(ids: np.ndarray, scale: np.ndarray) -> np.ndarray:
        return spiral_pairs(corners.point[ids], corners.u_in[ids], corners.u_out[ids], d_fit[ids] * scale)

    sharp_ids = np.zeros(0, dtype=int)
    if world is not None and turn_ids.size:
        built, scales, sharp = repair_corners(world, build, turn_ids, max_halvings)
        curves[turn_ids] = built
        sizes[turn_ids] = d_fit[turn_ids] * scales
        for i, sc in zip(turn_ids, scales):
            if sc < 1.0:
                notes.append(f"corner {index[i + 1]}: shrunk to {sc:.4g} of its size to clear obstacles")
        sharp_ids = turn_ids[sharp]
        kind[sharp_ids] = 1
    elif turn_ids.size:
        curves[turn_ids] = build(turn_ids, np.ones(turn_ids.size))
    tight: list[int] = []
    for i in sharp_ids:
        tight.append(int(index[i + 1]))
        notes.append(
            f"corner {index[i + 1]} at {_fmt_point(corners.point[i])}: every smooth "
            f"corner clips an obstacle; kept the polyline corner (the vehicle stops there)"
        )
    for i in np.nonzero(corners.kind == "reversal")[0]:
        tight.append(int(index[i + 1]))
        notes.append(
            f"corner {index[i + 1]} at {_fmt_point(corners.point[i])}: the path "
            f"reverses (heading change {math.degrees(corners.turn_rad[i]):.2f} deg); the "
            f"vehicle stops and turns there"
        )
    smooth_ids = turn_ids[kind[turn_ids] == 2]
    true_kappa = spiral_curvature_1_m(corners.turn_rad[smooth_ids], sizes[smooth_ids])
    over = true_kappa > kappa * (1.0 + 1e-9)
    tight.extend(index[smooth_ids[over] + 1].tolist())
    tight = sorted(set(tight))
    tight_ids = smooth_ids[over]

    def all_notes() -> list[str]:
        return notes + _tight_notes(tight_ids, index, corners, d_need, d_fit, sizes, true_kappa[over], kappa)

    ctrl, degrees = assemble_stacked(nodes, kind, curves)
    curve = BezierPath.from_stacked(
        ctrl,
        degrees,
        kappa_ok=not tight,
        notes=all_notes,
        tight_corners=tight,
        kappa_max_1_m=kappa,
        peaks_at_joints=True,
    )
    if logger.isEnabledFor(logging.INFO):
        for note in curve.notes:
            logger.info("smooth_g2: %s", note)
    return curve
