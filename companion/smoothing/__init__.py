"""Path smoothing and timing (paper section 3.2): G1 and G2 Bezier smoothing, speed profiles.

- ``smooth_g1(path)``: quartic midpoint interpolation, tangent-continuous (``g1.py``).
- ``smooth_g2(path, kappa_max_1_m, *, world=None)``: cubic Bezier spiral pairs,
  curvature-continuous and bounded by K_max (``g2.py``).
- ``time_parameterize(curve, limits)`` -> ``companion.flight.trajectory.Trajectory`` (``timing.py``).
- ``feasibility.check_and_stretch(trajectory)``: closed-loop check on the helicopter model.
"""

from companion.smoothing.bezier import BezierPath
from companion.smoothing.g1 import smooth_g1
from companion.smoothing.g2 import smooth_g2
from companion.smoothing.settings import FeasibilitySettings, SmoothingSettings, TrajectoryLimits
from companion.smoothing.timing import time_parameterize

__all__ = [
    "BezierPath",
    "smooth_g1",
    "smooth_g2",
    "time_parameterize",
    "TrajectoryLimits",
    "SmoothingSettings",
    "FeasibilitySettings",
]
