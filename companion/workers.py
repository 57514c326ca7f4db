"""Where the companion plans: a warm worker process pool beside the 50 Hz stream (DESIGN 1, 7).

Planning, smoothing, the closed-loop feasibility check, the threat manager's decisions (its
replans) and the M-GART refreshes are pure Python and numpy that hold the GIL for
milliseconds at a time. In a thread of the streaming process they delay the stream by up to
the GIL switch interval each time; in a ``ProcessPoolExecutor`` they only compete for a core,
and the workers run niced (``planning_worker_init``), so the stream keeps its period
(``benchmarks/setpoint_jitter.py``).

``PlanningWorkers.run(fn, *args, **kwargs)`` is the daemon's ``in_worker``:

- a function runs in a worker on pickled copies of its arguments; a
  ``numpy.random.Generator`` argument comes back advanced (its state is adopted), so a flight
  draws the same numbers as with threads;
- a bound method (the threat manager's ``on_threats``, ``resume``, ``compute_alternatives``)
  runs on a copy of its object, and the attributes the call changed are adopted back
  (``adopt_changes``), except those the caller replaced meanwhile (e.g. a new active
  reference engaged while a decision was computed): the manager's state stays in this process,
  as with threads.

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
import pickle
import threading
import time
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np

from companion.link.setpoints import planning_worker_init, restore_normal_priority

log = logging.getLogger(__name__)

__all__ = ["AlternativesGate", "PlanningWorkers", "adopt_changes", "call_function", "call_method", "warm_up"]

#: Niceness of the planning worker processes (the stream's process keeps 0 or better).
WORKER_NICENESS = 10
_MISSING = object()


def worker_init(niceness: int, log_level: int, log_format: str | None) -> None:
    """A planning process starts: it ends with its parent (``exit_with_parent``), normal
    scheduling policy, niced (``planning_worker_init``), and logging as in the companion (its
    lines go to the companion's stderr)."""
    exit_with_parent()
    planning_worker_init(niceness)
    logging.basicConfig(level=log_level, format=log_format)


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
    """Import the planners and run one tiny GART and M-GART (in a worker); returns the seconds it took.

    The planners' numba kernels are loaded here, not at the first plan: GART's compiled
    iteration and shortcut, and M-GART's distinctness test (other code, loaded at its first call).
    """
    t0 = time.perf_counter()
    from companion.planning import gart, mgart
    from companion.world import Disc, Sphere, World

    for module in ("companion.flight.plan", "companion.threats.decision.policy", "companion.smoothing.feasibility"):
        importlib.import_module(module)      # smoothing and timing; the threat manager and M-GART

    # 2D and 3D: numba specialises on the points' tuple length; no straight line: iterations run
    for world in (World([Disc((5.0, 5.0), 1.5)], np.zeros(2), np.full(2, 10.0)),
                  World([Sphere((5.0, 5.0, 5.0), 1.5)], np.zeros(3), np.full(3, 10.0))):
        start, goal = np.full(world.dim, 1.0), np.full(world.dim, 9.0)
        gart(world, start, goal, rng=np.random.default_rng(0), stop_at_first=True, max_time_s=60.0)
        mgart(world, start, goal, 1, rng=np.random.default_rng(0), max_time_s=60.0)
    return time.perf_counter() - t0


def call_function(fn, args: tuple, kwargs: dict):
    """Run ``fn(*args, **kwargs)``; returns its result and the states of its generators.

    Returns
    -------
    result, states : object, dict
        ``states`` maps each ``numpy.random.Generator`` argument's position (int) or keyword
        (str) to its bit generator's state after the call.
    """
    result = fn(*args, **kwargs)
    states = {key: value.bit_generator.state for key, value in [*enumerate(args), *kwargs.items()]
              if isinstance(value, np.random.Generator)}
    return result, states


def call_method(obj, name: str, args: tuple, kwargs: dict):
    """Run ``obj.name(*args, **kwargs)`` on this copy of ``obj``; returns the result and the
    attributes the call changed (compared by their pickles), pickled together with it so that
    objects shared between them stay shared."""
    before = {key: pickle.dumps(value, pickle.HIGHEST_PROTOCOL) for key, value in vars(obj).items()}
    result = getattr(obj, name)(*args, **kwargs)
    changed = {key: value for key, value in vars(obj).items()
               if before.get(key) != pickle.dumps(value, pickle.HIGHEST_PROTOCOL)}
    return result, changed


def adopt_changes(obj, sent: dict, changed: dict) -> list[str]:
    """Set the attributes of ``obj`` that a worker's call changed, unless the caller replaced
    them meanwhile (``sent``: the attributes as they were when the call was sent, compared by
    identity). Returns the names adopted."""
    current = vars(obj)
    adopted = []
    for key, value in changed.items():
        if current.get(key, _MISSING) is sent.get(key, _MISSING):
            current[key] = value
            adopted.append(key)
    return adopted


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
                    self.workers, mp_context=multiprocessing.get_context("forkserver"),
                    initializer=worker_init,
                    initargs=(WORKER_NICENESS, logging.getLogger().getEffectiveLevel(), _log_format()))
            else:
                self._executor = ThreadPoolExecutor(self.workers, thread_name_prefix="planning",
                                                    initializer=restore_normal_priority)
        return self._executor

    def start(self) -> asyncio.Future:
        """Start every worker now (from the calling thread) and warm it up (imports, one tiny
        GART) in the background; await the future returned to wait until they are ready."""
        loop = asyncio.get_running_loop()
        t0 = time.perf_counter()
        warming = [loop.run_in_executor(self.executor, warm_up) for _ in range(self.workers)]

        async def ready() -> None:
            spent = await asyncio.gather(*warming)
            log.info("planning workers (%d %s) ready in %.2f s (warm-up %s s)", self.workers,
                     "processes" if self.kind == "process" else "threads", time.perf_counter() - t0,
                     ", ".join(f"{s:.2f}" for s in spent))
        return asyncio.ensure_future(ready())

    async def run(self, fn, /, *args, **kwargs):
        """Run ``fn(*args, **kwargs)`` in a worker and return its result (see the module
        docstring for what is adopted back from a worker process)."""
        loop = asyncio.get_running_loop()
        if self.kind == "thread":
            return await loop.run_in_executor(self.executor, functools.partial(fn, *args, **kwargs))
        owner = getattr(fn, "__self__", None)
        if owner is not None and hasattr(owner, "__dict__"):
            sent = dict(vars(owner))
            result, changed = await loop.run_in_executor(
                self.executor, call_method, owner, fn.__name__, args, kwargs)
            adopt_changes(owner, sent, changed)
            return result
        result, states = await loop.run_in_executor(self.executor, call_function, fn, args, kwargs)
        for key, state in states.items():
            (args[key] if isinstance(key, int) else kwargs[key]).bit_generator.state = state
        return result

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


