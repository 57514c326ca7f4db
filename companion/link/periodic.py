"""The real-time driver of a schedule: a periodic tick on absolute monotonic deadlines.

``PeriodicDriver`` calls ``tick(now_s)`` once per period on deadlines ``t_k = t_0 + k * period``
of the monotonic clock (no drift; a late wake-up does not delay the next one; deadlines missed
by more than a period are skipped and counted, never run in a burst). On Linux the deadlines
are a kernel periodic timer the loop waits on (``companion.link.timerfd``: asyncio's own timers
wake up to 1 ms late, rounded to epoll's milliseconds); elsewhere the loop's timer, with an
optional spin before each deadline.

This is the real-time clock of the flight executor's schedule (``companion.flight.schedule``):
``companion run`` drives the executor's table with it at the setpoint rate, and a bare
``SetpointStreamer`` streams with one of its own. The asyncio edge: the schedule and its tasks
know nothing of it.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable

from companion.link.timerfd import PeriodicTimer

__all__ = ["PeriodicDriver"]

log = logging.getLogger(__name__)


class PeriodicDriver:
    """Calls ``tick(now_s)`` every ``1 / rate_hz`` s of the monotonic clock (see the module
    docstring).

    Parameters
    ----------
    rate_hz : float
        In (0, 1000].
    tick : callable (now_s) -> None
        The period's work, on the loop; quick (it delays the next period otherwise). An
        exception is logged (the first and every 500th) and the driver goes on.
    spin_s : float
        The last ``spin_s`` before a deadline are waited by yielding to the loop instead of a
        timed sleep (the loop's timer resolution is ~1 ms); 0 uses the kernel timer when there
        is one.
    """

    def __init__(self, rate_hz: float, tick: Callable[[float], None], *, spin_s: float = 0.0) -> None:
        if not (math.isfinite(rate_hz) and 0.0 < rate_hz <= 1000.0):
            raise ValueError(f"rate_hz must be in (0, 1000], got {rate_hz}")
        if not (0.0 <= spin_s < 1.0 / rate_hz):
            raise ValueError(f"spin_s must be in [0, period), got {spin_s}")
        self.period_s = 1.0 / rate_hz
        self.tick = tick
        self._spin_s = spin_s
        self._task: asyncio.Task | None = None
        self._waiters: list[tuple[Callable[[], bool], asyncio.Future]] = []
        self.missed = 0
        self.failures = 0

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    def start(self) -> asyncio.Task:
        """Start ticking on the running loop; returns the task."""
        if not self.running:
            self._task = asyncio.get_running_loop().create_task(self.run(), name="periodic-driver")
        return self._task

    async def stop(self) -> None:
        """Stop ticking (idempotent); whoever waits in ``until`` is woken."""
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None
        for _, future in self._waiters:
            if not future.done():
                future.set_result(False)
        self._waiters.clear()

    async def until(self, done: Callable[[], bool]) -> bool:
        """Wait until ``done()`` is true after a tick (True), or the driver stopped (False)."""
        if done():
            return True
        if not self.running:
            return False
        future = asyncio.get_running_loop().create_future()
        self._waiters.append((done, future))
        return await future

    def _run_tick(self, now_s: float) -> None:
        try:
            self.tick(now_s)
        except Exception:  # noqa: BLE001 - the period must go on
            self.failures += 1
            if self.failures == 1 or self.failures % 500 == 0:
                log.exception("periodic tick failed (%d so far)", self.failures)
        if self._waiters:
            still = []
            for done, future in self._waiters:
                if future.done():
                    continue
                if done():
                    future.set_result(True)
                else:
                    still.append((done, future))
            self._waiters = still

    async def run(self) -> None:
        """Tick until cancelled: on a kernel periodic timer when there is one and ``spin_s`` is
        0, else on the loop's timer."""
        t0 = time.monotonic()
        timer = PeriodicTimer.open(t0 + self.period_s, self.period_s) if self._spin_s == 0 else None
        if timer is None:
            await self._run_on_loop_timer(t0)
            return
        loop = asyncio.get_running_loop()

        def on_expiry() -> None:
            periods = timer.expirations()
            if periods:
                self.missed += periods - 1  # deadlines already passed are skipped, never bursts
                self._run_tick(time.monotonic())

        self._run_tick(t0)
        loop.add_reader(timer.fileno(), on_expiry)
        try:
            await loop.create_future()  # until cancelled
        finally:
            loop.remove_reader(timer.fileno())
            timer.close()

    async def _run_on_loop_timer(self, t0: float) -> None:
        k = 0
        while True:
            await self._wait_until(t0 + k * self.period_s)
            self._run_tick(time.monotonic())
            k += 1
            behind = int((time.monotonic() - (t0 + k * self.period_s)) // self.period_s)
            if behind > 0:  # skip deadlines missed by more than a period
                self.missed += behind
                k += behind

    async def _wait_until(self, deadline_s: float) -> None:
        remaining = deadline_s - time.monotonic() - self._spin_s
        if remaining > 0:
            await asyncio.sleep(remaining)
        while time.monotonic() < deadline_s:
            await asyncio.sleep(0)
