"""The values of the threat decision step (``step.decide``): what it is given and what it hands
on, each small, immutable and picklable (sent to a planning worker process and back).

- ``ActiveTrajectory``: the reference being flown, as the decision sees it (the caller owns it).
- ``LegContext``: the leg's static airspace (index, world, goal).
- ``DecisionPolicy``: the policy as data (settings, the trajectory pipeline, strategy,
  time scale).
- ``DecisionState``: what one decision hands to the next (seed and counter of the derived
  generators, running estimates, replan back-off, alternatives).
- ``Observation``: what a decision sees (time, threats, active reference, trigger).

Bad arguments raise ``DecisionError`` naming them.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass, field, replace

import numpy as np

from companion.errors import CompanionError
from companion.flight.pipeline import TrajectoryPipeline
from companion.threats.decision.alternatives import Alternative
from companion.threats.decision.estimate import RunningEstimate
from companion.threats.decision.kinds import Strategy, Trigger
from companion.threats.decision.spacetime import reference_accel_bound_m_s2
from companion.threats.settings import ThreatSettings
from companion.world import World

__all__ = [
    "DecisionError",
    "ActiveTrajectory",
    "LegContext",
    "DecisionPolicy",
    "DecisionState",
    "Observation",
    "FAST_ESTIMATE_S",
]

#: First estimate of the fast candidates' wall-clock time (s), before any was measured.
FAST_ESTIMATE_S = 0.03


class DecisionError(CompanionError, ValueError):
    """Bad arguments to the threat decision (naming them)."""


def _finite_positive(name: str, value) -> float:
    if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise DecisionError(f"{name}: must be a finite number > 0, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class ActiveTrajectory:
    """The reference being flown, as the decision sees it (the caller owns the real one).

    Attributes
    ----------
    trajectory : Trajectory-like
        ``sample(t_s) -> (pos, vel, acc)``, ``duration_s``; t = 0 at ``start_t_s``.
    start_t_s : float
        Clock time of its t = 0 (s).
    path_id : str
    ends_short : bool
        It stops short of the leg's goal on purpose (an evasion or a hold: resume after it).
    """

    trajectory: object
    start_t_s: float
    path_id: str
    ends_short: bool = False

    def __post_init__(self) -> None:
        if not hasattr(self.trajectory, "sample") or not hasattr(self.trajectory, "duration_s"):
            raise DecisionError("trajectory: expected an object with sample(t_s) and duration_s")
        if not (isinstance(self.start_t_s, (int, float)) and math.isfinite(self.start_t_s)):
            raise DecisionError(f"start_t_s: must be finite, got {self.start_t_s!r}")
        object.__setattr__(self, "start_t_s", float(self.start_t_s))
        object.__setattr__(self, "path_id", str(self.path_id))
        object.__setattr__(self, "ends_short", bool(self.ends_short))


@dataclass(frozen=True, eq=False)
class LegContext:
    """The leg's static airspace: its index, world (2D or 3D, local NED) and goal (d,).

    ``world_key`` (default: made unique at construction) names the world in the per-process
    memo of its widened copies (``worlds.py``); it travels with the leg to a worker process.
    """

    index: int
    world: World
    goal_ned_m: np.ndarray
    world_key: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.world, World):
            raise DecisionError(f"world: expected a World, got {type(self.world).__name__}")
        goal = np.asarray(self.goal_ned_m, dtype=float).reshape(-1)
        if goal.shape != (self.world.dim,) or not np.all(np.isfinite(goal)):
            raise DecisionError(f"goal_ned_m: expected {self.world.dim} finite numbers, got {self.goal_ned_m!r}")
        goal.setflags(write=False)
        object.__setattr__(self, "goal_ned_m", goal)
        object.__setattr__(self, "index", int(self.index))
        if not self.world_key:
            object.__setattr__(self, "world_key", uuid.uuid4().hex)


@dataclass(frozen=True)
class DecisionPolicy:
    """The policy as data.

    Attributes
    ----------
    settings : ThreatSettings
    pipeline : TrajectoryPipeline
        Plans, smooths, times and checks every new trajectory (replans, joins, alternatives:
        ``companion.flight.pipeline``), with the flight's smoothing method and limits.
    strategy : Strategy
        ``hybrid`` (DESIGN section 7, the default) or a single strategy (the benchmark).
    time_scale : float
        Clock seconds per wall-clock second (a SITL speed-up): the decision's own measured
        duration, in clock seconds, is how far ahead its candidates start.
    modelled_lead_s : (float, float) or None
        The fast step's and the replan's durations as modelled (clock seconds), in place of the
        measured running estimates: a fast-time flight whose jobs take modelled times
        (``companion.flight.fast_time.JobLatency``) plans for the same instants.
    """

    settings: ThreatSettings = field(default_factory=ThreatSettings)
    pipeline: TrajectoryPipeline = field(default_factory=TrajectoryPipeline.for_limits)
    strategy: Strategy = Strategy.HYBRID
    time_scale: float = 1.0
    modelled_lead_s: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.settings, ThreatSettings):
            raise DecisionError(f"settings: expected ThreatSettings, got {type(self.settings).__name__}")
        if not isinstance(self.pipeline, TrajectoryPipeline):
            raise DecisionError(f"pipeline: expected a TrajectoryPipeline, got {type(self.pipeline).__name__}")
        try:
            object.__setattr__(self, "strategy", Strategy(self.strategy))
        except ValueError:
            raise DecisionError(f"strategy: expected one of {', '.join(Strategy)}, got {self.strategy!r}") from None
        object.__setattr__(self, "time_scale", _finite_positive("time_scale", self.time_scale))

    @classmethod
    def from_settings(cls, settings, strategy: Strategy | str = Strategy.HYBRID) -> DecisionPolicy:
        """From the companion's ``Settings`` (``threats``; ``smoothing`` and ``planning``: the
        pipeline; ``link.time_scale``: None, not read from the vehicle yet, is real time as for
        the daemon's clock). No closed-loop check: a decision has milliseconds."""
        pipeline = TrajectoryPipeline.from_settings(settings.smoothing, settings.planning)
        return cls(settings.threats, pipeline, strategy, settings.link.time_scale or 1.0)

    @property
    def accel_bound_m_s2(self) -> float:
        """The checks' bound on a reference's acceleration (``spacetime.reference_accel_bound_m_s2``)."""
        return reference_accel_bound_m_s2(self.settings, self.pipeline.limits)

    def lead_s(self, estimate: RunningEstimate) -> float:
        """Clock seconds that a step of ``estimate`` is expected to take (mean + 1 deviation)."""
        return (estimate.mean_s + estimate.dev_s) * self.time_scale

    def fast_lead_s(self, state: DecisionState) -> float:
        """Clock seconds the fast step is expected to take: its running mean. Its candidates
        start then, so its latency is about its own duration; one that takes longer starts its
        reference a few milliseconds late, which the owner takes at its own time (a setpoint step
        of at most the change of acceleration times the delay: 0.05 m/s for 20 ms at 2.5 m/s^2).
        With mean + 1 deviation, most decisions waited for the tail's (SITL: start p99 51-143 ms
        after a 12-31 ms decision)."""
        if self.modelled_lead_s is not None:
            return self.modelled_lead_s[0]
        return state.fast_estimate.mean_s * self.time_scale

    def replan_lead_s(self, state: DecisionState) -> float:
        """Clock seconds a replan is expected to take."""
        return self.lead_s(state.replan_estimate) if self.modelled_lead_s is None else self.modelled_lead_s[1]


