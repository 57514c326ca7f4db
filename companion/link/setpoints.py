"""The 50 Hz GUIDED setpoint stream (DESIGN.md sections 1 and 5; paper section 2.2).

The vehicle's LQI tracks position/velocity/acceleration/yaw references; the companion must
deliver them at a steady rate whatever else it is doing (planning, smoothing, threat handling).
``SetpointStreamer`` sends one setpoint per tick and keeps the send times (jitter). The ticks
come on absolute deadlines of the monotonic clock from a ``PeriodicDriver``
(``companion.link.periodic``: a kernel periodic timer on Linux): in ``companion run`` the
driver runs the flight executor's schedule, whose first task is the stream
(``companion.flight.executor``); a bare streamer can ``start`` a driver of its own.

The setpoint comes from a callable ``setpoint_at(t_monotonic_s) -> Setpoint`` (the daemon's
``ReferenceOwner.setpoint_at``, ``companion.flight.active``), so a new trajectory takes effect
at the next tick. If the callable raises, the previous setpoint is repeated and the error
logged (once per source).

What ``companion run`` does (``companion.daemon``): the event-loop thread that streams is given
priority with ``raise_stream_priority`` (SCHED_FIFO when allowed) before the link connects;
planning, threat decisions and M-GART refreshes run in two warm worker *processes*
(``companion.workers.PlanningWorkers``, started before the priority is raised and niced by
``planning_worker_init``), so they compete with the stream for a core, never for the GIL; a short
GIL switch interval hands the GIL back to the stream quickly from the process's own threads.
``docs/BENCHMARKS.md`` (``benchmarks/setpoint_jitter.py``) compares it with planning in threads.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import time
from array import array
from collections.abc import Callable

import numpy as np

from companion.flight.setpoint import Setpoint, SetpointSource, hold_position
from companion.link.periodic import PeriodicDriver

__all__ = [
    "JitterStats",
    "Setpoint",
    "SetpointStreamer",
    "hold_position",
    "jitter_stats",
    "normal_priority",
    "planning_worker_init",
    "raise_stream_priority",
    "restore_normal_priority",
]

log = logging.getLogger(__name__)


#: The interpreter's switch interval while the stream runs (s; ``raise_stream_priority``).
STREAM_SWITCH_INTERVAL_S = 0.0005


def raise_stream_priority(fifo_priority: int = 10, nice_increment: int = -5) -> str:
    """Give the calling thread (the event loop streaming setpoints) scheduling priority.

    Tries ``SCHED_FIFO`` at ``fifo_priority`` (Linux, needs root or CAP_SYS_NICE), else lowers
    the process niceness by ``nice_increment``; logs and carries on if neither is allowed.
    Call it in the event-loop thread *before* ``VehicleLink.connect``: threads created later
    (MAVSDK's I/O and callback threads, executor threads) inherit the policy, so a callback
    holding the GIL is not preempted by other processes while the stream waits for it. Safe
    for the stream (about 0.1 ms of work per 20 ms period); never call it from a thread that
    runs long computations: start planning threads with ``restore_normal_priority`` (as the
    daemon does) or planning processes with ``planning_worker_init``.

    It also shortens the interpreter's switch interval to ``STREAM_SWITCH_INTERVAL_S``: a
    thread waiting for the GIL asks its holder to drop it after that long (Python's default is
    5 ms), so the stream waits at most about that for a callback of another thread (the gate,
    MAVSDK, zenoh, the planning pool's result thread) that holds the GIL when its timer fires.

    Returns
    -------
    str
        ``"fifo"``, ``"nice"`` or ``"normal"``: what was obtained.
    """
    import os
    import sys

    sys.setswitchinterval(STREAM_SWITCH_INTERVAL_S)

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(fifo_priority)))
        log.info("setpoint stream thread runs SCHED_FIFO priority %d", fifo_priority)
        return "fifo"
    except (AttributeError, OSError, PermissionError):
        pass
    try:
        os.nice(int(nice_increment))
        log.info("setpoint stream process niceness lowered by %d", -nice_increment)
        return "nice"
    except (AttributeError, OSError, PermissionError):
        log.warning("cannot raise the setpoint stream's scheduling priority; jitter will follow the machine's load")
        return "normal"


def planning_worker_init(niceness: int = 10) -> None:
    """``ProcessPoolExecutor`` initializer for planning workers: normal policy, then niced.

    A forked worker inherits SCHED_FIFO from a parent that called ``raise_stream_priority``;
    planning must never run at real-time priority.
    """
    import os

    restore_normal_priority()
    try:
        os.nice(int(niceness))
    except OSError:
        pass


def restore_normal_priority() -> None:
    """Undo ``raise_stream_priority``'s SCHED_FIFO for the calling thread (SCHED_OTHER)."""
    import os

    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError, PermissionError):
        pass


@contextlib.contextmanager
def normal_priority():
    """Run the block at the normal policy, then give the calling thread its own back: threads
    started inside (a Foxglove server's, zenoh's) do not inherit the stream's SCHED_FIFO."""
    import os

    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    except (AttributeError, OSError):
        yield
        return
    if policy != getattr(os, "SCHED_FIFO", None):
        yield
        return
    restore_normal_priority()
    try:
        yield
    finally:
        try:
            os.sched_setscheduler(0, policy, param)
        except (OSError, PermissionError):
            log.warning("could not give the setpoint stream its SCHED_FIFO priority back")


SetpointSender = Callable[..., None]


@dataclasses.dataclass(frozen=True)
class JitterStats:
    """Period jitter of a setpoint stream: statistics of ``|period - nominal|`` in ms."""

    count: int
    nominal_period_ms: float
    mean_period_ms: float
    p50_ms: float
    p99_ms: float
    max_ms: float
    missed: int

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def jitter_stats(send_times_s, nominal_period_s: float, missed: int = 0) -> JitterStats:
    """Jitter of send times.

    Parameters
    ----------
    send_times_s : array_like, shape (K,)
        Monotonic send times in seconds, increasing.
    nominal_period_s : float

    Returns
    -------
    JitterStats
        NaN statistics when fewer than 2 sends.
    """
    t = np.asarray(send_times_s, dtype=np.float64)
    if t.size < 2:
        nan = math.nan
        return JitterStats(int(t.size), nominal_period_s * 1e3, nan, nan, nan, nan, missed)
    periods = np.diff(t)
    dev_ms = np.abs(periods - nominal_period_s) * 1e3
    return JitterStats(
        int(t.size),
        nominal_period_s * 1e3,
        float(periods.mean() * 1e3),
        float(np.percentile(dev_ms, 50)),
        float(np.percentile(dev_ms, 99)),
        float(dev_ms.max()),
        missed,
    )


class SetpointStreamer:
    """Send the setpoints of a source: one per ``tick``, with the send times kept for jitter.

    It only streams: who ticks it is the flight executor's schedule (its ``setpoints`` task,
    driven by the daemon's ``PeriodicDriver``), or, after ``start``, a driver of its own at
    ``rate_hz`` (a stream with nothing else to do, e.g. a test).

    Parameters
    ----------
    send : callable
        ``send(pos_ned_m=..., vel_ned_m_s=..., acc_ned_m_s2=..., yaw_rad=..., yaw_rate_rad_s=...)``,
        non-blocking, e.g. ``VehicleLink.direct.send_setpoint``.
    source : callable, optional
        ``setpoint_at(t_monotonic_s) -> Setpoint or None``; nothing is sent while it is None
        or returns None.
    rate_hz : float
        Nominal rate (default 50 Hz): the jitter's reference, and ``start``'s driver's.
    on_sent : callable, optional
        ``on_sent(t_monotonic_s, setpoint)`` after each send (flight record); must be quick.
    spin_s : float
        ``start``'s driver's spin (``PeriodicDriver``).
    max_records : int
        Send times kept for ``stats()`` (a ring; default one hour at 50 Hz).

    Examples
    --------
    >>> streamer = SetpointStreamer(link.direct.send_setpoint, hold_position([0, 0, -10]))  # doctest: +SKIP
    >>> task = streamer.start()
    >>> streamer.set_source(lambda t: trajectory_setpoint(t - t_start))   # atomic swap
    >>> await streamer.stop(); streamer.stats().p99_ms
    """

    def __init__(
        self,
        send: SetpointSender,
        source: SetpointSource | None = None,
        *,
        rate_hz: float = 50.0,
        on_sent: Callable[[float, Setpoint], None] | None = None,
        spin_s: float = 0.0,
        max_records: int = 180_000,
    ) -> None:
        if not (math.isfinite(rate_hz) and 0.0 < rate_hz <= 1000.0):
            raise ValueError(f"rate_hz must be in (0, 1000], got {rate_hz}")
        if not (0.0 <= spin_s < 1.0 / rate_hz):
            raise ValueError(f"spin_s must be in [0, period), got {spin_s}")
        self._send = send
        self._source = source
        self._source_failed = False
        self.period_s = 1.0 / rate_hz
        self._on_sent = on_sent
        self._spin_s = spin_s
        self._max_records = int(max_records)
        self._times = array("d")
        self._last: Setpoint | None = None
        self._driver: PeriodicDriver | None = None
        self.sent = 0
        self.send_errors = 0
        self.missed = 0  # periods its driver skipped (``start``'s, or the caller's)

    def set_source(self, source: SetpointSource | None) -> None:
        """Replace the setpoint source; effective at the next tick (None pauses sending)."""
        self._source = source
        self._source_failed = False

    @property
    def source(self) -> SetpointSource | None:
        return self._source

    # ---------------------------------------------------------------- its own driver
    def start(self) -> asyncio.Task:
        """Stream at ``rate_hz`` on a driver of its own (the running loop); returns its task."""
        if self._driver is None:
            self._driver = PeriodicDriver(1.0 / self.period_s, self.tick, spin_s=self._spin_s)
        return self._driver.start()

    async def stop(self) -> None:
        """Stop its own driver (idempotent)."""
        if self._driver is not None:
            await self._driver.stop()
            self.missed = self._driver.missed

    @property
    def running(self) -> bool:
        return self._driver is not None and self._driver.running

    # ---------------------------------------------------------------- sending
    def send_now(self) -> None:
        """Send the current source's setpoint at once, outside the schedule (a new trajectory
        reaches the vehicle without waiting for the next tick; the jitter statistics count only
        the scheduled sends)."""
        self.tick(time.monotonic(), scheduled=False)

    def tick(self, now_s: float, scheduled: bool = True) -> None:
        """Evaluate the source at ``now_s`` and send (one period's work)."""
        source = self._source
        if source is None:
            return
        setpoint = self._evaluate(source, now_s)
        if setpoint is None:
            return
        try:
            self._send(
                pos_ned_m=setpoint.pos_ned_m,
                vel_ned_m_s=setpoint.vel_ned_m_s,
                acc_ned_m_s2=setpoint.acc_ned_m_s2,
                yaw_rad=setpoint.yaw_rad,
                yaw_rate_rad_s=setpoint.yaw_rate_rad_s,
            )
        except Exception:  # noqa: BLE001 - the stream must go on
            self.send_errors += 1
            if self.send_errors == 1 or self.send_errors % 500 == 0:
                log.exception("setpoint send failed (%d so far)", self.send_errors)
            return
        self._last = setpoint
        self.sent += 1
        if scheduled:
            if len(self._times) >= self._max_records:
                del self._times[: self._max_records // 10]
            self._times.append(now_s)
        if self._on_sent is not None:
            self._on_sent(now_s, setpoint)

    def _evaluate(self, source: SetpointSource, now_s: float) -> Setpoint | None:
        try:
            setpoint = source(now_s)
        except Exception:  # noqa: BLE001 - repeat the last setpoint
            if not self._source_failed:
                log.exception("setpoint source failed; repeating the last setpoint")
                self._source_failed = True
            return self._last
        if setpoint is not None and not isinstance(setpoint, Setpoint):
            setpoint = Setpoint(*setpoint)
        return setpoint

    # ---------------------------------------------------------------- statistics

    @property
    def send_times_s(self) -> np.ndarray:
        """Monotonic send times kept so far, shape (K,)."""
        return np.frombuffer(self._times, dtype=np.float64).copy()

    def stats(self) -> JitterStats:
        """Period jitter of the sends so far (``missed``: the periods its driver skipped)."""
        return jitter_stats(self.send_times_s, self.period_s, self.missed)
