"""The flight executor: the clock, the phase machine, the monitor, the decisions and the
reference, run by one explicit schedule (DESIGN 7; after ArduPilot's AP_Scheduler and SITL).

``FlightExecutor`` flies a mission's legs. It is made of

- the ``ReferenceOwner`` (``companion.flight.active``): the one active reference, the setpoint
  stream's source;
- the ``LegRunner`` (``companion.flight.legs``): the legs one after the other, each by the pure
  phase machine;
- the ``Avoidance`` (``companion.flight.avoidance``), when threats are watched: monitor,
  decisions through the pure step ``decide(state, observation, leg, policy)``, alternatives;
- its ``Scheduler`` (``companion.flight.schedule``): the table below, at declared rates, run by
  whoever drives :meth:`FlightExecutor.tick`.

================  =====================================  =================================
task              rate                                   work
================  =====================================  =================================
``setpoints``     ``link.setpoint_rate_hz`` (50 Hz)      the active reference's setpoint out
``tell``          every tick                             decisions told once their first
                                                         setpoint went out (latency)
``prepare``       10 Hz                                  the reference's work ahead
``phase``         10 Hz                                  the phase machine (``leg_step``)
``monitor``       10 Hz (DESIGN 7.3: >= 10 Hz)           the active reference re-checked
``alternatives``  ``time_scale / flight.alternatives_    M-GART alternatives planned again
                  period_s``
``alerts``        ``time_scale x alerts.rate_hz`` (1 Hz)  traffic alerts to the ground station
================  =====================================  =================================

The daemon adds its own rows (telemetry hand-over, record, status, zenoh watch, fleet
publication: ``companion.service.tasks``) and drives the table from its 50 Hz timer over MAVLink
(``companion.service.driver``); a fast-time flight (``companion.flight.fast_time``) drives the
very same executor from a virtual clock against the closed-loop helicopter model. Only the
ports differ (``companion.flight.ports``). No asyncio and no I/O here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from companion.flight.active import ReferenceOwner
from companion.flight.avoidance import Avoidance
from companion.flight.legs import FlightOutcome, LegReplanner, LegRunner
from companion.flight.ports import FlightSink, Jobs, VehiclePort
from companion.flight.schedule import Scheduler, Task

__all__ = ["FlightExecutor", "PHASE_RATE_HZ", "PREPARE_RATE_HZ", "MONITOR_RATE_HZ"]

log = logging.getLogger(__name__)

#: The phase machine's rate (Hz of the executor's clock): the vehicle's position arrives at
#: 10 Hz, so stepping faster only repeats the same observation.
PHASE_RATE_HZ = 10.0
#: How often the reference evaluates ahead of the stream.
PREPARE_RATE_HZ = 10.0
#: The monitor's rate: the active reference is re-checked at >= 10 Hz (DESIGN 7.3).
MONITOR_RATE_HZ = 10.0


class FlightExecutor:
    """Flies the legs of a mission on its schedule (see the module docstring).

    Parameters
    ----------
    legs : sequence of LegPlan
    owner : ReferenceOwner
    vehicle : VehiclePort
    jobs : Jobs
    sink : FlightSink
    stream : callable (now_s, scheduled) -> None
        Sends the owner's setpoint at executor time ``now_s`` (``scheduled`` False: a send out
        of the table, a new reference's first setpoint).
    now_s : callable () -> float
        Mission time now.
    clock_s : callable () -> float
        The executor's clock, the one ``tick`` is driven by (monotonic wall seconds in real
        time, virtual seconds in fast time).
    setpoint_rate_hz : float
    timeout_margin_s : float
        See ``companion.flight.phases``.
    replanner : LegReplanner
    avoidance : Avoidance, optional
    monitor_rate_hz, alternatives_rate_hz, alerts_rate_hz : float
        The monitor's, the alternatives' and the traffic alerts' rates (with ``avoidance``; the
        alerts with its ``alerts``).
    leg_started : callable (LegPlan), optional
    seed : int
    slack_s : float
        See ``Scheduler``.
    """

    def __init__(
        self,
        legs: Sequence,
        *,
        owner: ReferenceOwner,
        vehicle: VehiclePort,
        jobs: Jobs,
        sink: FlightSink,
        stream: Callable[[float, bool], None],
        now_s: Callable[[], float],
        clock_s: Callable[[], float],
        setpoint_rate_hz: float,
        timeout_margin_s: float,
        replanner: LegReplanner,
        avoidance: Avoidance | None = None,
        monitor_rate_hz: float = MONITOR_RATE_HZ,
        alternatives_rate_hz: float = 0.2,
        alerts_rate_hz: float = 1.0,
        leg_started: Callable | None = None,
        seed: int = 0,
        slack_s: float = 0.0,
    ) -> None:
        self.owner = owner
        self.avoidance = avoidance
        self.stream = stream
        self.clock_s = clock_s
        self.legs = LegRunner(
            legs,
            owner=owner,
            vehicle=vehicle,
            jobs=jobs,
            sink=sink,
            now_s=now_s,
            replanner=replanner,
            timeout_margin_s=timeout_margin_s,
            avoidance=avoidance,
            leg_started=leg_started,
            seed=seed,
        )
        self.schedule = Scheduler(
            self._table(setpoint_rate_hz, monitor_rate_hz, alternatives_rate_hz, alerts_rate_hz), slack_s=slack_s
        )

    def _table(
        self, setpoint_rate_hz: float, monitor_rate_hz: float, alternatives_rate_hz: float, alerts_rate_hz: float
    ) -> list[Task]:
        rows = [
            Task("setpoints", setpoint_rate_hz, lambda now: self.stream(now, True), budget_ms=2.0),
            Task("prepare", PREPARE_RATE_HZ, lambda now: self.owner.prepare(), budget_ms=4.0),
            Task("phase", PHASE_RATE_HZ, self.legs.step, budget_ms=2.0),
        ]
        if self.avoidance is not None:
            rows += [
                Task("tell", setpoint_rate_hz, self.avoidance.tell_engaged, budget_ms=1.0),
                Task("monitor", monitor_rate_hz, self.avoidance.monitor, budget_ms=8.0),
                Task("alternatives", alternatives_rate_hz, self.avoidance.refresh_alternatives, budget_ms=2.0),
            ]
            if self.avoidance.alerts is not None:
                rows.append(Task("alerts", alerts_rate_hz, self.avoidance.alerts.check, budget_ms=4.0))
        return rows

    # ------------------------------------------------------------------ driving
    def start(self) -> None:
        """Engage the first leg (the vehicle hovers where the legs start)."""
        self.legs.start()

    def tick(self, now_s: float) -> None:
        """One tick of the driver at executor time ``now_s``: the tasks that are due run."""
        self.schedule.tick(now_s)

    def send_now(self) -> None:
        """Send the current setpoint at once (a new reference's first setpoint)."""
        self.stream(self.clock_s(), False)

    @property
    def done(self) -> bool:
        return self.legs.done

    @property
    def outcome(self) -> FlightOutcome:
        return self.legs.outcome