@dataclass(frozen=True, eq=False)
class DecisionState:
    """What one decision hands to the next (small, explicit: sent to a worker and back).
    Compared by identity (its alternatives hold arrays): the caller adopts a returned state
    when its own is still the one it sent.

    Attributes
    ----------
    seed : int
        Seed of the derived generators.
    counter : int
        Advanced by every replan, engaged decision and alternatives search (path ids, draws).
    replan_estimate, fast_estimate : RunningEstimate
        Measured wall-clock time of a replan and of the fast candidates (s).
    replan_blocked_until_s : float
        No replan before this clock time (a replan found nothing clear just before).
    alternatives : tuple of Alternative
        The M-GART switching targets.
    """

    seed: int
    counter: int
    replan_estimate: RunningEstimate
    fast_estimate: RunningEstimate
    replan_blocked_until_s: float
    alternatives: tuple[Alternative, ...] = ()

    @classmethod
    def initial(cls, policy: DecisionPolicy, seed: int) -> DecisionState:
        """The state of a flight's first decision: the policy's first estimates, no alternatives."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise DecisionError(f"seed: expected an int >= 0, got {seed!r}")
        return cls(
            int(seed),
            0,
            RunningEstimate(policy.settings.replan_budget_s),
            RunningEstimate(FAST_ESTIMATE_S),
            -math.inf,
            (),
        )

    def with_alternatives(self, alternatives, *, dim: int | None = None, spacing_m: float = 2.0) -> DecisionState:
        """This state with new switching targets (``Alternative`` or (M, d) paths, converted
        with entries ``spacing_m`` apart); every one of dimension ``dim`` (the leg's world's)."""
        alts = []
        for i, alt in enumerate(alternatives):
            if not isinstance(alt, Alternative):
                alt = Alternative.from_path(f"alt{i}", alt, spacing_m)
            want = alts[0].path_ned_m.shape[1] if dim is None and alts else dim
            if want is not None and alt.path_ned_m.shape[1] != want:
                raise DecisionError(
                    f"alternatives[{i}]: dimension {alt.path_ned_m.shape[1]} does not match the world's {want}"
                )
            alts.append(alt)
        return replace(self, alternatives=tuple(alts))

    @property
    def replan_estimate_s(self) -> float:
        """Current replanning estimate: running mean + 3 mean absolute deviations (s)."""
        return self.replan_estimate.high_s


@dataclass(frozen=True, eq=False)
class Observation:
    """What a decision sees: clock time ``t_s``, every threat known then (local frame, stamped on
    the same clock), the reference being flown (None: nothing to decide) and what asked."""

    t_s: float
    threats: tuple = ()
    active: ActiveTrajectory | None = None
    trigger: Trigger = Trigger.THREAT

    def __post_init__(self) -> None:
        if not (isinstance(self.t_s, (int, float)) and math.isfinite(self.t_s)):
            raise DecisionError(f"t_s: must be finite, got {self.t_s!r}")
        if self.active is not None and not isinstance(self.active, ActiveTrajectory):
            raise DecisionError(f"active: expected an ActiveTrajectory, got {type(self.active).__name__}")
        try:
            object.__setattr__(self, "trigger", Trigger(self.trigger))
        except ValueError:
            raise DecisionError(f"trigger: expected one of {', '.join(Trigger)}, got {self.trigger!r}") from None
        object.__setattr__(self, "t_s", float(self.t_s))
        object.__setattr__(self, "threats", tuple(self.threats))
