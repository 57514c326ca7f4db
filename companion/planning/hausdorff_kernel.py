"""M-GART's distinctness test compiled (numba), with the numpy answer wherever it could differ.

:func:`~companion.planning.mgart.hausdorff_m` resamples both paths
(:func:`~companion.planning.mgart.resample_path`, whose points :func:`resample_points` computes
with the same arithmetic) and takes the discrete Hausdorff distance with numpy; M-GART only asks
whether it reaches ``min_separation_m``. :func:`separated_kernel` answers that from the
resampled points with distances summed left to right, which can differ from numpy's in the last
bits only: its answer is taken when the distance is clearly on one side of the threshold, and
:func:`~companion.planning.mgart.separated` lets numpy decide the rare cases within 1e-9
(relative) of it, so the answers are numpy's, always.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["resample_points", "separated_kernel", "UNSURE"]

UNSURE = -1
_TOLERANCE = 1e-9


@njit(cache=True)
def resample_points(path, counts):
    """Points of ``path`` (M, d): its first point, then ``counts[k]`` (M-1,) points per edge k.

    Edge k's points are ``a + (i / n) (b - a)``, i = 1 .. n, the arithmetic of ``resample_path``.
    """
    m, d = path.shape
    out = np.empty((1 + counts.sum(), d))
    out[0] = path[0]
    row = 1
    for k in range(m - 1):
        n = counts[k]
        for i in range(1, n + 1):
            t = i / n
            for j in range(d):
                out[row, j] = path[k, j] + t * (path[k + 1, j] - path[k, j])
            row += 1
    return out


@njit(cache=True)
def _directed(a, b) -> float:
    """max over the points of ``a`` of the distance to the nearest point of ``b``."""
    worst = 0.0
    for i in range(a.shape[0]):
        best = np.inf
        for k in range(b.shape[0]):
            s2 = 0.0
            for j in range(a.shape[1]):
                dj = a[i, j] - b[k, j]
                s2 += dj * dj
            if s2 < best:
                best = s2
        if best > worst:
            worst = best
    return math.sqrt(worst)


@njit(cache=True)
def separated_kernel(a, b, threshold_m: float) -> int:
    """For resampled paths ``a`` (K, d) and ``b`` (L, d): 1 when their discrete Hausdorff
    distance is >= ``threshold_m``, 0 when below, -1 (UNSURE) within 1e-9 (relative) of it."""
    h = max(_directed(a, b), _directed(b, a))
    if abs(h - threshold_m) <= _TOLERANCE * max(1.0, threshold_m):
        return UNSURE
    return 1 if h >= threshold_m else 0
