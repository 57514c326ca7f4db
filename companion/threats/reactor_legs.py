"""The reactor's legs and alternatives (paper section 3.3): the manager told of each leg and
of every reference the daemon engages; M-GART alternatives refreshed in the background (at
every leg start, after every decision, every ``flight.alternatives_period_s``) from just ahead
of the vehicle; the active path and the alternatives published on ``uav/<sysid>/path``."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from typing import Callable

import numpy as np

from companion.threats.model import ThreatTable

log = logging.getLogger(__name__)


class LegsAndAlternatives:
    """Legs and alternatives of a ``ThreatReactor`` (a part of it: it uses the reactor's table,
    manager, bus, callables and ``schedule``)."""

    settings: object
    table: ThreatTable
    manager: object
    manager_factory: Callable
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
        """The daemon engaged ``ref`` (any reference): the manager checks that one now
        (``ref.resume``: it ends short of the goal on purpose); the other vehicles are told."""
        if self.fleet is not None:
            self.fleet.publish()
        if self.manager is not None:
            self.manager.set_active(ref.trajectory, ref.t0_s, ref.path_id,
                                    ends_short=bool(getattr(ref, "resume", False)))

    def on_leg_started(self, leg, ref) -> None:
        """A leg starts with reference ``ref``: the manager gets its world, goal and reference."""
        if self.manager is None:
            self.manager = self.manager_factory(leg)
        self.manager.set_leg(leg.world, leg.goal_ned_m)
        self.set_active(ref)
        self.manager.set_alternatives([])
        self.leg, self.leg_index = leg, leg.index
        self.publish_path()
        self.refresh_alternatives()
        self.table.expire(self.clock_now_s())
        if self.has_threats():
            self.schedule(time.monotonic(), "monitor")

    def on_leg_ended(self) -> None:
        self.leg = None
        if self.manager is not None:
            self.manager.set_alternatives([])

    def refresh_alternatives(self) -> None:
        """Recompute the M-GART alternatives from the current reference in the background."""
        if self.manager is None or self.leg is None or self.settings.flight.alternatives_k == 0:
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
                leg, t = self.leg, self.clock_now_s()
                if leg is None:
                    break
                threats = self.threats_now(t)
                rng = np.random.default_rng(self.rng.integers(2**63))
                ref = self.reference()
                start = None if ref is None else ref.state(t + f.alternatives_lead_s)[0]
                alternatives = await self.in_worker(
                    self.manager.compute_alternatives, threats, t, f.alternatives_k, rng=rng,
                    max_time_s=f.alternatives_budget_s, start_ned_m=start)
                if leg is self.leg and alternatives:     # none found: keep the previous ones
                    self.manager.set_alternatives(alternatives)
                    self.publish_path()
                    self.record("alternatives", leg=leg.index, t_s=t, paths=[a.path_ned_m for a in alternatives])
                if not self._alt_dirty:
                    break
        except Exception:  # noqa: BLE001 - without alternatives the manager replans or holds
            log.exception("refreshing the alternatives failed")
        finally:
            self._alt_busy = False

    def publish_path(self) -> None:
        """Publish the active reference and the alternatives on ``uav/<sysid>/path``."""
        ref = self.reference()
        if ref is None or self.manager is None:
            return
        t = np.linspace(0.0, ref.trajectory.duration_s, max(2, int(ref.trajectory.duration_s * 2)))
        self.bus.outbound.publish_path({
            "t_s": self.clock_now_s(), "leg": self.leg_index, "path_id": ref.path_id,
            "t0_s": ref.t0_s, "duration_s": ref.trajectory.duration_s,
            "reference_ned_m": ref.trajectory.sample(t)[0],
            "alternatives": [{"path_id": a.path_id, "path_ned_m": a.path_ned_m}
                             for a in self.manager.alternatives]})

    def min_separation_m(self, pos_ned_m: np.ndarray, t_s: float) -> float:
        """Distance from ``pos_ned_m`` to the surface of the nearest threat now (inf if none)."""
        best = math.inf
        for th in self.table.snapshot(t_s):
            best = min(best, float(np.linalg.norm(th.position_at(t_s) - pos_ned_m)) - th.radius_m)
        return best
