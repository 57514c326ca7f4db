"""``math.dist`` inside compiled code, to the last bit (numba).

The Python planner measures edges with :func:`math.dist`, which CPython computes more accurately
than ``sqrt(dx*dx + dy*dy)``: the coordinates' differences are scaled by a power of two, squared
without loss (an exact two-product), summed with a compensated sum, and the square root gets
one differential correction (faithful rounding, usually correct rounding). A compiled planner
that used the naive formula would disagree with the Python one in the last bit now and then, and
an RRT* tree amplifies such a difference into another tree. :func:`python_dist` follows the same
steps; the exact product is Dekker's (Veltkamp splitting), which gives the same pair as a fused
multiply-add. It is checked against :func:`math.dist` by the unit tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from heli_common.pyfloat import exact_product

__all__ = ["python_dist"]

_DBL_MIN = 2.2250738585072014e-308


@njit(cache=True)
def _scaled_norm(diffs: np.ndarray, largest: float) -> float:
    """Norm of ``diffs`` (d,) (non-negative, finite, largest ``largest`` > 0), CPython's way."""
    _, exponent = math.frexp(largest)
    scale = math.ldexp(1.0, -exponent)
    total = 1.0  # compensated sum started at 1 (subtracted at the end)
    frac_sq = 0.0  # low parts of the squares
    frac_sum = 0.0  # rounding errors of the sum
    for k in range(diffs.shape[0]):
        x = diffs[k] * scale
        sq, sq_lo = exact_product(x, x)
        s = total + sq
        frac_sum += sq - (s - total)
        total = s
        frac_sq += sq_lo
    h = math.sqrt(total - 1.0 + (frac_sq + frac_sum))
    sq, sq_lo = exact_product(-h, h)
    s = total + sq
    frac_sum += sq - (s - total)
    total = s
    frac_sq += sq_lo
    x = total - 1.0 + (frac_sq + frac_sum)
    h += x / (2.0 * h)
    return h / scale


@njit(cache=True)
def python_dist(p, q) -> float:
    """``math.dist(p, q)`` for two points of d >= 2 finite coordinates (arrays or tuples)."""
    d = len(p)
    diffs = np.empty(d)
    largest = 0.0
    for k in range(d):
        x = abs(p[k] - q[k])
        diffs[k] = x
        if x > largest:
            largest = x
    if largest == 0.0:
        return largest
    _, exponent = math.frexp(largest)
    if exponent < -1023:  # subnormal differences: lift them to normal numbers first
        for k in range(d):
            diffs[k] /= _DBL_MIN
        return _DBL_MIN * _scaled_norm(diffs, largest / _DBL_MIN)
    return _scaled_norm(diffs, largest)