class AlternativesGate:
    """The threat reactor's ``in_worker``: an M-GART refresh that could not change anything is
    not run.

    With no threat held, the alternatives depend only on the leg (world, goal) and the active
    reference; the periodic refresh (every ``flight.alternatives_period_s``) would search the
    same static world again and again. A ``compute_alternatives`` call with no threats, on the
    same world, goal and active reference as the last one that ran with no threats, returns
    ``[]`` at once, which the reactor takes as "keep the previous alternatives". Every other
    call (decisions, a refresh with threats held, a new leg or reference) goes to ``run``.

    Parameters
    ----------
    run : coroutine function (fn, *args, **kwargs)
        Runs ``fn`` in a planning worker (the daemon's ``in_worker``).
    """

    def __init__(self, run) -> None:
        self.run = run
        self._last_key: tuple | None = None
        self.skipped = 0

    async def __call__(self, fn, /, *args, **kwargs):
        manager = getattr(fn, "__self__", None)
        if manager is None or getattr(fn, "__name__", "") != "compute_alternatives":
            return await self.run(fn, *args, **kwargs)
        threats = args[0] if args else kwargs.get("threats")
        key = None if threats else (id(manager.world), manager.goal_ned_m.tobytes(), manager.active_path_id)
        if key is not None and key == self._last_key:
            self.skipped += 1
            return []
        self._last_key = None
        result = await self.run(fn, *args, **kwargs)
        self._last_key = key if result else None
        return result
