"""Plane geometry shared by the companion and the SITL vehicle. Pure numerics."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


def point_in_polygon(point: Sequence[float] | np.ndarray, polygon: Sequence[Sequence[float]] | np.ndarray) -> bool:
    """Even-odd rule (crossing number): is the 2D ``point`` inside ``polygon``?

    Parameters
    ----------
    point : (2,) array_like
        (x, y), e.g. (north, east) in metres.
    polygon : (K, 2) array_like
        Vertices in order; the last connects to the first.
    """
    x, y = float(point[0]), float(point[1])
    inside = False
    n = len(polygon)
    if n == 0:
        return False
    xj, yj = polygon[n - 1]
    for i in range(n):
        xi, yi = polygon[i]
        if (yi > y) != (yj > y):
            x_cross = xi + (y - yi) * (xj - xi) / (yj - yi)
            if x < x_cross:
                inside = not inside
        xj, yj = xi, yi
    return inside
