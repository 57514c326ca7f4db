"""The view's geometry: NED to the display's east-north-up, attitudes, tubes, walls. Pure numpy.

Foxglove's 3D panel (and the report's 3D plot) draw a right-handed frame with z up, so positions
go from local NED about home to ``map``, east-north-up about home; the vehicle's body axes from
forward-right-down to forward-left-up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["enu_from_ned", "flu_quaternion_enu", "threat_tube", "prism_side_triangles"]

#: NED -> ENU swaps north and east and flips down (its own inverse).
_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def enu_from_ned(points_ned_m: Sequence) -> np.ndarray:
    """Positions NED -> ENU, shape (..., 3) -> (..., 3)."""
    return np.asarray(points_ned_m, dtype=float) @ _ENU_FROM_NED.T


def prism_side_triangles(vertices_ne_m: Sequence, bottom_m: float, top_m: float) -> np.ndarray:
    """The side walls of a polygon (north-east, shape (n, 2)) extruded from ``bottom_m`` to
    ``top_m`` (up), two triangles per edge, ENU: shape (6 n, 3). Right for any simple polygon."""
    ring = np.asarray(vertices_ne_m, dtype=float)[:, ::-1]  # (east, north)
    nxt = np.roll(ring, -1, axis=0)
    lo, hi = np.full((len(ring), 1), bottom_m), np.full((len(ring), 1), top_m)
    a, b = np.hstack([ring, lo]), np.hstack([nxt, lo])
    c, d = np.hstack([nxt, hi]), np.hstack([ring, hi])
    return np.stack([a, b, c, a, c, d], axis=1).reshape(-1, 3)


def threat_tube(
    position_ned_m: np.ndarray,
    velocity_ned_m_s: np.ndarray,
    radius_m: float,
    age_s: float,
    horizon_s: float,
    step_s: float,
    uncertainty_m_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Centres (NED, shape (k, 3)) and radii (shape (k,)) of a threat's predicted tube.

    Constant velocity from the report, ``age_s`` ago, every ``step_s`` up to ``horizon_s`` ahead
    of now; a mover's radius grows by ``uncertainty_m_s`` per second since the report (as
    ``companion.threats.decision.prediction`` predicts it). A threat at rest is one sphere, its own size.
    """
    if np.linalg.norm(velocity_ned_m_s) <= 1e-6:
        return position_ned_m[None, :].astype(float), np.array([float(radius_m)])
    ages = age_s + np.arange(0.0, horizon_s + 1e-9, step_s)
    centres = position_ned_m[None, :] + ages[:, None] * velocity_ned_m_s[None, :]
    return centres, radius_m + uncertainty_m_s * ages


def _multiply(a: tuple, b: tuple) -> tuple[float, float, float, float]:
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


#: NED -> ENU is half a turn about (1, 1, 0); FLU -> FRD half a turn about x.
_Q_ENU_FROM_NED = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)
_Q_FRD_FROM_FLU = (1.0, 0.0, 0.0, 0.0)


def flu_quaternion_enu(euler_rad: Sequence[float]) -> tuple[float, float, float, float]:
    """The attitude (roll, pitch, yaw of FRD in NED, rad; ZYX order) as the quaternion
    (x, y, z, w) of the body's forward-left-up axes in east-north-up."""
    roll, pitch, yaw = (0.5 * float(a) for a in euler_rad)
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    q_ned_frd = (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )
    return _multiply(_multiply(_Q_ENU_FROM_NED, q_ned_frd), _Q_FRD_FROM_FLU)
