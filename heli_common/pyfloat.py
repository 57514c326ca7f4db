"""Python's float arithmetic inside numba kernels, to the last bit.

A kernel that must give the very bits the Python code gives (the planner's and the model's
compiled paths, checked against the Python ones) cannot use LLVM's versions of a few things:

- ``x ** 2`` in Python is the C library's ``pow(x, 2.0)``, which differs from ``x * x`` in the
  last bit for about one ``x`` in a thousand; LLVM rewrites a ``pow`` with a constant exponent
  into ``x * x``, so :func:`libm_pow` calls the library's ``pow`` under a symbol name LLVM does
  not know (:func:`py_square`: Python's ``x ** 2``, overflow included);
- ``min``/``max`` follow Python's rule (the first argument unless the second is strictly
  smaller/greater), which decides signed zeros and NaN (:func:`py_min`, :func:`py_max`);
- ``math.hypot`` is CPython's compensated vector norm (scaled by a power of two, squares split
  exactly by Dekker's product, a compensated sum, one correction of the root):
  :func:`py_hypot`, :func:`scaled_norm2`, :func:`exact_product`.

No ``fastmath`` anywhere. Compiled at the first call and cached on disk (``cache=True``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math

from llvmlite import binding as llvm_binding
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["libm_pow", "py_square", "py_min", "py_max", "exact_product", "scaled_norm2", "py_hypot"]

_SPLITTER = 134217729.0  # 2**27 + 1: Veltkamp's split of a double into two halves
_DBL_MIN = 2.2250738585072014e-308
POW_SYMBOL = "heli_common_libm_pow"


def _libm_pow_address() -> int:
    """Address of the C library's ``pow`` (the one CPython's ``float.__pow__`` calls)."""
    try:
        fn = ctypes.CDLL(None).pow
    except AttributeError:  # an interpreter that does not export libm's symbols
        fn = ctypes.CDLL(ctypes.util.find_library("m")).pow
    address = ctypes.cast(fn, ctypes.c_void_p).value
    if address is None:  # a NULL pointer: no symbol to hand LLVM
        raise OSError("the C library's pow has no address")
    return address


llvm_binding.add_symbol(POW_SYMBOL, _libm_pow_address())


@intrinsic
def libm_pow(typingctx, x, y):
    """``pow(x, y)`` of the C library, called under a name LLVM does not simplify."""
    sig = types.float64(types.float64, types.float64)

    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        fn = builder.module.globals.get(POW_SYMBOL)
        if fn is None:
            fn = ir.Function(builder.module, ir.FunctionType(double, [double, double]), name=POW_SYMBOL)
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True)
def py_min(x: float, y: float) -> float:
    """Python's ``min(x, y)``."""
    return y if y < x else x


@njit(cache=True)
def py_max(x: float, y: float) -> float:
    """Python's ``max(x, y)``."""
    return y if y > x else x


@njit(cache=True)
def py_square(x: float) -> float:
    """Python's ``x ** 2`` for a float ``x`` (``OverflowError`` when the square overflows)."""
    r = libm_pow(x, 2.0)
    if math.isinf(r) and not math.isinf(x):
        raise OverflowError("(34, 'Numerical result out of range')")
    return r


@njit(cache=True)
def exact_product(a: float, b: float) -> tuple[float, float]:
    """``(p, e)`` with ``p = fl(a * b)`` and ``a * b = p + e`` exactly (Dekker)."""
    p = a * b
    c = _SPLITTER * a
    a_hi = c - (c - a)
    a_lo = a - a_hi
    c = _SPLITTER * b
    b_hi = c - (c - b)
    b_lo = b - b_hi
    e = ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo
    return p, e


@njit(cache=True)
def scaled_norm2(x0: float, x1: float, largest: float) -> float:
    """Norm of ``(x0, x1)`` (non-negative, finite, largest ``largest`` > 0), CPython's way."""
    _, exponent = math.frexp(largest)
    scale = math.ldexp(1.0, -exponent)
    total = 1.0  # compensated sum started at 1 (subtracted at the end)
    frac_sq = 0.0  # low parts of the squares
    frac_sum = 0.0  # rounding errors of the sum
    for x in (x0 * scale, x1 * scale):
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
def py_hypot(x: float, y: float) -> float:
    """``math.hypot(x, y)`` (CPython >= 3.10) for finite or infinite, non-NaN ``x``, ``y``."""
    x0 = abs(x)
    x1 = abs(y)
    if math.isnan(x0) or math.isnan(x1):
        return x0 if math.isinf(x0) else (x1 if math.isinf(x1) else math.nan)
    largest = x1 if x1 > x0 else x0
    if math.isinf(largest) or largest == 0.0:
        return largest
    _, exponent = math.frexp(largest)
    if exponent < -1023:  # subnormal arguments: lift them to normal numbers first
        return _DBL_MIN * scaled_norm2(x0 / _DBL_MIN, x1 / _DBL_MIN, largest / _DBL_MIN)
    return scaled_norm2(x0, x1, largest)
