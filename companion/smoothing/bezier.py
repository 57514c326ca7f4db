"""Bezier curves for path smoothing (paper section 3.2): the public names in one place.

The machinery is split by step:

- ``bezier_maths``: one curve's Bernstein evaluation (eq. 8), derivatives, curvature
  |B' x B''| / |B'|^3, Gauss-Legendre arc length, de Casteljau splitting, degree elevation;
- ``bezier_arclength``: the knot table of a chain and its quintic-Hermite inverse s -> u;
- ``bezier_peaks``: the curvature maxima inside pieces (G1 corners);
- ``bezier_joints``: tangent discontinuities at joints (where a trajectory stops);
- ``bezier_path``: ``BezierPath``, a chain of pieces addressed by arc length.

The corner curves themselves are built in ``g1`` (quartic midpoint interpolation) and ``g2``
(cubic spiral pairs). Import from here (``companion.smoothing.bezier``) or from the step's own
module.
"""

from companion.smoothing.bezier_maths import (
    arc_length,
    bernstein,
    curvature,
    curvature_from_derivatives,
    derivative,
    derivative_control_points,
    elevate,
    elevate_lines,
    evaluate,
    split,
)
from companion.smoothing.bezier_path import BezierPath

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
    "elevate_lines",
    "BezierPath",
]
