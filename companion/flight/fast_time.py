"""Fast time: the flight executor flown in process against the helicopter model (ArduPilot SITL).

``FastTimeFlight`` runs the very ``FlightExecutor`` that ``companion run`` runs, with other
ports (``companion.flight.ports``):

- the clock is virtual (:class:`VirtualClock`): mission time and the executor's clock are one;
- the vehicle is the closed-loop helicopter model (:class:`ModelVehicle`:
  ``heli_model.vehicle_update.VehicleUpdate``, the LQI flight controller and RK4 physics that
  ``sim-vehicle`` flies), given each setpoint the executor streams;
- jobs (decisions, replans, alternatives) run in process (:class:`InlineJobs`); each is done
  at its start plus its measured wall-clock duration (times ``job_time_scale``) on the virtual
  clock, or plus a modelled duration (:class:`JobLatency`: a reproducible flight), and handed
  over at that instant, so the vehicle keeps flying the old reference meanwhile, as it does
  over MAVLink;
- threats arrive as the encounter says (:class:`ThreatFeed`): each update at its time, through
  the same ``Avoidance.on_threats_changed`` a zenoh sample or an ADS-B report goes through.

No sockets, no asyncio, no processes. The result (:class:`FastTimeResult`) holds the vehicle's
own trajectory and every decision told.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import itertools
import logging
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from companion.flight.active import ReferenceOwner
from companion.flight.avoidance import AlternativesPlan, Avoidance
from companion.flight.executor import FlightExecutor
from companion.flight.legs import FlightOutcome, LegReplanner
from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.ports import VehicleView
from companion.threats.decision.kinds import DecisionKind, Strategy, Trigger
from companion.threats.decision.step import DecisionPolicy, DecisionState
from companion.threats.model import Threat, ThreatTable
from heli_model import dynamics
from heli_model.control import Setpoint as ModelSetpoint
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleUpdate

__all__ = [
    "VirtualClock",
    "ModelVehicle",
    "JobLatency",
    "InlineJobs",
    "ThreatFeed",
    "FlightLog",
    "FastTimeResult",
    "FastTimeFlight",
]

log = logging.getLogger(__name__)

#: Position indices of the simulation state (``heli_model.dynamics``: 13 model states, yaw, NED).
_POS = slice(14, 17)


class VirtualClock:
    """Mission time and the executor's clock in one: virtual seconds, advanced by the driver."""

    scale = 1.0

    def __init__(self, t0_s: float = 0.0) -> None:
        self.t_s = float(t0_s)

    def now_s(self, monotonic_s: float | None = None) -> float:
        """Now (or the mission time of an executor instant: the same number)."""
        return self.t_s if monotonic_s is None else float(monotonic_s)

    @property
    def synced(self) -> bool:
        return True


class ModelVehicle:
    """The helicopter model flying the setpoints it is given (the fast-time ``VehiclePort``).

    Parameters
    ----------
    update : VehicleUpdate
    pos_ned_m : array_like, shape (3,)
        Where it hovers at the start (trimmed).
    yaw_rad : float
    """

    def __init__(self, update: VehicleUpdate, pos_ned_m, yaw_rad: float = 0.0) -> None:
        self.update = update
        self.state = update.hover_state(np.asarray(pos_ned_m, dtype=float), yaw_rad)
        self.setpoint: ModelSetpoint | None = None
        self.control_dt_s = update.law.settings.control_dt_s

    @property
    def pos_ned_m(self) -> np.ndarray:
        return self.state.x[_POS].copy()

    @property
    def yaw_rad(self) -> float:
        return float(self.state.x[dynamics.IDX_PSI])

    def view(self) -> VehicleView:
        return VehicleView(True, True, True, "GUIDED", self.pos_ned_m, self.yaw_rad)

    def command(self, setpoint) -> None:
        """The setpoint streamed (``companion.flight.setpoint.Setpoint``)."""
        self.setpoint = ModelSetpoint(
            np.asarray(setpoint.pos_ned_m, dtype=float),
            None if setpoint.vel_ned_m_s is None else np.asarray(setpoint.vel_ned_m_s, dtype=float),
            None if setpoint.acc_ned_m_s2 is None else np.asarray(setpoint.acc_ned_m_s2, dtype=float),
            setpoint.yaw_rad,
            setpoint.yaw_rate_rad_s,
        )

    def advance(self, dt_s: float) -> None:
        """Fly ``dt_s`` on the last setpoint: the controller at its own period, RK4 within."""
        n = max(1, math.ceil(dt_s / self.control_dt_s - 1e-9))
        self.state = self.update.fly(self.state, VehicleCommand(self.setpoint), dt_s / n, n)


