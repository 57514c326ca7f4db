"""Polyline preparation shared by the G1 and G2 smoothers (paper section 3.2).

A planner's path is validated (shape, finite values), repeated nodes are dropped, and the
corner geometry at every interior node is computed: the unit vectors towards both neighbours,
the adjacent segment lengths and the heading change. Corners are then classified as
``straight`` (heading change below 1e-7 rad: nothing to smooth), ``reversal`` (the path turns
back on itself, heading change within 1e-3 rad of pi: no smooth curve exists, the vehicle must
stop) or ``turn``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.errors import SmoothingError
from companion.smoothing.bezier_maths import elevate_lines

__all__ = ["Corners", "clean_path", "prepare_path", "corner_geometry", "assemble_stacked"]

STRAIGHT_RAD = 1e-7
REVERSAL_RAD = 1e-3


def _distinct_nodes(path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate a polyline (M, d) and index its nodes without consecutive repeats: (array, index)."""
    try:
        arr = np.asarray(path, dtype=float)
    except (TypeError, ValueError):
        raise SmoothingError(f"{name}: expected an (M, d) array of numbers") from None
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise SmoothingError(f"{name}: expected shape (M, 2) or (M, 3), got {arr.shape}")
    if arr.shape[0] < 2:
        raise SmoothingError(f"{name}: needs at least 2 nodes, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.nonzero(~np.all(np.isfinite(arr), axis=1))[0][0])
        raise SmoothingError(f"{name}: node {bad} is not finite (NaN or inf)")
    scale = max(1.0, float(np.max(np.abs(arr))))
    step = np.linalg.norm(np.diff(arr, axis=0), axis=1)
    keep = np.concatenate([[True], step > 1e-9 * scale])
    index = np.nonzero(keep)[0]
    if index.size < 2:
        raise SmoothingError(f"{name}: all {arr.shape[0]} nodes are at the same place; nothing to smooth")
    return arr, index


def clean_path(path, name: str = "path") -> tuple[np.ndarray, np.ndarray]:
    """Validate a polyline, drop repeated consecutive nodes and nodes where it runs straight on.

    Parameters
    ----------
    path : array_like, shape (M, d)
        Nodes, d = 2 (north-east) or 3 (NED), M >= 2.
    name : str
        Argument name used in error messages.

    Returns
    -------
    nodes : ndarray, shape (M', d)
        Nodes without consecutive repeats or straight-on nodes (M' >= 2).
    index : ndarray of int, shape (M',)
        Index of every kept node in the input.

    Raises
    ------
    SmoothingError
        Wrong shape, fewer than 2 nodes, NaN/inf, or every node at the same place.
    """
    arr, index = _distinct_nodes(path, name)
    index = drop_straight_nodes(arr, index)
    return arr[index], index


def prepare_path(path, name: str = "path") -> tuple[np.ndarray, np.ndarray, Corners]:
    """``clean_path`` and ``corner_geometry`` in one pass (what the G1 and G2 smoothers need).

    The corner geometry of the distinct nodes also tells whether any node runs straight on
    (heading change below twice ``STRAIGHT_RAD``, a margin over the sequential rule of
    ``drop_straight_nodes``); only then are nodes dropped and the geometry computed again.

    Returns
    -------
    nodes : ndarray, shape (M', d)
    index : ndarray of int, shape (M',)
    corners : Corners
        Geometry of the M' - 2 corners of ``nodes``.
    """
    arr, index = _distinct_nodes(path, name)
    corners = corner_geometry(arr[index])
    if np.any(corners.turn_rad < 2.0 * STRAIGHT_RAD):
        index = drop_straight_nodes(arr, index)
        corners = corner_geometry(arr[index])
    return arr[index], index, corners


def drop_straight_nodes(arr: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Leave out interior nodes where the heading changes by less than ``STRAIGHT_RAD``.

    Two straight pieces meeting there would carry that (numerically tiny) tangent jump; one
    straight piece through them has none and stays within ``STRAIGHT_RAD`` times its length
    of the node. The heading change at a node is measured from the last node kept, so the
    rule is sequential; it is evaluated for all nodes at once against their direct neighbours,
    and the exact sequential rule (``_straight_at``) is applied only to nodes within a factor 2
    of the threshold and to the nodes that follow a dropped one: the same nodes are kept as by
    a node-by-node walk.

    Parameters
    ----------
    arr : ndarray, shape (M, d)
    index : ndarray of int, shape (M',)
        Nodes of ``arr`` to consider, in order (no consecutive repeats).

    Returns
    -------
    ndarray of int, shape (M'',)
        The subset of ``index`` that is kept (first and last always).
    """
    if index.size < 3:
        return index
    seg = np.diff(arr[index], axis=0)
    a, b = seg[:-1], seg[1:]
    cos = np.einsum("ij,ij->i", a, b)
    sin = _cross_norm(a, b)
    check = np.nonzero(np.arctan2(sin, cos) < 2.0 * STRAIGHT_RAD)[0] + 1  # positions in index
    if check.size == 0:
        return index
    kept = np.ones(index.size, dtype=bool)
    todo = sorted(check.tolist())
    anchor = 0
    while todo:
        pos = todo.pop(0)
        if kept[pos - 1]:
            anchor = pos - 1
        if not _straight_at(arr, index[anchor], index[pos], index[pos + 1]):
            continue
        kept[pos] = False
        if pos + 1 < index.size - 1 and (not todo or todo[0] != pos + 1):
            todo.insert(0, pos + 1)
    return index[kept]


def _straight_at(arr: np.ndarray, prev: int, node: int, nxt: int) -> bool:
    """Whether the heading change at ``node`` (from ``prev``, to ``nxt``) is below ``STRAIGHT_RAD``."""
    a, b = arr[node] - arr[prev], arr[nxt] - arr[node]
    cos = float(np.dot(a, b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    sin: float | np.floating = float(np.linalg.norm(np.cross(a, b) if a.size == 3 else a[0] * b[1] - a[1] * b[0]))
    sin /= np.linalg.norm(a) * np.linalg.norm(b)
    return math.atan2(sin, cos) < STRAIGHT_RAD


def _cross_norm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a x b| of the rows of (K, 2) or (K, 3) arrays -> (K,) (the components written out:
    the same values as ``numpy.linalg.norm(numpy.cross(a, b), axis=1)``, without its overhead)."""
    if a.shape[1] == 2:
        return np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    x, y, z = a[:, 0], a[:, 1], a[:, 2]
    u, v, w = b[:, 0], b[:, 1], b[:, 2]
    cx = y * w - z * v
    cy = z * u - x * w
    cz = x * v - y * u
    return np.sqrt(cx * cx + cy * cy + cz * cz)


@dataclass(frozen=True)
class Corners:
    """Geometry of the interior nodes 1..M-2 of a cleaned polyline (C = M - 2 corners).

    Attributes
    ----------
    point : ndarray, shape (C, d)
        Corner nodes.
    u_in : ndarray, shape (C, d)
        Unit vector from the corner towards the previous node.
    u_out : ndarray, shape (C, d)
        Unit vector from the corner towards the next node.
    len_in, len_out : ndarray, shape (C,)
        Lengths of the incoming and outgoing segments (m).
    turn_rad : ndarray, shape (C,)
        Heading change at the corner, in [0, pi].
    kind : ndarray of str, shape (C,)
        ``"straight"``, ``"turn"`` or ``"reversal"``.
    """

    point: np.ndarray
    u_in: np.ndarray
    u_out: np.ndarray
    len_in: np.ndarray
    len_out: np.ndarray
    turn_rad: np.ndarray
    kind: np.ndarray


def corner_geometry(nodes: np.ndarray) -> Corners:
    """Corner geometry of a cleaned polyline ``nodes`` (M, d)."""
    seg = np.diff(nodes, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    unit = seg / seg_len[:, None]
    t_in = unit[:-1]
    t_out = unit[1:]
    cos_turn = np.clip(np.sum(t_in * t_out, axis=1), -1.0, 1.0)
    # atan2(|a x b|, a.b) is accurate at both ends of [0, pi], unlike arccos
    turn = np.arctan2(_cross_norm(t_in, t_out), cos_turn)
    kind = np.where(turn < STRAIGHT_RAD, "straight", np.where(turn > np.pi - REVERSAL_RAD, "reversal", "turn"))
    return Corners(
        point=nodes[1:-1], u_in=-t_in, u_out=t_out, len_in=seg_len[:-1], len_out=seg_len[1:], turn_rad=turn, kind=kind
    )


def assemble_stacked(nodes: np.ndarray, corner_kind: np.ndarray, curves: np.ndarray):
    """Chain corner curves with straight pieces, all as one stacked array.

    Parameters
    ----------
    nodes : ndarray, shape (M, d)
    corner_kind : ndarray of int, shape (M-2,)
        For every interior node: 0 = no curve (the straight line runs through it), 1 = kept
        sharp (the lines meet at the node; the trajectory stops there), 2 = curved.
    curves : ndarray, shape (M-2, m, N+1, d)
        The m Bezier pieces of degree N of every corner (used where ``corner_kind == 2``),
        starting on the incoming segment and ending on the outgoing one.

    Returns
    -------
    ctrl : ndarray, shape (P, N+1, d)
        Every piece elevated to degree N, in order from ``nodes[0]`` to ``nodes[-1]``.
    degrees : ndarray of int, shape (P,)
        1 for the straight pieces, N for the corner curves.
    """
    degree = curves.shape[2] - 1
    m = curves.shape[1]
    used = np.nonzero(corner_kind > 0)[0]
    curved = corner_kind[used] == 2
    entry = np.where(curved[:, None], curves[used, 0, 0], nodes[used + 1])  # (K, d)
    exit_ = np.where(curved[:, None], curves[used, -1, -1], nodes[used + 1])
    line_a = np.vstack([nodes[:1], exit_])
    line_b = np.vstack([entry, nodes[-1:]])
    lines = elevate_lines(line_a, line_b, degree)  # (K+1, N+1, d)
    count = 1 + m * curved.astype(int)  # pieces per corner + line
    first = np.concatenate([[0], np.cumsum(count)])  # line index of each block
    total = int(first[-1]) + 1
    ctrl = np.empty((total, degree + 1, nodes.shape[1]))
    degrees = np.full(total, degree)
    ctrl[first] = lines
    degrees[first] = 1
    rows = first[:-1][curved]
    for j in range(m):
        ctrl[rows + 1 + j] = curves[used[curved], j]
    return ctrl, degrees
