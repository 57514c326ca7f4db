"""M-GART's distinctness test compiled (numba), with the numpy answer wherever it could differ.

:func:`~companion.planning.mgart.hausdorff_m` resamples both paths (``resample_path``) and takes
the discrete Hausdorff distance with numpy; M-GART only asks whether it reaches
``min_separation_m``. :func:`separated_kernel` answers that from the same resampled points (the same
count per edge, the same ``a + t (b - a)`` arithmetic) with distances summed left to right, which
can differ from numpy's in the last bits only. So the compiled answer is taken when the distance
is clearly on one side of the threshold, and the numpy function decides the rare cases within
1e-9 (relative) of it, or an edge whose length is within 1e-9 of a whole number of samples
(where the sample count itself could differ): :func:`~companion.planning.mgart.separated`
returns numpy's answer, always.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["separated_kernel", "UNSURE"]

UNSURE = -1
_TOLERANCE = 1e-9


@njit(cache=True)
def _resample(path, step_m):
    """``resample_path`` of the path (M, d): (K, d) points, or an empty array when a count is unsure."""
    m, d = path.shape
    counts = np.empty(max(m - 1, 0), dtype=np.int64)
    total = 1
    for k in range(m - 1):
        s2 = 0.0
        for j in range(d):
            dj = path[k + 1, j] - path[k, j]
            s2 += dj * dj
        q = math.sqrt(s2) / step_m
        if abs(q - round(q)) <= _TOLERANCE * max(1.0, q):
            return np.empty((0, d))
        counts[k] = max(1, int(math.ceil(q)))
        total += counts[k]
    out = np.empty((total, d))
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
def separated_kernel(path_a, path_b, step_m: float, threshold_m: float) -> int:
    """1 when the discrete Hausdorff distance is >= ``threshold_m``, 0 when below, -1 when unsure."""
    a = _resample(path_a, step_m)
    b = _resample(path_b, step_m)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return UNSURE
    h = max(_directed(a, b), _directed(b, a))
    if abs(h - threshold_m) <= _TOLERANCE * max(1.0, threshold_m):
        return UNSURE
    return 1 if h >= threshold_m else 0