@dataclasses.dataclass(frozen=True)
class JobLatency:
    """Modelled job durations on the virtual clock (s), in place of the measured ones: the flight
    no longer depends on this machine's speed or load (the campaign's rows are reproducible).

    The defaults are the decision-latency goals: 50 ms for a decision, 250 ms for one that plans
    again (a replan, or the way back to the mission) and for a leg's replan; 0.5 s for an
    alternatives search (its default wall-clock budget).
    """

    decision_s: float = 0.05
    replan_s: float = 0.25
    alternatives_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("decision_s", "replan_s", "alternatives_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: must be a finite number of seconds >= 0, got {value!r}")

    def of(self, name: str, args: tuple, result) -> float:
        """The duration of job ``name`` called with ``args`` that returned ``result`` (None when
        it raised)."""
        if name == "alternatives":
            return self.alternatives_s
        if name == "decision":
            observation = args[1]
            kind = getattr(result[0], "kind", None) if isinstance(result, tuple) and result else None
            plans = kind == DecisionKind.REPLAN or observation.trigger == Trigger.RESUME
            return self.replan_s if plans else self.decision_s
        return self.replan_s


@dataclasses.dataclass(order=True)
class _Job:
    due_s: float
    order: int
    outcome: Callable = dataclasses.field(compare=False)


class InlineJobs:
    """Jobs run in process at submission, done on the virtual clock after their measured time.

    Parameters
    ----------
    clock : VirtualClock
    job_time_scale : float
        Virtual seconds per measured wall-clock second of a job (1: as long as it took here).
    latency : JobLatency, optional
        Modelled durations instead (``job_time_scale`` is then not used).
    """

    def __init__(self, clock: VirtualClock, job_time_scale: float = 1.0, latency: JobLatency | None = None) -> None:
        self.clock = clock
        self.job_time_scale = float(job_time_scale)
        self.latency = latency
        self._due: list[_Job] = []
        self._order = itertools.count()
        self.wall_s: dict[str, list[float]] = {}

    def submit(self, name: str, fn: Callable, args: tuple, done: Callable, failed: Callable) -> None:
        t0 = time.perf_counter()
        result = None
        try:
            result = fn(*args)
            outcome = lambda: done(result)  # noqa: E731 - delivered later
        except Exception as exc:  # noqa: BLE001 - a job's failure is the caller's to handle
            outcome = functools.partial(failed, exc)  # ``exc`` itself is unbound after the block
        spent = time.perf_counter() - t0
        self.wall_s.setdefault(name, []).append(spent)
        took = spent * self.job_time_scale if self.latency is None else self.latency.of(name, args, result)
        heapq.heappush(self._due, _Job(self.clock.t_s + took, next(self._order), outcome))

    def deliver(self, now_s: float) -> None:
        """Hand over the results of the jobs done by ``now_s``, in order, each at the instant it
        was done (as the daemon's loop takes a worker's result the moment it comes)."""
        while self._due and self._due[0].due_s <= now_s:
            job = heapq.heappop(self._due)
            self.clock.t_s = max(job.due_s, self.clock.t_s)
            job.outcome()
        self.clock.t_s = now_s


class ThreatFeed:
    """An encounter's threat updates, delivered at their times (the fast-time ``ThreatSource``).

    Parameters
    ----------
    updates : sequence of (t_s, Threat or None, str)
        Mission time, the threat put (None: the id deleted) and its id.
    home : companion.geo.LocalFrame, optional
        Where ``global`` threats (ADS-B) are converted to the local frame.
    """

    def __init__(self, updates: Sequence[tuple[float, Threat | None, str]], home=None) -> None:
        self.table = ThreatTable(home)
        self._updates = sorted(updates, key=lambda u: u[0])
        self._next = 0

    def threats_at(self, t_s: float) -> tuple:
        return self.table.snapshot(t_s)

    def any_known(self) -> bool:
        return len(self.table) > 0

    def deliver(self, now_s: float) -> bool:
        """Put or delete the updates due by ``now_s``; True when the table changed."""
        changed = False
        while self._next < len(self._updates) and self._updates[self._next][0] <= now_s:
            _, threat, threat_id = self._updates[self._next]
            self._next += 1
            if threat is None:
                self.table.delete(threat_id)
            else:
                self.table.put(threat)
            changed = True
        self.table.expire(now_s)
        return changed


