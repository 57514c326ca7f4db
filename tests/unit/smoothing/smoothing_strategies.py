"""Hypothesis strategies shared by the smoothing tests: random polylines in 2D and 3D.

Polylines have segments of at least 1 m and corners that are either exactly straight or turn
by at least 1e-3 rad: below that, a corner curve is micrometres long and the floating-point
rounding of its control points (relative to coordinates of 100 m) dominates its curvature.
"""

import numpy as np
from hypothesis import assume
from hypothesis import strategies as st

coord = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False, allow_infinity=False)


def _turns(path: np.ndarray) -> np.ndarray:
    seg = np.diff(path, axis=0)
    unit = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    cos = np.clip(np.sum(unit[:-1] * unit[1:], axis=1), -1.0, 1.0)
    return np.arccos(cos)


@st.composite
def polylines(draw, dim=None, min_nodes=2, max_nodes=8):
    """An (M, d) polyline with d in {2, 3} (or ``dim``)."""
    d = draw(st.sampled_from([2, 3])) if dim is None else dim
    m = draw(st.integers(min_value=min_nodes, max_value=max_nodes))
    pts = np.array(draw(st.lists(st.lists(coord, min_size=d, max_size=d), min_size=m, max_size=m)))
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assume(np.all(seg >= 1.0))
    turns = _turns(pts)
    assume(np.all((turns == 0.0) | ((turns >= 1e-3) & (turns <= np.pi - 1e-3))))
    return pts


def joint_angles(pieces) -> np.ndarray:
    """Angle (rad) between the end tangent of each piece and the start tangent of the next."""
    out = []
    for a, b in zip(pieces[:-1], pieces[1:]):
        ta = a[-1] - a[-2]
        tb = b[1] - b[0]
        ta = ta / np.linalg.norm(ta)
        tb = tb / np.linalg.norm(tb)
        if ta.size == 2:
            cross = abs(ta[0] * tb[1] - ta[1] * tb[0])
        else:
            cross = np.linalg.norm(np.cross(ta, tb))
        out.append(np.arctan2(cross, np.dot(ta, tb)))
    return np.array(out)
