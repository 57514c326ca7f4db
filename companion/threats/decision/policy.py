"""The threat policy: keep, retime, switch, replan, evade or hold (DESIGN 7, paper section 3.3).

``ThreatManager`` holds the active reference, the leg's airspace and goal, and the M-GART
alternatives, and decides:

- ``on_threats`` (every threat update and every monitor tick, >= 10 Hz): the active reference
  is checked against the tubes over the horizon. Clear -> ``none`` (keep it). Otherwise the
  strategies of the mode produce candidates (``candidates.py``), all judged by the same
  space-time check and chosen by the same cost (``decision.choose``). In ``hybrid`` mode the
  fast candidates (evade and hold, retime, switch: milliseconds) are always generated; when none
  of them reaches the goal clear (retime, switch) and the conflict is further away than the
  measured replanning time, a replan joins them. A candidate that
  still intrudes replaces the active reference only when it is strictly better, so the same
  answer is never decided twice.
- ``resume`` (after an evasion or a hold has ended in a hover): plan back to the mission
  (replan through time, waiting for a mover where that is cheapest, or switch).

The single strategies (``hold``, ``retime``, ``switch``, ``replan``, ``evade``) exist for the
benchmark. Pure: no asyncio, no zenoh, no clock of its own (times are arguments; the wall clock
only measures the decision's own duration). The daemon calls it from one worker thread.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from companion.errors import CompanionError
from companion.flight.pipeline import TrajectoryPipeline
from companion.planning import GartSettings
from companion.smoothing import TrajectoryLimits
from companion.threats.decision import candidates as gen
from companion.threats.decision.alternatives import Alternative, airspace_for, plan_alternatives
from companion.threats.decision.choice import Candidate, Decision, ReferenceState, choose
from companion.threats.decision.prediction import predict_tubes
from companion.threats.settings import ThreatSettings
from companion.threats.decision.spacetime import Conflict
from companion.world import World

__all__ = ["ThreatManager", "ThreatManagerError"]

log = logging.getLogger(__name__)

#: First estimate of the fast candidates' wall-clock time (s), before any was measured.
FAST_ESTIMATE_S = 0.03
#: After a replan that found nothing clear, no replan for this long (clock s): the same
#: failing answer is not sought again every monitor tick.
REPLAN_BACKOFF_S = 1.0
#: Longest candidate accepted (s): a longer one is a numerical failure, logged and dropped.
MAX_DURATION_S = 3600.0
#: An intruding candidate replaces an intruding active reference only with this much more
#: minimum clearance (m).
BETTER_BY_M = 1.0


class ThreatManagerError(CompanionError, ValueError):
    """Bad arguments to the threat manager (naming them)."""


@dataclass
class _Active:
    trajectory: object
    start_t_s: float
    path_id: str
    ends_short: bool = False


@dataclass
class _RunningEstimate:
    """Running estimate of a step's wall-clock time: mean and mean absolute deviation (s)."""

    mean_s: float
    dev_s: float = 0.0
    samples: int = 0

    def update(self, measured_s: float, gain: float) -> None:
        if self.samples == 0:
            self.mean_s, self.dev_s = measured_s, 0.25 * measured_s
        else:
            err = measured_s - self.mean_s
            self.mean_s += gain * err
            self.dev_s += gain * (abs(err) - self.dev_s)
        self.samples += 1

    @property
    def high_s(self) -> float:
        return self.mean_s + 3.0 * self.dev_s


