"""The one owner of the reference the vehicle is sent (PX4's FlightTask hand-over, DESIGN 7).

``ReferenceOwner`` holds the active reference (an ``ActiveReference`` flown from a mission time,
or a hover at a point) and is the setpoint stream's source. Everything that needs the reference
asks it: the executor's phase machine and monitor, the threat decisions (which get a value,
``active_trajectory``), the record, the status, the fleet's publication. A new reference starts
from the state the current one commands at the instant the switch takes effect (a later ``t0_s``
keeps the current one until then), so a switch never jumps: a property of this owner, not of
each caller.

Pure: no I/O, no asyncio. The clock is given (``now_s`` and the mission time of a monotonic
instant).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

import numpy as np

from companion.flight.reference import ActiveReference, MissionClock
from companion.flight.setpoint import Setpoint, SetpointSource, hold_position

__all__ = ["ReferenceOwner", "ReferenceListener"]

log = logging.getLogger(__name__)


class ReferenceListener(Protocol):
    """Told of every new reference (``None``: a hover with no trajectory)."""

    def __call__(self, reference: ActiveReference | None) -> None: ...


class ReferenceOwner:
    """The active reference and the setpoint source that samples it.

    Parameters
    ----------
    clock : MissionClock
        Mission time (the vehicle's seconds: a VehicleClock; fast time's VirtualClock), also of
        a monotonic instant.
    turn_rate_rad_s : float
        How fast a leg that starts at rest turns on the spot to its heading first.
    yaw_now_rad : callable () -> float
        The vehicle's heading now (where a turn starts from, and a hover's heading).
    """

    def __init__(self, clock: MissionClock, *, turn_rate_rad_s: float, yaw_now_rad: Callable[[], float]) -> None:
        self.clock = clock
        self.turn_rate_rad_s = float(turn_rate_rad_s)
        self.yaw_now_rad = yaw_now_rad
        self.current: ActiveReference | None = None
        self._hover: SetpointSource | None = None  # the hover source when no trajectory is active
        self._listeners: list[ReferenceListener] = []

    def listen(self, listener: ReferenceListener) -> Callable[[], None]:
        """Call ``listener(reference)`` after every change; returns the function that stops it."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener) if listener in self._listeners else None

    def engage(
        self, trajectory, path_id: str, t0_s: float | None = None, *, turn: bool = False, resume: bool = False
    ) -> ActiveReference:
        """Make ``trajectory`` the active reference from mission time ``t0_s`` (default now).

        A later ``t0_s`` keeps the current reference until then; ``turn``: first turn on the
        spot to the trajectory's heading (a leg that starts at rest); ``resume``: it stops short
        of the leg's goal on purpose (an evasion or a hold).
        """
        now = self.clock.now_s()
        later = t0_s is not None and t0_s > now
        ref = ActiveReference(
            trajectory,
            now if t0_s is None else t0_s,
            self.clock,
            path_id,
            turn_from_yaw_rad=self.yaw_now_rad() if turn else None,
            turn_rate_rad_s=self.turn_rate_rad_s,
            resume=resume,
            previous=self.current if later else None,
        )
        self.current, self._hover = ref, None
        self._tell(ref)
        return ref

    def hold(self, pos_ned_m) -> None:
        """Hover at ``pos_ned_m`` (no trajectory: ``current`` is None until the next engage)."""
        self.current = None
        self._hover = hold_position(np.asarray(pos_ned_m, dtype=float), self.yaw_now_rad())
        self._tell(None)

    @property
    def holding(self) -> bool:
        """A hover is commanded (no trajectory)."""
        return self._hover is not None

    def setpoint_at(self, monotonic_s: float) -> Setpoint | None:
        """The setpoint at the monotonic instant ``monotonic_s`` (the stream's source); None
        before anything was engaged or held."""
        if self.current is not None:
            return self.current.setpoint_at(monotonic_s)
        return None if self._hover is None else self._hover(monotonic_s)

    def prepare(self) -> None:
        """Work ahead for the stream (``ActiveReference.prepare``)."""
        if self.current is not None:
            self.current.prepare()

    def _tell(self, ref: ActiveReference | None) -> None:
        for listener in list(self._listeners):
            try:
                listener(ref)
            except Exception:  # noqa: BLE001 - a listener must not stop a hand-over
                log.exception("reference listener %r failed", listener)
