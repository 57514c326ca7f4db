"""Named tasks at declared rates: the flight's schedule, after ArduPilot's AP_Scheduler.

ArduCopter declares its periodic work as one table: each row a function, a rate in Hz and a
time budget; ``scheduler.run()`` runs, in each main-loop tick, the tasks whose time has come,
and counts the overruns per task. :class:`Scheduler` is that table for the flight executor
(``companion.flight.executor``): whoever drives it (the daemon's 50 Hz setpoint timer in real
time, the virtual clock of a fast-time flight) calls :meth:`Scheduler.tick` with the clock's
time, and every task whose period has elapsed runs, in table order. Anyone can read what runs,
how often and what it cost (:meth:`Scheduler.report`); no task hides inside another's callback.

Pure: no asyncio, no I/O. The clock is the caller's; only the tasks' own durations are measured
(``time.perf_counter``) to count overruns of their budgets.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from companion.errors import CompanionError

__all__ = ["Task", "TaskStats", "Scheduler", "ScheduleError"]

log = logging.getLogger(__name__)


class ScheduleError(CompanionError, ValueError):
    """A malformed schedule (naming the task and the field)."""


@dataclass(frozen=True)
class Task:
    """One row of the schedule.

    Attributes
    ----------
    name : str
        Unique, short (``setpoints``, ``phase``, ``monitor`` ...).
    rate_hz : float
        How often it runs, in the driver's clock (> 0; at most the driver's tick rate).
    run : callable (now_s) -> None
        The work: quick and non-blocking (slow work is submitted as a job).
    budget_ms : float
        Expected longest run (ms of wall clock); a longer run counts as an overrun.
    """

    name: str
    rate_hz: float
    run: Callable[[float], None]
    budget_ms: float

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz


@dataclass
class TaskStats:
    """What one task cost so far (wall-clock ms)."""

    runs: int = 0
    overruns: int = 0
    failures: int = 0
    total_ms: float = 0.0
    max_ms: float = 0.0

    def add(self, spent_ms: float, budget_ms: float) -> None:
        self.runs += 1
        self.total_ms += spent_ms
        self.max_ms = max(self.max_ms, spent_ms)
        if spent_ms > budget_ms:
            self.overruns += 1


#: Times closer than this are the same time (s): a task at the driver's own rate runs at every
#: tick whatever the rounding of ``k * period``.
SAME_TIME_S = 1e-9


@dataclass
class _Slot:
    """A task's times are ``anchor_s + n * period`` from its first run (no drift)."""

    task: Task
    anchor_s: float = math.nan
    due_s: float = -math.inf
    stats: TaskStats = field(default_factory=TaskStats)

    def advance(self, now_s: float, slack_s: float) -> None:
        """The next time after a run at ``now_s``, up to ``slack_s`` early (times missed by a
        late tick are skipped)."""
        period = self.task.period_s
        if math.isnan(self.anchor_s):
            self.anchor_s = now_s
        n = math.floor((now_s + slack_s - self.anchor_s) / period + SAME_TIME_S) + 1
        self.due_s = self.anchor_s + n * period


class Scheduler:
    """Runs the tasks of a table at their rates (see the module docstring).

    Parameters
    ----------
    tasks : sequence of Task
        In the order they run within one tick (the setpoint first, as ArduCopter's fast loop).
    slack_s : float
        A task runs when the clock is within ``slack_s`` of its time (a driver whose ticks
        jitter, e.g. half its tick period; 0 for a virtual clock).
    timer : callable () -> float
        Measures the tasks' durations (s); default ``time.perf_counter``.

    Raises
    ------
    ScheduleError
        A duplicate name, or a rate or budget that is not a finite number > 0.
    """

    def __init__(
        self, tasks: Sequence[Task] = (), *, slack_s: float = 0.0, timer: Callable[[], float] = time.perf_counter
    ) -> None:
        if not (math.isfinite(slack_s) and slack_s >= 0.0):
            raise ScheduleError(f"slack_s must be a finite number >= 0, got {slack_s!r}")
        self._slots: dict[str, _Slot] = {}
        for task in tasks:
            self.add(task)
        self.slack_s = float(slack_s)
        self._timer = timer

    def add(self, task: Task) -> None:
        """Append ``task`` to the table (it runs at the next tick)."""
        if task.name in self._slots:
            raise ScheduleError(f"task {task.name!r}: the schedule has one already")
        for name in ("rate_hz", "budget_ms"):
            value = getattr(task, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ScheduleError(f"task {task.name!r}: {name} must be a finite number > 0, got {value!r}")
        self._slots[task.name] = _Slot(task)

    def remove(self, name: str) -> None:
        """Take the task ``name`` out of the table (no error if it is not there)."""
        self._slots.pop(name, None)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._slots)

    def tick(self, now_s: float) -> list[str]:
        """Run every task whose time has come at ``now_s``; returns their names in run order.

        A task's times are whole periods from its first run; it runs at most once per tick,
        and times missed by a late tick are skipped, never run in a burst.
        """
        ran = []
        for slot in list(self._slots.values()):
            if now_s < slot.due_s - self.slack_s - SAME_TIME_S:
                continue
            slot.advance(now_s, self.slack_s)
            self._run(slot, now_s)
            ran.append(slot.task.name)
        return ran

    def _run(self, slot: _Slot, now_s: float) -> None:
        t0 = self._timer()
        try:
            slot.task.run(now_s)
        except Exception:  # noqa: BLE001 - one failing task must not stop the flight
            slot.stats.failures += 1
            if slot.stats.failures == 1 or slot.stats.failures % 100 == 0:
                log.exception("task %s failed (%d so far)", slot.task.name, slot.stats.failures)
        slot.stats.add((self._timer() - t0) * 1e3, slot.task.budget_ms)

    def report(self) -> list[dict]:
        """The table with what each task cost: name, rate, budget, runs, overruns, failures,
        mean and max duration (ms)."""
        return [
            {
                "task": s.task.name,
                "rate_hz": s.task.rate_hz,
                "budget_ms": s.task.budget_ms,
                "runs": s.stats.runs,
                "overruns": s.stats.overruns,
                "failures": s.stats.failures,
                "mean_ms": round(s.stats.total_ms / s.stats.runs, 4) if s.stats.runs else 0.0,
                "max_ms": round(s.stats.max_ms, 4),
            }
            for s in self._slots.values()
        ]
