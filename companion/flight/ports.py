"""What the flight executor needs from the world around it: the ports it is built with.

The executor (``companion.flight.executor``) runs unchanged in real time inside the daemon and
in fast time in the campaign; only these ports differ, as ArduPilot's flight code runs against
SITL's HAL:

========================  =============================================  ==============================
port                      real time (``companion run``)                   fast time (``fast_time``)
========================  =============================================  ==============================
``VehiclePort``           the MAVLink link's telemetry                    the closed-loop helicopter model
``Jobs``                  the planning worker processes                   in process, done after the
                                                                          measured time on the virtual clock
``FlightSink``            record, zenoh events and status, STATUSTEXT,    the flight's log (lists)
                          COLLISION
========================  =============================================  ==============================

The setpoints leave through the ``ReferenceOwner``'s stream (``companion.flight.active``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["VehicleView", "VehiclePort", "Jobs", "FlightSink"]


@dataclass(frozen=True)
class VehicleView:
    """The vehicle as the executor sees it at one instant.

    Attributes
    ----------
    connected : bool
        Its heartbeat is heard.
    armed, guided : bool or None
        None: not known yet.
    mode_name : str
    pos_ned_m : ndarray, shape (3,), or None
        About the planning home; None before the first position.
    yaw_rad : float
    """

    connected: bool
    armed: bool | None
    guided: bool | None
    mode_name: str
    pos_ned_m: np.ndarray | None
    yaw_rad: float = 0.0


class VehiclePort(Protocol):
    """The vehicle's state (telemetry, or the model's)."""

    def view(self) -> VehicleView: ...


class Jobs(Protocol):
    """Slow work (planning, decisions) off the executor's ticks.

    ``submit`` runs ``fn(*args)`` somewhere and later calls ``done(result)`` or
    ``failed(error)`` from the executor's own thread; the executor never waits for it.
    """

    def submit(
        self,
        name: str,
        fn: Callable,
        args: tuple,
        done: Callable[[object], None],
        failed: Callable[[BaseException], None],
    ) -> None: ...


class FlightSink(Protocol):
    """Where the flight's events and decisions are told."""

    def event(self, name: str, **fields) -> None:
        """A flight event (leg reached, resumed, ...): logged, recorded, status published."""

    def decision(self, decision, event: dict) -> None:
        """A threat decision that changed the reference (or a rejection): published on
        ``uav/<sysid>/events`` and ``path``, recorded, told to the ground stations."""

    def record(self, line_type: str, /, **fields) -> None:
        """One line of the flight record."""

    def path(self, reference, alternatives, leg_index: int) -> None:
        """The active reference and the alternatives (``uav/<sysid>/path``)."""

    def alert(self, alert) -> None:
        """A traffic alert (``companion.flight.alerting.TrafficAlert``): COLLISION and, when it
        has one, its STATUSTEXT to the ground stations; recorded and published."""
