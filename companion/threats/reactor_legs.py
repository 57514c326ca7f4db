"""The reactor's legs and alternatives (paper section 3.3): each leg's ``LegContext`` (its world
and goal), the other vehicles told of every reference the daemon engages; M-GART alternatives
refreshed in the background (at every leg start, after every decision, every
``flight.alternatives_period_s``) from just ahead of the vehicle, unless the refresh could not
change anything (``AlternativesGate``); the active path and the alternatives published on
``uav/<sysid>/path``."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from companion.threats.decision.step import (DecisionPolicy, DecisionState, LegContext,
                                             plan_alternatives_for)
from companion.threats.model import ThreatTable

log = logging.getLogger(__name__)


class AlternativesGate:
    """Whether an M-GART refresh could change anything.

    With no threat held, the alternatives depend only on the leg (world, goal) and the active
    reference; the periodic refresh (every ``flight.alternatives_period_s``) would search the
    same static world again and again. The caller builds a key for each refresh (leg, world
    and active path id with no threat held; None with threats) and asks ``should_run``: a key
    equal to the one it ``remember``-ed after the last refresh that found alternatives is
    skipped (the previous alternatives stay). Every other refresh runs.
    """

    def __init__(self) -> None:
        self._last_key: tuple | None = None
        self.skipped = 0

    def should_run(self, key: tuple | None) -> bool:
        """False (and counted in ``skipped``) for the key of the last refresh that found some."""
        if key is not None and key == self._last_key:
            self.skipped += 1
            return False
        self._last_key = None
        return True

    def remember(self, key: tuple | None) -> None:
        """The refresh of ``key`` ran and found alternatives (None: it found none, or threats
        were held)."""
        self._last_key = key


class LegsAndAlternatives:
    """Legs and alternatives of a ``ThreatReactor`` (a part of it: it uses the reactor's table,
    policy, decision state, bus, callables and ``schedule``)."""

    settings: object
    table: ThreatTable
    policy: DecisionPolicy
    decision_state: DecisionState | None
    leg_context: LegContext | None
    alternatives_gate: AlternativesGate
    observation: Callable
    leg: object
    leg_index: int
    fleet: object
    threats_now: Callable
    has_threats: Callable
    rng: np.random.Generator
    pause: Callable
    clock_now_s: Callable[[], float]
    in_worker: Callable
    reference: Callable
    record: Callable
    _alt_busy: bool
    _alt_dirty: bool

    def set_active(self, ref) -> None:
        """The daemon engaged ``ref`` (any reference): the other vehicles are told (the next
        decision observes it through ``reference()``)."""
        if self.fleet is not None:
            self.fleet.publish()

    def on_leg_started(self, leg, ref) -> None:
        """A leg starts with reference ``ref``: its world and goal become the ``LegContext``; the
        alternatives of the previous leg go (the first leg draws the decision state's seed)."""
        if self.decision_state is None:
            self.decision_state = DecisionState.initial(self.policy, int(self.rng.integers(2**63)))
        self.leg_context = LegContext(leg.index, leg.world, leg.goal_ned_m)
        self.decision_state = self.decision_state.with_alternatives(())
        self.set_active(ref)
        self.leg, self.leg_index = leg, leg.index
        self.publish_path()
        self.refresh_alternatives()
        self.table.expire(self.clock_now_s())
        if self.has_threats():
            self.schedule(time.monotonic(), "monitor")

    def on_leg_ended(self) -> None:
        self.leg = self.leg_context = None
        if self.decision_state is not None:
            self.decision_state = self.decision_state.with_alternatives(())

    def refresh_alternatives(self) -> None:
        """Recompute the M-GART alternatives from the current reference in the background."""
        if self.leg_context is None or self.leg is None or self.settings.flight.alternatives_k == 0:
            return
        if self._alt_busy:
            self._alt_dirty = True
            return
        self._alt_busy = True
        asyncio.get_running_loop().create_task(self._alternatives_loop(), name="alternatives")

    async def _refresh_alternatives_periodically(self) -> None:
        """Keep the alternatives starting just ahead of the vehicle."""
        s = self.settings
        while True:
            await self.pause(s.flight.alternatives_period_s / s.link.time_scale)
            self.refresh_alternatives()

    async def _alternatives_loop(self) -> None:
        f = self.settings.flight
        try:
            while True:
                self._alt_dirty = False
                leg, leg_context, t = self.leg, self.leg_context, self.clock_now_s()
                if leg is None:
                    break
                obs = self.observation(t)
                ref = self.reference()
                key = None if obs.threats or ref is None else (leg.index, leg_context.world_key, ref.path_id)
                if self.alternatives_gate.should_run(key):
                    start = None if ref is None else ref.state(t + f.alternatives_lead_s)[0]
                    alternatives, state = await self.in_worker(
                        plan_alternatives_for, self.decision_state, obs, leg_context, self.policy,
                        f.alternatives_k, max_time_s=f.alternatives_budget_s, start_ned_m=start)
                    self.alternatives_gate.remember(key if alternatives else None)
                    if leg is self.leg:
                        self._adopt_alternatives(state, alternatives)
                    if leg is self.leg and alternatives:     # none found: keep the previous ones
                        self.publish_path()
                        self.record("alternatives", leg=leg.index, t_s=t,
                                    paths=[a.path_ned_m for a in alternatives])
                if not self._alt_dirty:
                    break
        except Exception:  # noqa: BLE001 - without alternatives the decision replans or holds
            log.exception("refreshing the alternatives failed")
        finally:
            self._alt_busy = False

    def _adopt_alternatives(self, returned: DecisionState, alternatives) -> None:
        """The search's counter (the larger: a decision may have advanced it meanwhile) and its
        alternatives, when it found some, in the current state (a decision's estimates are kept)."""
        current = self.decision_state
        current = replace(current, counter=max(current.counter, returned.counter))
        self.decision_state = current.with_alternatives(alternatives, dim=self.leg_context.world.dim) \
            if alternatives else current

    def publish_path(self) -> None:
        """Publish the active reference and the alternatives on ``uav/<sysid>/path``."""
        ref = self.reference()
        if ref is None or self.decision_state is None:
            return
        t = np.linspace(0.0, ref.trajectory.duration_s, max(2, int(ref.trajectory.duration_s * 2)))
        self.bus.publish_path({
            "t_s": self.clock_now_s(), "leg": self.leg_index, "path_id": ref.path_id,
            "t0_s": ref.t0_s, "duration_s": ref.trajectory.duration_s,
            "reference_ned_m": ref.trajectory.sample(t)[0],
            "alternatives": [{"path_id": a.path_id, "path_ned_m": a.path_ned_m}
                             for a in self.decision_state.alternatives]})

    def min_separation_m(self, pos_ned_m: np.ndarray, t_s: float) -> float:
        """Distance from ``pos_ned_m`` to the surface of the nearest threat now (inf if none)."""
        best = math.inf
        for th in self.table.snapshot(t_s):
            best = min(best, float(np.linalg.norm(th.position_at(t_s) - pos_ned_m)) - th.radius_m)
        return best
