"""Every numba kernel of the companion compiled (or loaded from numba's cache) before any budget.

``ensure_compiled()`` is what a process that plans calls before its first budgeted work: the
planning workers of ``companion run`` and ``companion serve`` (``companion.workers.warm_up``),
the threat decision step, ``companion demo``. It joins the groups that the public calls warm by
themselves on their first call (``companion.planning.gart.warm``: GART and M-GART;
``companion.smoothing.feasibility.warm_model``: the helicopter model) and the prisms' queries.
Each group runs once per process; see :mod:`companion.numba_cache`.
"""

from __future__ import annotations

import functools
import logging

from companion.numba_cache import cache_is_cold
from companion.planning.gart import PLANNER_PROBES, PLANNERS_COMPILE_S, warm
from companion.smoothing.feasibility import MODEL_COMPILE_S, model_probes, warm_model
from companion.world import polyhedral_kernels

__all__ = ["COMPILE_S", "announce_if_cold", "ensure_compiled"]

log = logging.getLogger(__name__)

#: Every kernel compiled on a cold numba cache, on the 2-core reference machine (s).
COMPILE_S = PLANNERS_COMPILE_S + MODEL_COMPILE_S


def announce_if_cold() -> bool:
    """Log ``compiling the planners (once, about N s)`` when numba's cache is cold for any
    group, without compiling (a process about to have its workers compile); returns whether
    it was cold."""
    cold = cache_is_cold(PLANNER_PROBES + model_probes())
    if cold:
        log.info("compiling the planners (once, about %.0f s)", COMPILE_S)
    return cold


@functools.cache
def ensure_compiled() -> float:
    """Compile or load every kernel group once in this process.

    Returns
    -------
    float
        The seconds its first call in this process took (later calls return it at once).
    """
    polyhedral_kernels.warm_up()
    return warm() + warm_model()
