"""The flight executor's jobs in real time: run in the planning worker processes, their results
handed back on the event loop (the ``Jobs`` port of ``companion.flight.ports``).

``WorkerJobs.submit(name, fn, args, done, failed)`` sends ``fn(*args)`` to the daemon's warm
planning workers (``companion.workers.PlanningWorkers``) and calls ``done(result)`` or
``failed(error)`` on the loop when it is over, so the executor's state is only ever touched from
the loop's thread. ``fn`` and its arguments are values (module-level functions, frozen
dataclasses): nothing is diffed or adopted back.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from concurrent.futures import Future

from companion.workers import PlanningWorkers

__all__ = ["WorkerJobs"]

log = logging.getLogger(__name__)


class WorkerJobs:
    """Jobs in the planning workers, results on ``loop`` (see the module docstring).

    Parameters
    ----------
    workers : PlanningWorkers
    loop : asyncio.AbstractEventLoop
        The executor's loop.
    """

    def __init__(self, workers: PlanningWorkers, loop: asyncio.AbstractEventLoop) -> None:
        self.workers = workers
        self.loop = loop
        self.wall_s: dict[str, list[float]] = {}
        self.outstanding = 0

    def submit(
        self,
        name: str,
        fn: Callable,
        args: tuple,
        done: Callable[[object], None],
        failed: Callable[[BaseException], None],
    ) -> None:
        t0 = time.perf_counter()
        self.outstanding += 1
        try:
            future = self.workers.submit(fn, *args)
        except Exception as exc:  # noqa: BLE001 - e.g. the pool is shutting down
            self.outstanding -= 1
            failed(exc)
            return

        def on_loop(f: Future) -> None:
            self.outstanding -= 1
            self.wall_s.setdefault(name, []).append(time.perf_counter() - t0)
            if f.cancelled():
                log.info("job %s cancelled", name)
                return
            error = f.exception()
            if error is not None:
                failed(error)
            else:
                done(f.result())

        def handed_over(f: Future) -> None:
            if not self.loop.is_closed():
                self.loop.call_soon_threadsafe(on_loop, f)

        future.add_done_callback(handed_over)
