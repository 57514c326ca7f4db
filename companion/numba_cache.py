"""Compile numba kernels before a budget's clock starts (issue 25, item 4).

The planners' and the model's inner loops are ``@njit(cache=True)`` kernels: numba compiles
each one at its first call (about 20 s for all of them on the 2-core reference machine) and
writes the result to its cache (``__pycache__/*.nbi, *.nbc`` next to the source, or
``NUMBA_CACHE_DIR``); a later process loads it from there (about a second). Either happens at
the first call, so a first ``gart(..., max_time_s=0.5)`` would spend its budget compiling.
:func:`compile_once` runs a small workload that makes those first calls, and every budgeted
entry point calls it (through a ``functools.cache``-d function of its own: once per process)
before it reads the clock. When numba's cache holds nothing for the probe kernels it logs, at
INFO, ``compiling <what> (once, about N s)`` first, so a person waiting knows why.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable

__all__ = ["cache_is_cold", "compile_once"]

log = logging.getLogger(__name__)


def _index_of(kernel) -> dict | None:
    """The signatures numba's cache holds for ``kernel`` (a ``@njit(cache=True)`` dispatcher):
    an empty dict when the cache has no index for it, or only a stale one (its source file
    changed, or another numba version wrote it); None when the dispatcher has no cache."""
    cache = getattr(kernel, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is None:
        return None
    return cache_file._load_index()


def cache_is_cold(probes: Iterable) -> bool:
    """True when numba's cache holds no compiled code for one of the ``probes``.

    Parameters
    ----------
    probes : iterable of numba dispatchers
        Kernels whose compilation dominates the workload (a cold cache for them means a compile
        of many seconds, a warm one a load of milliseconds).

    Returns
    -------
    bool
        False when every probe has a fresh cache index, or when numba's cache cannot be read
        (another numba version's internals: then nothing is announced).
    """
    try:
        return any(_index_of(kernel) == {} for kernel in probes)
    except (AttributeError, OSError, EOFError, ValueError) as exc:  # numba's private cache API
        log.debug("numba's cache index not readable (%s): compile not announced", exc)
        return False


def compile_once(what: str, workload: Callable[[], object], probes: Iterable, estimate_s: float) -> float:
    """Run ``workload`` (the first calls of the kernels), announcing a compile when the cache is cold.

    Parameters
    ----------
    what : str
        What is compiled, for the log line (``"the planners"``).
    workload : callable
        Calls every kernel of the group once per argument type used (tiny inputs, no clock).
    probes : iterable of numba dispatchers
        See :func:`cache_is_cold`.
    estimate_s : float
        The compile's duration measured on the reference machine, for the log line.

    Returns
    -------
    float
        The seconds the workload took (a compile, or a load from the cache).
    """
    cold = cache_is_cold(probes)
    if cold:
        log.info("compiling %s (once, about %.0f s)", what, estimate_s)
    start = time.perf_counter()
    workload()
    took = time.perf_counter() - start
    log.log(
        logging.INFO if cold else logging.DEBUG,
        "%s %s in %.1f s",
        what,
        "compiled" if cold else "loaded from numba's cache",
        took,
    )
    return took