class FlightLog:
    """The fast-time ``FlightSink``: what the flight told, kept in lists (events stamped with
    the mission time ``now_s()``, as the daemon's record stamps them)."""

    def __init__(self, now_s: Callable[[], float]) -> None:
        self.now_s = now_s
        self.events: list[dict] = []
        self.decisions: list[dict] = []
        self.alerts: list = []
        self.paths = 0

    def event(self, name: str, **fields) -> None:
        self.events.append({"name": name, "t_s": self.now_s(), **fields})

    def decision(self, decision, event: dict) -> None:
        self.decisions.append(event)

    def record(self, line_type: str, /, **fields) -> None:
        if line_type == "event":
            self.events.append(fields)

    def path(self, reference, alternatives, leg_index: int) -> None:
        self.paths += 1

    def alert(self, alert) -> None:
        self.alerts.append(alert)


@dataclasses.dataclass(frozen=True)
class FastTimeResult:
    """A fast-time flight.

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        Mission times of the samples (every executor tick).
    pos_ned_m : ndarray, shape (K, 3)
        The vehicle's own position (the model's).
    ref_pos_ned_m : ndarray, shape (K, 3)
        The setpoint's position at those times.
    decisions : list of dict
        Every decision told (the ``uav/<sysid>/events`` messages).
    events : list of dict
    outcome : FlightOutcome
    reason : str
    schedule : list of dict
        The executor's schedule with what each task cost.
    job_wall_s : dict
        Measured wall-clock time of each job, by kind.
    states : list of VehicleState
        The vehicle's state at each sample (to join the flight later: ``run(from_state=...)``).
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    ref_pos_ned_m: np.ndarray
    decisions: list
    events: list
    outcome: FlightOutcome
    reason: str
    schedule: list
    job_wall_s: dict
    states: list = dataclasses.field(default_factory=list, repr=False)


class FastTimeFlight:
    """The flight executor on the virtual clock against the helicopter model.

    Parameters
    ----------
    legs : sequence of LegPlan
        The mission's legs (``companion.flight.plan``); the vehicle starts hovering at the
        first leg's start.
    settings : companion.config.Settings
        The companion's settings, as ``companion run`` takes them.
    threats : sequence of (t_s, Threat or None, str), optional
        The threat updates (``ThreatFeed``); None: no threats watched (no ``Avoidance``).
    strategy : Strategy
    policy : DecisionPolicy, optional
        The decision's policy (default ``DecisionPolicy.from_settings(settings, strategy)``).
    seed : int
    start_yaw_rad : float
    model : HeliModel, optional
        Default ``HeliModel.default()`` with the settings' controller.
    job_time_scale : float
        See ``InlineJobs``.
    world : World, optional
        The mission's world, where a leg is planned again (default: the first leg's).
    replanner : LegReplanner, optional
        How a leg is planned again (default: in ``world``, through the settings' pipeline).
    update : VehicleUpdate, optional
        The vehicle (default: built from ``model``); give one to fly many flights on one design.
    job_latency : JobLatency, optional
        Modelled job durations (``InlineJobs``); default: measured, times ``job_time_scale``.
    home : companion.geo.LocalFrame, optional
        The local frame's origin, for ``global`` threats (ADS-B reports).
    """

    def __init__(
        self,
        legs,
        settings,
        *,
        threats=None,
        strategy: Strategy = Strategy.HYBRID,
        policy: DecisionPolicy | None = None,
        seed: int = 0,
        start_yaw_rad: float = 0.0,
        model: HeliModel | None = None,
        job_time_scale: float = 1.0,
        world=None,
        replanner: LegReplanner | None = None,
        update: VehicleUpdate | None = None,
        job_latency: JobLatency | None = None,
        home=None,
    ) -> None:
        self.settings = settings
        self.clock = VirtualClock()
        start = np.asarray(legs[0].trajectory.sample(np.array([0.0]))[0][0], dtype=float)
        update = update or VehicleUpdate.build(model or HeliModel.default())
        self.vehicle = ModelVehicle(update, start, start_yaw_rad)
        self.jobs = InlineJobs(self.clock, job_time_scale, job_latency)
        self.log = FlightLog(self.clock.now_s)
        self.owner = ReferenceOwner(
            self.clock, turn_rate_rad_s=settings.flight.turn_rate_rad_s, yaw_now_rad=lambda: self.vehicle.yaw_rad
        )
        self.feed = ThreatFeed(threats, home) if threats is not None else None
        self.avoidance = (
            None
            if self.feed is None
            else self._avoidance(self.feed, policy or DecisionPolicy.from_settings(settings, strategy), seed)
        )
        s = settings
        self.executor = FlightExecutor(
            legs,
            owner=self.owner,
            vehicle=self.vehicle,
            jobs=self.jobs,
            sink=self.log,
            stream=self._stream,
            now_s=self.clock.now_s,
            clock_s=self.clock.now_s,
            setpoint_rate_hz=s.link.setpoint_rate_hz,
            timeout_margin_s=s.link.leg_timeout_margin_s,
            replanner=replanner
            or LegReplanner.in_world(
                world or legs[0].world, TrajectoryPipeline.from_settings(s.smoothing, s.planning), s.flight
            ),
            avoidance=self.avoidance,
            alternatives_rate_hz=1.0 / s.flight.alternatives_period_s,
            alerts_rate_hz=s.alerts.rate_hz,
            seed=seed,
        )
        self._refs: list[np.ndarray] = []

    def _avoidance(self, feed: ThreatFeed, policy: DecisionPolicy, seed: int) -> Avoidance:
        f = self.settings.flight
        return Avoidance(
            policy=policy,
            state=DecisionState.initial(policy, seed),
            owner=self.owner,
            threats=feed,
            jobs=self.jobs,
            sink=self.log,
            now_s=self.clock.now_s,
            monotonic_s=self.clock.now_s,
            send_now=lambda: self.executor.send_now(),
            position_ned_m=lambda: self.vehicle.pos_ned_m,
            alternatives=AlternativesPlan(f.alternatives_k, f.alternatives_budget_s, f.alternatives_lead_s),
            alerts=self.settings.alerts,
        )

    def _stream(self, now_s: float, scheduled: bool) -> None:
        setpoint = self.owner.setpoint_at(now_s)
        if setpoint is not None:
            self.vehicle.command(setpoint)

    def run(self, max_s: float = 600.0, *, from_s: float = 0.0, from_state=None) -> FastTimeResult:
        """Fly until the legs are done or ``max_s`` of mission time has passed.

        Parameters
        ----------
        max_s : float
        from_s, from_state : float, VehicleState, optional
            Join the flight in the air: the legs are engaged at time 0 as always, then the clock
            jumps to ``from_s`` (a tick) and the vehicle is in ``from_state`` (a state of an earlier
            flight of these legs at that instant, ``FastTimeResult.states``): an encounter that
            begins in cruise, without flying what comes before again.
        """
        dt = 1.0 / self.settings.link.setpoint_rate_hz
        self.owner.hold(self.vehicle.pos_ned_m)
        self.executor.start()
        k = 0
        if from_state is not None:
            k = int(round(from_s / dt))
            self.vehicle.state = from_state
            self.clock.t_s = k * dt
        times, positions, refs, states = [], [], [], []
        while not self.executor.done and self.clock.t_s < max_s:
            now = self.clock.t_s
            if self.feed is not None and self.feed.deliver(now):
                assert self.avoidance is not None  # made with the feed
                self.avoidance.on_threats_changed(now)
            self.jobs.deliver(now)
            self.executor.tick(now)
            times.append(now)
            positions.append(self.vehicle.pos_ned_m)
            states.append(self.vehicle.state)
            sp = self.vehicle.setpoint
            refs.append(positions[-1] if sp is None else np.asarray(sp.pos_ned_m, dtype=float))
            self.vehicle.advance(dt)
            k += 1
            self.clock.t_s = k * dt
        outcome, reason = self.executor.outcome, self.executor.legs.reason
        if not self.executor.done:
            reason = f"not done after {max_s:g} s"
        return FastTimeResult(
            np.asarray(times),
            np.asarray(positions),
            np.asarray(refs),
            self.log.decisions,
            self.log.events,
            outcome,
            reason,
            self.executor.schedule.report(),
            self.jobs.wall_s,
            states,
        )