class ThreatManager:
    """The policy of the module docstring. Not thread-safe by itself: call it from one worker
    thread at a time (``set_alternatives`` may come from another).

    Parameters
    ----------
    world : World
        Static world of the current leg (2D or 3D, local NED).
    goal_ned_m : array_like, shape (d,)
    settings : ThreatSettings, optional
    limits : TrajectoryLimits, optional
        Limits of new planned trajectories.
    kappa_max_1_m : float
        K_max of the G2 smoothing.
    gart_settings : GartSettings, optional
    pipeline : TrajectoryPipeline, optional
        Plans, smooths, times and checks every new trajectory (``TrajectoryPipeline.from_settings``);
        default: G2 with ``limits``, ``kappa_max_1_m`` and ``gart_settings``, which must not be
        given with it.
    rng : numpy.random.Generator, optional
        Default: ``numpy.random.default_rng(settings.seed)``.
    mode : str
        One of ``MODES`` (``hybrid``, DESIGN section 7, is the default).
    time_scale : float
        Clock seconds per wall-clock second (a SITL speed-up): the decision's own measured
        duration, in clock seconds, is how far ahead its candidates start.
    """

    MODES = ("hybrid", "hold", "retime", "switch", "replan", "evade")

    def __init__(self, world: World, goal_ned_m, *, settings: ThreatSettings | None = None,
                 limits: TrajectoryLimits | None = None, kappa_max_1_m: float = 0.1,
                 gart_settings: GartSettings | None = None, rng: np.random.Generator | None = None,
                 mode: str = "hybrid", time_scale: float = 1.0, pipeline: TrajectoryPipeline | None = None) -> None:
        self.settings = settings or ThreatSettings()
        if not isinstance(self.settings, ThreatSettings):
            raise ThreatManagerError(f"settings: expected ThreatSettings, got {type(settings).__name__}")
        if mode not in self.MODES:
            raise ThreatManagerError(f"mode: expected one of {', '.join(self.MODES)}, got {mode!r}")
        if not (isinstance(kappa_max_1_m, (int, float)) and math.isfinite(kappa_max_1_m) and kappa_max_1_m > 0):
            raise ThreatManagerError(f"kappa_max_1_m: must be a finite number > 0, got {kappa_max_1_m!r}")
        if not (isinstance(time_scale, (int, float)) and math.isfinite(time_scale) and time_scale > 0):
            raise ThreatManagerError(f"time_scale: must be a finite number > 0, got {time_scale!r}")
        self.mode = mode
        self.time_scale = float(time_scale)
        if pipeline is None:
            pipeline = TrajectoryPipeline.for_limits(limits, float(kappa_max_1_m), gart_settings)
        elif not isinstance(pipeline, TrajectoryPipeline):
            raise ThreatManagerError(f"pipeline: expected a TrajectoryPipeline, got {type(pipeline).__name__}")
        elif limits is not None or gart_settings is not None:
            raise ThreatManagerError("pipeline: give either a pipeline or limits and gart_settings, not both")
        self.pipeline = pipeline
        self.rng = rng if rng is not None else np.random.default_rng(self.settings.seed)
        self.set_leg(world, goal_ned_m)
        self._active: _Active | None = None
        self._alternatives: tuple[Alternative, ...] = ()
        self._estimate = _RunningEstimate(self.settings.replan_budget_s)
        self._fast = _RunningEstimate(FAST_ESTIMATE_S)
        self._counter = 0
        self._replan_blocked_until_s = -math.inf

    # ------------------------------------------------------------------ inputs
    def set_leg(self, world: World, goal_ned_m) -> None:
        """A new leg: its static world and goal (clears nothing else)."""
        if not isinstance(world, World):
            raise ThreatManagerError(f"world: expected a World, got {type(world).__name__}")
        goal = np.asarray(goal_ned_m, dtype=float).reshape(-1)
        if goal.shape != (world.dim,) or not np.all(np.isfinite(goal)):
            raise ThreatManagerError(f"goal_ned_m: expected {world.dim} finite numbers, got {goal_ned_m!r}")
        self.world = world
        self.goal_ned_m = goal
        self._worlds: dict[str, World] = {}

    def set_active(self, trajectory, start_t_s: float, path_id: str = "active", ends_short: bool = False) -> None:
        """The reference being flown: ``trajectory`` with its t = 0 at clock time ``start_t_s``."""
        if not hasattr(trajectory, "sample") or not hasattr(trajectory, "duration_s"):
            raise ThreatManagerError("trajectory: expected an object with sample(t_s) and duration_s")
        if not math.isfinite(start_t_s):
            raise ThreatManagerError(f"start_t_s: must be finite, got {start_t_s!r}")
        self._active = _Active(trajectory, float(start_t_s), str(path_id), bool(ends_short))

    def set_alternatives(self, alternatives) -> None:
        """Replace the switching targets (``Alternative`` or (M, d) paths); one reference swap."""
        alts = []
        for i, alt in enumerate(alternatives):
            if not isinstance(alt, Alternative):
                alt = Alternative.from_path(f"alt{i}", alt, self.settings.entry_spacing_m)
            if alt.path_ned_m.shape[1] != self.world.dim:
                raise ThreatManagerError(f"alternatives[{i}]: dimension {alt.path_ned_m.shape[1]} "
                                         f"does not match the world's {self.world.dim}")
            alts.append(alt)
        self._alternatives = tuple(alts)

    @property
    def alternatives(self) -> tuple[Alternative, ...]:
        return self._alternatives

    @property
    def active_path_id(self) -> str | None:
        return None if self._active is None else self._active.path_id

    @property
    def replan_estimate_s(self) -> float:
        """Current replanning estimate: running mean + 3 mean absolute deviations (s)."""
        return self._estimate.high_s

    def compute_alternatives(self, threats, t_s: float, k: int = 4, *, rng: np.random.Generator,
                             max_time_s: float = 2.0, start_ned_m=None) -> list[Alternative]:
        """M-GART alternatives from the reference (or ``start_ned_m``) to the goal.

        Slow (``max_time_s``): run it in the background, then ``set_alternatives``. Pop-ups are
        obstacles; a mover is placed where the active reference would meet it (its track
        around that time), so alternatives pass it on either side.
        """
        if start_ned_m is None:
            ref = self.reference_state(t_s)
            if ref is None:
                raise ThreatManagerError("start_ned_m: needed when no trajectory is active")
            start_ned_m = ref.pos_ned_m
        start = np.asarray(start_ned_m, dtype=float)[: self.world.dim]
        sit = self._situation(t_s, threats)
        obstacles = [] if sit is None else gen.meeting_obstacles(sit, self._active.trajectory, self._active.start_t_s, [start, self.goal_ned_m])
        world = airspace_for(self.world, [start])
        world = world.with_threats(obstacles) if obstacles else world
        self._counter += 1
        return plan_alternatives(world, start, self.goal_ned_m, k, pipeline=self.pipeline, rng=rng,
                                 max_time_s=max_time_s, spacing_m=self.settings.entry_spacing_m,
                                 airspace=self._airspace([start]), vertical_offsets_m=self.settings.vertical_offsets_m,
                                 tag=f"-{self._counter}")

    # ------------------------------------------------------------------ state
    def reference_state(self, t_s: float) -> ReferenceState | None:
        """Reference of the active trajectory at clock time ``t_s`` (its own dimension)."""
        if self._active is None:
            return None
        a = self._active
        tau = np.array([min(max(t_s - a.start_t_s, 0.0), a.trajectory.duration_s)])
        pos, vel, acc = (np.atleast_2d(v)[0].astype(float) for v in a.trajectory.sample(tau))
        if t_s - a.start_t_s >= a.trajectory.duration_s:
            vel, acc = np.zeros_like(vel), np.zeros_like(acc)
        yaw = float(a.trajectory.yaw_rad(tau)[0]) if hasattr(a.trajectory, "yaw_rad") else 0.0
        return ReferenceState(float(t_s), pos, vel, acc, yaw)

    def _relevant(self, threats, t_s: float, pos: np.ndarray) -> list:
        """Local, unexpired threats within the sensor range of ``pos`` now."""
        d = self.world.dim
        out = []
        for th in threats:
            if th.frame != "local_ned":
                raise ThreatManagerError(f"threat {th.id!r}: convert global threats to local NED "
                                         f"first (ThreatTable(home=...))")
            if th.expires_t_s <= t_s:
                continue
            if float(np.linalg.norm(th.position_at(t_s)[:d] - pos[:d])) - th.radius_m <= self.settings.sensor_range_m:
                out.append(th)
        return out

    def _situation(self, t_s: float, threats) -> gen.Situation | None:
        """Everything the candidates need, from the reference state at ``t_s``."""
        ref = self.reference_state(t_s)
        if ref is None:
            return None
        s = self.settings
        tubes = predict_tubes(self._relevant(threats, t_s, ref.pos_ned_m), inflation_m=s.inflation_m,
                              uncertainty_m_s=s.uncertainty_m_s, uncertainty_max_m=s.uncertainty_max_m)
        lift = float(ref.pos_ned_m[2]) if self.world.dim == 2 and ref.pos_ned_m.shape[0] == 3 else None
        here = [ref.pos_ned_m[: self.world.dim]]
        return gen.Situation(ref, tubes, self._airspace(here), self._slab(here),
                             self.goal_ned_m, s, self.pipeline, lift)

    def _airspace(self, points) -> World:
        """The leg's world with room above and below for escapes and alternatives (cached)."""
        s = self.settings
        return self._cached("airspace", points, lambda: airspace_for(self.world, points, s.vertical_room_m,
                                                                     -s.min_altitude_m))

    def _slab(self, points) -> World:
        """The leg's planning world widened to contain ``points`` (cached)."""
        return self._cached("slab", points, lambda: airspace_for(self.world, points))

    def _cached(self, name: str, points, build) -> World:
        """A widened world, rebuilt only when a point leaves the cached one's down bounds."""
        world = self._worlds.get(name)
        downs = np.atleast_2d(np.asarray(points, dtype=float))[:, -1]
        if world is None or world.dim == 3 and not (
                np.all(downs >= world.bounds_min[2]) and np.all(downs <= world.bounds_max[2])):
            world = self._worlds[name] = build()
        return world

    def check(self, threats, t_s: float) -> Conflict | None:
        """First conflict of the active reference with ``threats`` over the horizon (or None)."""
        sit = self._situation(t_s, threats)
        if sit is None:
            return None
        return self._keep_at(sit).conflict

    def _keep_at(self, sit: gen.Situation) -> Candidate:
        """The active reference as the ``keep`` candidate, judged."""
        a = self._active
        keep = Candidate("none", "keep", a.trajectory, self._remaining_s(sit), a.path_id, ends_short=a.ends_short)
        t = sit.times(sit.settings.check_step_s)
        pos = gen.positions_at(a.trajectory, a.start_t_s, t, sit.dim)
        res = gen.check(sit, t, pos, static=False)          # the static world was checked before
        return keep.judged(res, 0)

    # ------------------------------------------------------------------ the decision
    def on_threats(self, threats, t_s: float) -> Decision:
        """Decide what to do about ``threats`` at clock time ``t_s`` (see the module docstring).

        New candidates start from the active reference's state at the time the decision is
        expected to take effect (``t_s`` plus the measured decision time, in clock seconds:
        ``time_scale``), which the vehicle keeps flying until then: the setpoint never jumps.

        Parameters
        ----------
        threats : sequence of Threat
            Every threat known now, local frame, stamped on the same clock as ``t_s``.
        t_s : float
            Now: the active reference is checked from here.

        Returns
        -------
        Decision
            With a trajectory, the manager has made it its active reference (t = 0 at
            ``start_t_s``); the caller engages it too.
        """
        t0 = time.perf_counter()
        sit = self._situation(t_s, threats)
        if sit is None:
            return Decision("none", "no active trajectory", decide_ms=_ms_since(t0))
        keep = self._keep_at(sit)
        if keep.clear:
            return Decision("none", "the active reference stays clear", decide_ms=_ms_since(t0),
                            resume=self._active.ends_short, min_clearance_m=keep.min_clearance_m)
        ttc = keep.conflict.time_to_conflict_s
        what = f"{keep.conflict.threat_id} in {ttc:.1f} s"
        fast = self._situation(t_s + self._lead_s(self._fast), threats)
        cands = self._fast_candidates(fast)
        continues = any(c.clear and not c.ends_short for c in cands)     # a clear way to the goal
        slow_lead = self._lead_s(self._fast) + self._lead_s(self._estimate)
        stop_s = float(np.linalg.norm(fast.ref.vel_ned_m_s)) / self.settings.evade_accel_m_s2
        urgent = ttc <= slow_lead + stop_s + self.settings.urgency_margin_s
        if self.mode == "replan" or (self.mode == "hybrid" and not continues and not urgent):
            # there is time to replan: plan from where the vehicle will be when it is done
            slow = self._situation(t_s + slow_lead, threats)
            cands = self._replan(slow)
            if self.mode == "hybrid":
                cands += gen.evade_candidates(slow, self._remaining_s(slow))
            return self._finish(slow, keep, cands, what, t0)
        self._fast.update(time.perf_counter() - t0, self.settings.estimate_gain)
        return self._finish(fast, keep, cands, what, t0)

    def resume(self, threats, t_s: float) -> Decision:
        """Plan back to the mission from the active reference (after an evasion or a hold),
        from its state when the measured replanning time has passed."""
        t0 = time.perf_counter()
        sit = self._situation(t_s + self._lead_s(self._estimate), threats)
        if sit is None:
            return Decision("none", "no active trajectory", decide_ms=_ms_since(t0))
        cands = []
        if self.mode in ("hybrid", "switch"):
            cands += gen.switch_to_alternatives(sit, self._alternatives)[0]
        if self.mode != "switch":
            cands += self._replan(sit)
        best = choose([c for c in _sane(cands) if c.clear], self.settings.clearance_weight_s_m,
                      self.settings.clearance_cap_m)
        if best is None:
            return Decision("none", "no clear way back to the mission yet", decide_ms=_ms_since(t0),
                            resume=True, candidates=_counts(cands))
        return self._engage(sit, best, "back to the mission", None, cands, t0)

    def reject(self, error: Exception) -> Decision:
        """The ``rejected`` decision for an invalid threat sample (the flight goes on)."""
        return Decision("rejected", str(error))

    # ------------------------------------------------------------------ internals
    def _lead_s(self, estimate: "_RunningEstimate") -> float:
        """Clock seconds that a decision step is expected to take (mean + 1 deviation)."""
        return (estimate.mean_s + estimate.dev_s) * self.time_scale

    def _remaining_s(self, sit: gen.Situation) -> float:
        """Time left on the active reference from the situation's time (s)."""
        a = self._active
        return max(a.start_t_s + a.trajectory.duration_s - sit.ref.t_s, 0.0)

    def _fast_candidates(self, sit: gen.Situation) -> list[Candidate]:
        """The candidates of milliseconds: evade and hold, retime, switch (by mode)."""
        mode = self.mode
        a = self._active
        remaining = self._remaining_s(sit)
        out: list[Candidate] = []
        if mode in ("hybrid", "evade", "hold"):
            out += gen.evade_candidates(sit, remaining, brake_only=mode == "hold")
        if mode in ("hybrid", "retime"):
            out += gen.retime_candidates(sit, a.trajectory, a.start_t_s, remaining, a.ends_short)
        if mode in ("hybrid", "switch") and not any(c.clear and c.kind == "retime" for c in out):
            out += gen.switch_to_alternatives(sit, self._alternatives)[0]
        return out

    def _replan(self, sit: gen.Situation) -> list[Candidate]:
        """Replan candidates, unless a replan found nothing clear less than
        ``REPLAN_BACKOFF_S`` ago."""
        if sit.ref.t_s < self._replan_blocked_until_s:
            return []
        t0 = time.perf_counter()
        self._counter += 1
        out = gen.replan_candidates(sit, rng=self.rng, path_id=f"replan-{self._counter}")
        self._estimate.update(time.perf_counter() - t0, self.settings.estimate_gain)
        if not any(c.clear for c in out):
            self._replan_blocked_until_s = sit.ref.t_s + REPLAN_BACKOFF_S * self.time_scale
        return out

    def _finish(self, sit, keep: Candidate, cands: list[Candidate], what: str, t0: float) -> Decision:
        s = self.settings
        best = choose(_sane(cands), s.clearance_weight_s_m, s.clearance_cap_m)
        if best is None or (not best.clear and best.min_clearance_m < keep.min_clearance_m + BETTER_BY_M):
            return Decision("none", f"{what}: no candidate better than the active reference",
                            decide_ms=_ms_since(t0), resume=self._active.ends_short, conflict=keep.conflict,
                            candidates=_counts(cands), min_clearance_m=keep.min_clearance_m)
        return self._engage(sit, best, what, keep.conflict, cands, t0)

    def _engage(self, sit, best: Candidate, what: str, conflict, cands, t0: float) -> Decision:
        self._counter += 1
        path_id = best.path_id if best.kind in ("switch", "replan") else f"{best.kind}-{self._counter}"
        self._active = _Active(best.trajectory, sit.ref.t_s, path_id, best.ends_short)
        clear = "clear" if best.clear else f"least intrusion, {best.min_clearance_m:.1f} m"
        decision = Decision(best.kind, f"{what}: {best.label} ({clear})", best.trajectory, sit.ref.t_s,
                            path_id, best.path_ned_m, conflict, plan_ms=_ms_since(t0),
                            resume=best.ends_short, label=best.label, candidates=_counts(cands),
                            min_clearance_m=best.min_clearance_m)
        decision = replace(decision, decide_ms=_ms_since(t0))
        log.info("threat decision %s (%s) path %s: decide %.1f ms", decision.kind, decision.reason,
                 path_id, decision.decide_ms)
        return decision


def _sane(cands) -> list[Candidate]:
    """Candidates with a finite, plausible duration (others are logged and dropped)."""
    out = []
    for c in cands:
        if math.isfinite(c.trajectory.duration_s) and c.trajectory.duration_s <= MAX_DURATION_S:
            out.append(c)
        else:
            log.warning("candidate %s dropped: duration %r s", c.label, c.trajectory.duration_s)
    return out


def _counts(cands) -> dict:
    out: dict[str, int] = {}
    for c in cands:
        out[c.kind] = out.get(c.kind, 0) + 1
    return out


def _ms_since(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3
