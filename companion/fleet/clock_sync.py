"""Clock offset between two companions from the stamps their trajectory messages carry.

NTP's exchange over zenoh: A sends at ``t1`` (its clock), B receives at ``t2`` (B's clock) and
echoes ``(t1, t2)`` in its next message, sent at ``t3``; A receives that at ``t4``. Then

    offset (B minus A) = ((t2 - t1) + (t3 - t4)) / 2,     round trip = (t4 - t1) - (t3 - t2),

and the true offset lies within half the round trip of the estimate, whatever the asymmetry of
the two directions. Of the exchanges in the last ``window_s``, the one with the shortest round
trip is kept (NTP's clock filter): its bound is the smallest. Before any exchange the offset is
taken as 0 (the same machine, or clocks kept by NTP) and the bound is unknown (inf).

Pure: numbers only; times are arguments.
"""

from __future__ import annotations

import math
from collections import deque

__all__ = ["ClockOffset", "exchange"]


def exchange(t1: float, t2: float, t3: float, t4: float) -> tuple[float, float]:
    """``(offset, round_trip)`` of one exchange (see the module docstring), seconds."""
    return ((t2 - t1) + (t3 - t4)) / 2.0, (t4 - t1) - (t3 - t2)


class ClockOffset:
    """The offset of one other vehicle's wall clock from ours, best of a sliding window.

    Parameters
    ----------
    window_s : float
        Exchanges older than this (our clock, s) are forgotten.
    """

    def __init__(self, window_s: float = 60.0) -> None:
        self.window_s = window_s
        self._samples: deque[tuple[float, float, float]] = deque()  # (t4, offset, round trip)

    def observe(self, t1: float, t2: float, t3: float, t4: float) -> None:
        offset, rtt = exchange(t1, t2, t3, t4)
        if rtt < -1e-9:  # stamps that contradict each other: ignored
            return
        self._samples.append((t4, offset, max(rtt, 0.0)))
        while self._samples and self._samples[0][0] < t4 - self.window_s:
            self._samples.popleft()

    def _best(self):
        return min(self._samples, key=lambda s: s[2]) if self._samples else None

    @property
    def offset_s(self) -> float:
        """Their clock minus ours (s); 0 before any exchange."""
        best = self._best()
        return 0.0 if best is None else best[1]

    @property
    def bound_s(self) -> float:
        """Half the round trip of the exchange used: the error bound of ``offset_s`` (inf before any)."""
        best = self._best()
        return math.inf if best is None else best[2] / 2.0
