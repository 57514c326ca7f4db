"""The 50 Hz GUIDED setpoint stream (DESIGN.md sections 1 and 5; paper section 2.2).

The vehicle's LQI tracks position/velocity/acceleration/yaw references; the companion must
deliver them at a steady rate whatever else it is doing (planning, smoothing, threat handling).
``SetpointStreamer`` is an asyncio task that sends one setpoint per period on absolute
deadlines of the monotonic clock (``t_k = t_0 + k * period``: no drift, a late wake-up does not
delay the next one; a deadline missed by more than a period is skipped, never sent in a burst).
On Linux the deadlines are a kernel periodic timer the loop waits on (``companion.link.timerfd``:
asyncio's own timers wake up to 1 ms late, rounded to epoll's milliseconds).

The setpoint comes from a callable ``setpoint_at(t_monotonic_s) -> Setpoint`` that the daemon
replaces atomically with ``set_source`` (a single attribute store) when a new trajectory is
ready, so a splice takes effect at the next tick. If the callable raises, the previous setpoint
is repeated and the error logged (once per source).

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
from typing import Callable, NamedTuple

import numpy as np

from companion.link.timerfd import PeriodicTimer

log = logging.getLogger(__name__)


#: The interpreter's switch interval while the stream runs (s; ``raise_stream_priority``).
STREAM_SWITCH_INTERVAL_S = 0.0005
#: ``SetpointStreamer.sleep`` wakes on the loop's timer this long after its delay if no send
#: woke it (s).
SLEEP_BACKSTOP_S = 1.0
#: The stream's housekeeping (the source's work ahead, the after-tick callbacks, the sleepers)
#: follows a send about this often (s), not every send: the flight's periodic work (the phase
#: machine, the monitor, the record: 10 Hz) needs no more, and each turn costs the loop.
HOUSEKEEPING_PERIOD_S = 0.1


def _wake(future: asyncio.Future) -> None:
    if not future.done():
        future.set_result(None)


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
        log.warning("cannot raise the setpoint stream's scheduling priority; jitter will "
                    "follow the machine's load")
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


class Setpoint(NamedTuple):
    """One GUIDED setpoint (None = not commanded; masked out in type_mask).

    Attributes
    ----------
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : ndarray (3,), sequence of 3 floats, or None
    yaw_rad : float or None
    yaw_rate_rad_s : float or None
        With ``yaw_rad``: the heading's rate of change, a feed-forward for the yaw loop.
    """

    pos_ned_m: np.ndarray | None
    vel_ned_m_s: np.ndarray | None = None
    acc_ned_m_s2: np.ndarray | None = None
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None


SetpointSource = Callable[[float], Setpoint]
SetpointSender = Callable[..., None]


def hold_position(pos_ned_m, yaw_rad: float | None = None) -> SetpointSource:
    """A source that holds ``pos_ned_m`` with zero velocity and acceleration (a hover)."""
    pos = np.asarray(pos_ned_m, dtype=np.float64).reshape(3).copy()
    zero = np.zeros(3)

    def setpoint_at(t_monotonic_s: float) -> Setpoint:
        return Setpoint(pos, zero, zero, yaw_rad)

    return setpoint_at


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
    return JitterStats(int(t.size), nominal_period_s * 1e3, float(periods.mean() * 1e3),
                       float(np.percentile(dev_ms, 50)), float(np.percentile(dev_ms, 99)),
                       float(dev_ms.max()), missed)


class SetpointStreamer:
    """Send setpoints at a fixed rate on absolute monotonic deadlines.

    Parameters
    ----------
    send : callable
        ``send(pos_ned_m=..., vel_ned_m_s=..., acc_ned_m_s2=..., yaw_rad=...)``, non-blocking,
        e.g. ``VehicleLink.send_setpoint``.
    source : callable, optional
        Initial ``setpoint_at(t_monotonic_s) -> Setpoint``; nothing is sent until one is set.
    rate_hz : float
        Stream rate (default 50 Hz).
    on_sent : callable, optional
        ``on_sent(t_monotonic_s, setpoint)`` after each send (flight record); must be quick.
    spin_s : float
        The last ``spin_s`` before a deadline are waited by yielding to the loop in a tight
        loop instead of a timed sleep (the loop's timer resolution is ~1 ms). 0 disables.
    max_records : int
        Send times kept for ``stats()`` (a ring; default one hour at 50 Hz).

    Examples
    --------
    >>> streamer = SetpointStreamer(link.send_setpoint, hold_position([0, 0, -10]))  # doctest: +SKIP
    >>> task = streamer.start()
    >>> streamer.set_source(lambda t: trajectory_setpoint(t - t_start))   # atomic swap
    >>> await streamer.stop(); streamer.stats().p99_ms
    """

    def __init__(self, send: SetpointSender, source: SetpointSource | None = None, *,
                 rate_hz: float = 50.0,
                 on_sent: Callable[[float, Setpoint], None] | None = None,
                 spin_s: float = 0.0, max_records: int = 180_000) -> None:
        if not (math.isfinite(rate_hz) and 0.0 < rate_hz <= 1000.0):
            raise ValueError(f"rate_hz must be in (0, 1000], got {rate_hz}")
        if not (0.0 <= spin_s < 1.0 / rate_hz):
            raise ValueError(f"spin_s must be in [0, period), got {spin_s}")
        self._send = send
        self._source = source
        self._prepare: Callable[[], None] | None = None
        self._source_failed = False
        self.period_s = 1.0 / rate_hz
        self._housekeeping_ticks = max(1, int(HOUSEKEEPING_PERIOD_S / self.period_s + 1e-9))
        self._ticks = 0
        self._on_sent = on_sent
        self._spin_s = spin_s
        self._max_records = int(max_records)
        self._times = array("d")
        self._last: Setpoint | None = None
        self._task: asyncio.Task | None = None
        self.missed = 0
        self.sent = 0
        self.send_errors = 0
        self._tick_callbacks: list[Callable[[], None]] = []
        #: Called right after every scheduled send (e.g. the link taking the telemetry the gate
        #: read: ``VehicleLink.batch_reads``); each must be quick and must not raise.
        self.tick_hooks: list[Callable[[], None]] = []
        self._sleepers: list[tuple[float, asyncio.Future]] = []   # (wake at, future) of sleep()
        self._first_wake_s = math.inf                               # the earliest of them

    # ---------------------------------------------------------------- control

    def set_source(self, source: SetpointSource | None,
                   prepare: Callable[[], None] | None = None) -> None:
        """Replace the setpoint source; effective at the next tick (None pauses sending).

        ``prepare()``, when given, is called in the stream's housekeeping (right after a send,
        every ``HOUSEKEEPING_PERIOD_S``): work the source
        can do ahead (e.g. ``ActiveReference.prepare``) then never delays a send."""
        self._source = source
        self._prepare = prepare
        self._source_failed = False

    @property
    def source(self) -> SetpointSource | None:
        return self._source

    def start(self) -> asyncio.Task:
        """Start streaming on the running loop; returns the task."""
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self.run(), name="setpoints")
        return self._task

    async def stop(self) -> None:
        """Stop streaming (idempotent)."""
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None
        self._run_tick_callbacks()
        self._wake_sleepers(math.inf)

    def call_after_next_tick(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` on the loop in the stream's next housekeeping, right after a
        scheduled send (at most ``HOUSEKEEPING_PERIOD_S`` away; soon when not
        streaming), in the same wake-up as the send: no task, no future, warm caches."""
        if self.running:
            self._tick_callbacks.append(callback)
        else:
            asyncio.get_running_loop().call_soon(callback)

    async def sleep(self, delay_s: float) -> None:
        """Sleep about ``delay_s``, waking in the first housekeeping that follows (while
        streaming: the periodic work of the flight then shares the stream's wake-up of the
        process instead of adding its own); ``asyncio.sleep`` when not streaming."""
        if not self.running:
            await asyncio.sleep(delay_s)
            return
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        wake_s = time.monotonic() + delay_s - 0.5 * self.housekeeping_period_s
        self._sleepers.append((wake_s, future))
        self._first_wake_s = min(self._first_wake_s, wake_s)
        # a stream that stopped ticking without stop() must not hold the sleeper for ever
        backstop = loop.call_later(delay_s + SLEEP_BACKSTOP_S, _wake, future)
        try:
            await future
        finally:
            backstop.cancel()
            if not future.done():
                future.cancel()

    def _wake_sleepers(self, now_s: float) -> None:
        if now_s < self._first_wake_s:
            return
        due = [f for t, f in self._sleepers if t <= now_s]
        if due:
            self._sleepers = [(t, f) for t, f in self._sleepers if t > now_s and not f.done()]
            self._first_wake_s = min((t for t, _ in self._sleepers), default=math.inf)
            for future in due:
                if not future.done():
                    future.set_result(None)

    def _after_tick(self) -> None:
        """Right after a scheduled send: the tick hooks; every ``HOUSEKEEPING_PERIOD_S``, also
        the source's work ahead, the after-tick callbacks and the sleepers that are due."""
        for hook in self.tick_hooks:
            hook()
        self._ticks += 1
        if self._ticks % self._housekeeping_ticks:
            return
        if self._prepare is not None:
            try:
                self._prepare()
            except Exception:  # noqa: BLE001 - the send path evaluates again if needed
                log.exception("setpoint source's prepare failed")
                self._prepare = None
        self._run_tick_callbacks()
        self._wake_sleepers(time.monotonic())

    def _run_tick_callbacks(self) -> None:
        callbacks, self._tick_callbacks = self._tick_callbacks, []
        for callback in callbacks:
            try:
                callback()
            except Exception:  # noqa: BLE001 - the stream goes on
                log.exception("after-tick callback %r failed", callback)

    @property
    def housekeeping_period_s(self) -> float:
        """How often the housekeeping follows a send (s; ``HOUSEKEEPING_PERIOD_S``, whole ticks)."""
        return self._housekeeping_ticks * self.period_s

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    # ---------------------------------------------------------------- loop

    async def run(self) -> None:
        """Stream until cancelled: on a kernel periodic timer (``companion.link.timerfd``,
        Linux) when there is one and ``spin_s`` is 0, else on the loop's timer."""
        t0 = time.monotonic()
        timer = PeriodicTimer.open(t0 + self.period_s, self.period_s) if self._spin_s == 0 else None
        if timer is None:
            await self._run_on_loop_timer(t0)
            return
        loop = asyncio.get_running_loop()

        def on_expiry() -> None:
            periods = timer.expirations()
            if periods:
                self.missed += periods - 1        # deadlines already passed are skipped, never bursts
                self.tick(time.monotonic())
                self._after_tick()

        self.tick(t0)
        loop.add_reader(timer.fileno(), on_expiry)
        try:
            await loop.create_future()            # until cancelled
        finally:
            loop.remove_reader(timer.fileno())
            timer.close()

    async def _run_on_loop_timer(self, t0: float) -> None:
        k = 0
        while True:
            deadline = t0 + k * self.period_s
            await self.wait_until(deadline)
            now = time.monotonic()
            self.tick(now)
            self._after_tick()
            k += 1
            # skip deadlines already missed by more than one period (no bursts)
            behind = int((time.monotonic() - (t0 + k * self.period_s)) // self.period_s)
            if behind > 0:
                self.missed += behind
                k += behind

    async def wait_until(self, deadline_s: float) -> None:
        """Sleep to ``deadline_s - spin_s`` on the loop timer, then yield until the deadline."""
        remaining = deadline_s - time.monotonic() - self._spin_s
        if remaining > 0:
            await asyncio.sleep(remaining)
        while time.monotonic() < deadline_s:
            await asyncio.sleep(0)

    def send_now(self) -> None:
        """Send the current source's setpoint at once, outside the schedule (a new trajectory
        reaches the vehicle without waiting for the next tick; the jitter statistics count only
        the scheduled sends)."""
        if self.running:
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
            self._send(pos_ned_m=setpoint.pos_ned_m, vel_ned_m_s=setpoint.vel_ned_m_s,
                       acc_ned_m_s2=setpoint.acc_ned_m_s2, yaw_rad=setpoint.yaw_rad,
                       yaw_rate_rad_s=setpoint.yaw_rate_rad_s)
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
        if not isinstance(setpoint, Setpoint):
            setpoint = Setpoint(*setpoint)
        return setpoint

    # ---------------------------------------------------------------- statistics

    @property
    def send_times_s(self) -> np.ndarray:
        """Monotonic send times kept so far, shape (K,)."""
        return np.frombuffer(self._times, dtype=np.float64).copy()

    def stats(self) -> JitterStats:
        """Period jitter of the sends so far."""
        return jitter_stats(self.send_times_s, self.period_s, self.missed)
