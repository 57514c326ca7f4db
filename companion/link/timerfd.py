"""A periodic kernel timer the event loop can wait on: Linux ``timerfd`` through ctypes.

asyncio's own timers wake through ``epoll_wait``, whose timeout is a whole number of
milliseconds (CPython rounds it up): a 50 Hz stream on ``asyncio.sleep`` wakes 0 to 1 ms late,
every period. A ``timerfd`` armed with an absolute CLOCK_MONOTONIC deadline and a period is a
file descriptor that becomes readable at each expiry with the kernel's high-resolution timer
(tens of microseconds of latency); ``loop.add_reader`` wakes the loop on it. CLOCK_MONOTONIC is
the clock of ``time.monotonic`` on Linux. Python 3.13 has ``os.timerfd_create``; this module
calls libc directly so that 3.11 has it too. Elsewhere ``PeriodicTimer.open`` returns None and
the caller sleeps on the loop's timer.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import math
import os
import sys

log = logging.getLogger(__name__)

__all__ = ["PeriodicTimer"]

CLOCK_MONOTONIC = 1
TFD_NONBLOCK = os.O_NONBLOCK
TFD_CLOEXEC = getattr(os, "O_CLOEXEC", 0o2000000)
TFD_TIMER_ABSTIME = 1


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]


def _timespec(seconds: float) -> _Timespec:
    whole = math.floor(seconds)
    return _Timespec(int(whole), int(round((seconds - whole) * 1e9)) % 1_000_000_000)


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        libc.timerfd_create, libc.timerfd_settime  # noqa: B018 - both must exist
    except (OSError, AttributeError):
        return None
    return libc


class PeriodicTimer:
    """A ``timerfd`` that expires at ``first_s`` (``time.monotonic`` seconds) and every
    ``period_s`` after it; ``fileno()`` for ``loop.add_reader``, ``expirations()`` to read it.

    Use ``PeriodicTimer.open``, which returns None where timerfd is not available.
    """

    def __init__(self, fd: int, period_s: float) -> None:
        self.fd = fd
        self.period_s = period_s

    @classmethod
    def open(cls, first_s: float, period_s: float) -> PeriodicTimer | None:
        libc = _libc()
        if libc is None:
            return None
        fd = libc.timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
        if fd < 0:
            log.info(
                "timerfd_create failed (%s): the stream sleeps on the loop's timer", os.strerror(ctypes.get_errno())
            )
            return None
        spec = _Itimerspec(_timespec(period_s), _timespec(max(first_s, 1e-9)))
        if libc.timerfd_settime(fd, TFD_TIMER_ABSTIME, ctypes.byref(spec), None) != 0:
            log.info(
                "timerfd_settime failed (%s): the stream sleeps on the loop's timer", os.strerror(ctypes.get_errno())
            )
            os.close(fd)
            return None
        return cls(fd, period_s)

    def fileno(self) -> int:
        return self.fd

    def expirations(self) -> int:
        """Periods elapsed since the last read (0 if none: a spurious wake-up)."""
        try:
            return int.from_bytes(os.read(self.fd, 8), sys.byteorder)
        except BlockingIOError:
            return 0

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
