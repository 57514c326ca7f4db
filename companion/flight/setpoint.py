"""One GUIDED setpoint, and a source of them that holds a point (a hover).

The value the setpoint stream sends (``companion.link.setpoints``) and a fast-time flight gives
the helicopter model (``companion.flight.fast_time``); the active reference produces it
(``companion.flight.reference``). Pure.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["Setpoint", "SetpointSource", "hold_position"]


class Setpoint(NamedTuple):
    """One GUIDED setpoint (None = not commanded; masked out in type_mask).

    Attributes
    ----------
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : ndarray (3,), sequence of 3 floats, or None
    yaw_rad : float or None
    yaw_rate_rad_s : float or None
        With ``yaw_rad``: the heading's rate of change, a feed-forward for the yaw loop.
    """

    pos_ned_m: np.ndarray | Sequence[float] | None
    vel_ned_m_s: np.ndarray | Sequence[float] | None = None
    acc_ned_m_s2: np.ndarray | Sequence[float] | None = None
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None


SetpointSource = Callable[[float], Setpoint]


def hold_position(pos_ned_m, yaw_rad: float | None = None) -> SetpointSource:
    """A source that holds ``pos_ned_m`` with zero velocity and acceleration (a hover)."""
    pos = np.asarray(pos_ned_m, dtype=np.float64).reshape(3).copy()
    zero = np.zeros(3)

    def setpoint_at(t_monotonic_s: float) -> Setpoint:
        return Setpoint(pos, zero, zero, yaw_rad)

    return setpoint_at
