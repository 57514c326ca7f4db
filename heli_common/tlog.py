"""Telemetry logs (``.tlog``): MAVLink frames as they crossed a link, each after its time stamp.

The format MAVProxy writes and ``pymavlink.mavutil.mavlink_connection("x.tlog")``, MAVExplorer
and QGroundControl read: for every frame, the wall-clock time in microseconds since the Unix
epoch as a big-endian unsigned 64-bit integer, then the frame's bytes unchanged (MAVLink 1 or 2,
signed or not). Both directions go in one file.

pymavlink reads these files, but has no writer of them: ``mavutil.mavlogfile.write`` appends the
bytes it is given without the stamp (MAVProxy packs each stamp itself, as :func:`tlog_record`
does), so this module writes them; the tests read them back with pymavlink.
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

__all__ = ["TlogWriter", "tlog_record"]

_STAMP = struct.Struct(">Q")


def tlog_record(frame: bytes, time_s: float) -> bytes:
    """One ``.tlog`` record: ``time_s`` (Unix seconds) as big-endian microseconds, then ``frame``."""
    return _STAMP.pack(int(time_s * 1e6)) + frame


class TlogWriter:
    """Appends frames to a ``.tlog`` file; flushed at most ``flush_period_s`` after each write.

    Parameters
    ----------
    path : str or Path
        The file, opened for appending (a restarted process adds to the same log).
    flush_period_s : float
        A crash loses at most this much of the log.
    clock : callable
        Unix time in seconds (``time.time``).

    Raises
    ------
    OSError
        When ``path`` cannot be opened for writing.
    """

    def __init__(self, path: str | Path, flush_period_s: float = 0.5, clock: Callable[[], float] = time.time) -> None:
        self.path = Path(path)
        self._file: BinaryIO | None = open(self.path, "ab")  # None once closed
        self._clock = clock
        self._flush_period_s = flush_period_s
        self._last_flush_s = clock()
        self._lock = threading.Lock()
        self.frames = 0

    def write(self, frame: bytes) -> None:
        """Record one frame now (ignored once closed)."""
        with self._lock:
            if self._file is None:
                return
            now = self._clock()
            self._file.write(tlog_record(frame, now))
            self.frames += 1
            if now - self._last_flush_s >= self._flush_period_s:
                self._file.flush()
                self._last_flush_s = now

    def close(self) -> None:
        """Flush and close (idempotent)."""
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None
