"""Where the companion plans: a warm worker process pool beside the 50 Hz stream (DESIGN 1, 7).

Planning, smoothing, the closed-loop feasibility check, the threat decisions (their
replans) and the M-GART refreshes are pure Python and numpy that hold the GIL for
milliseconds at a time. In a thread of the streaming process they delay the stream by up to
the GIL switch interval each time; in a ``ProcessPoolExecutor`` they only compete for a core,
and the workers run niced (``planning_worker_init``), so the stream keeps its period
(``benchmarks/setpoint_jitter.py``).

``PlanningWorkers.run(fn, *args, **kwargs)`` is the daemon's ``in_worker``: a module-level
function runs in a worker on pickled copies of its arguments and its result comes back. Nothing
else travels: a caller passes values and gets values back (the threat decision sends its
``DecisionState`` and receives the next one; a planner is given a generator of its own,
derived from the flight's).

``kind="thread"`` keeps today's two threads at normal priority (the comparison of the jitter
benchmark, and a fallback). The pool is started and warmed (imports, one tiny GART per worker)
when the flight starts, so that the first plan does not pay for the spawn.
"""

from __future__ import annotations

import asyncio
import functools
import importlib
import logging
import multiprocessing
import multiprocessing.connection
import os
import threading
import time
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor

from companion.link.setpoints import planning_worker_init, restore_normal_priority

log = logging.getLogger(__name__)

__all__ = ["PlanningWorkers", "warm_up"]

#: Niceness of the planning worker processes (the stream's process keeps 0 or better).
WORKER_NICENESS = 10


def worker_init(niceness: int, log_level: int, log_format: str | None) -> None:
    """A planning process starts: it ends with its parent (``exit_with_parent``), normal
    scheduling policy, niced (``planning_worker_init``), and logging as in the companion (its
    lines go to the companion's stderr), except the announcement of a compile on a cold numba
    cache, which the companion makes once for all its workers (``PlanningWorkers.start``)."""
    exit_with_parent()
    planning_worker_init(niceness)
    logging.basicConfig(level=log_level, format=log_format)
    logging.getLogger("companion.numba_cache").setLevel(max(log_level, logging.WARNING))


def exit_with_parent() -> None:
    """End this worker when the companion that asked for it ends. A companion killed with
    SIGKILL (a crash, the kernel's OOM killer) would otherwise leave its workers behind, blocked
    forever on a queue whose ends they hold themselves. ``multiprocessing.parent_process()`` is
    the companion (not the forkserver) and its ``sentinel`` turns readable when it is gone."""
    parent = multiprocessing.parent_process()
    if parent is None or parent.sentinel is None:
        return

    def watch() -> None:
        multiprocessing.connection.wait([parent.sentinel])
        os._exit(0)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _log_format() -> str | None:
    """The format of the root logger's first handler (None: logging's default)."""
    handlers = logging.getLogger().handlers
    formatter = handlers[0].formatter if handlers else None
    return formatter._fmt if formatter is not None else None


def warm_up() -> float:
    """Import the planners and compile their kernels (in a worker); returns the seconds it took.

    The modules a job needs are imported here, and every numba kernel (GART's and M-GART's, the
    helicopter model's for the closed-loop check and the fast-time flights, the prisms' queries)
    is compiled or loaded from numba's cache (``companion.kernels.ensure_compiled``), not at
    the first plan nor inside any budget.
    """
    t0 = time.perf_counter()
    for module in ("companion.flight.plan", "companion.threats.decision.step", "companion.smoothing.feasibility"):
        importlib.import_module(module)  # smoothing and timing; the threat decision and M-GART
    from companion.kernels import ensure_compiled

    ensure_compiled()
    return time.perf_counter() - t0


class PlanningWorkers:
    """The daemon's planning workers (see the module docstring).

    Parameters
    ----------
    kind : str
        ``"process"`` (default: a ``ProcessPoolExecutor`` of niced workers, started by
        ``forkserver`` so that no thread of this process is forked) or ``"thread"``.
    workers : int
        Number of workers: a decision and an M-GART refresh run side by side.
    """

    KINDS = ("process", "thread")

    def __init__(self, kind: str = "process", workers: int = 2) -> None:
        if kind not in self.KINDS:
            raise ValueError(f"kind: expected one of {', '.join(self.KINDS)}, got {kind!r}")
        self.kind = kind
        self.workers = int(workers)
        self._executor: Executor | None = None

    @property
    def executor(self) -> Executor:
        if self._executor is None:
            if self.kind == "process":
                self._executor = ProcessPoolExecutor(
                    self.workers,
                    mp_context=multiprocessing.get_context("forkserver"),
                    initializer=worker_init,
                    initargs=(WORKER_NICENESS, logging.getLogger().getEffectiveLevel(), _log_format()),
                )
            else:
                self._executor = ThreadPoolExecutor(
                    self.workers, thread_name_prefix="planning", initializer=restore_normal_priority
                )
        return self._executor

    def start(self) -> asyncio.Future:
        """Start every worker now (from the calling thread) and warm it up (imports, the
        kernels compiled or loaded: ``warm_up``) in the background; await the future returned
        to wait until they are ready. A cold numba cache is announced here, once."""
        from companion.kernels import announce_if_cold

        loop = asyncio.get_running_loop()
        t0 = time.perf_counter()
        if self.kind == "process":
            announce_if_cold()  # the workers themselves do not (worker_init)
        warming = [loop.run_in_executor(self.executor, warm_up) for _ in range(self.workers)]

        async def ready() -> None:
            spent = await asyncio.gather(*warming)
            log.info(
                "planning workers (%d %s) ready in %.2f s (warm-up %s s)",
                self.workers,
                "processes" if self.kind == "process" else "threads",
                time.perf_counter() - t0,
                ", ".join(f"{s:.2f}" for s in spent),
            )

        return asyncio.ensure_future(ready())

    async def run(self, fn, /, *args, **kwargs):
        """Run ``fn(*args, **kwargs)`` in a worker and return its result (``fn`` module-level:
        it is pickled by reference to a worker process, with copies of its arguments)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self.executor, functools.partial(fn, *args, **kwargs))

    def submit(self, fn, /, *args) -> Future:
        """Start ``fn(*args)`` in a worker; returns its ``concurrent.futures.Future`` (the
        flight executor's jobs, ``companion.service.jobs``)."""
        return self.executor.submit(fn, *args)

    async def on_each(self, fn, /, *args) -> None:
        """Run ``fn(*args)`` once per worker, side by side (a per-process cache filled in every
        worker; best effort: an idle worker takes each call)."""
        loop = asyncio.get_running_loop()
        await asyncio.gather(*(loop.run_in_executor(self.executor, fn, *args) for _ in range(self.workers)))

    def shutdown(self) -> None:
        """Stop the workers (pending work is cancelled)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
