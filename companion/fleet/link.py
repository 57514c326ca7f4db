"""The fleet's zenoh side: this vehicle's trajectory out, the others' in (DESIGN 6).

``FleetLink`` publishes the committed trajectory (the active reference, ``horizon_s`` of it
every ``sample_step_s``; a hover at the vehicle's position when there is none) on
``uav/<sysid>/trajectory`` every ``publish_period_s`` (``publish``: a task of the flight
executor's schedule) and at every change, and subscribes to
``uav/*/trajectory``: each sample is decoded on the zenoh thread into the ``PeerTable`` (a bad
one is counted and logged, never fatal). ``delay_check`` is RMADER's wait before a new
trajectory is flown (``companion.fleet.commit``); ``FleetCommitGate`` puts it before the
executor engages a decision. ``fleet.inject_delay_s`` holds every message
that long before it is put (testing the delay check). I/O only: the numbers are in ``peers``,
``commit`` and ``message``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import time
from collections.abc import Callable

import numpy as np

from companion.errors import ThreatPayloadError
from companion.fleet import commit
from companion.fleet.message import SampledPath, TrajectoryMessage, decode, encode
from companion.fleet.peers import PeerTable
from companion.fleet.settings import FleetSettings

__all__ = ["FleetLink", "FleetCommitGate", "ReferenceGrid", "sample_reference"]

log = logging.getLogger(__name__)

#: Extra wait of the delay check beyond the largest measured delay (wall s).
DELAY_MARGIN_S = 0.05
#: At most one log line about bad trajectory messages per this many seconds.
BAD_LOG_PERIOD_S = 5.0


class ReferenceGrid:
    """A reference's positions every ``step_s`` of its own time from its start, to its end
    point: evaluated once per reference (a Bezier evaluation of a whole horizon at every
    publication was most of the fleet's cost), sliced at each publication."""

    def __init__(self, step_s: float) -> None:
        self.step_s = float(step_s)
        self._of: tuple | None = None  # (trajectory, t0_s) the positions are of
        self._ned_m = np.zeros((0, 3))

    def positions(self, ref) -> np.ndarray:
        """``ref.trajectory`` at ``min(k * step_s, duration)``, k = 0 .. ceil(duration / step_s); (K, 3)."""
        if self._of is None or self._of[0] is not ref.trajectory or self._of[1] != ref.t0_s:
            duration_s = ref.trajectory.duration_s
            tau = np.minimum(self.step_s * np.arange(math.ceil(duration_s / self.step_s) + 1), duration_s)
            self._ned_m = np.atleast_2d(ref.trajectory.sample(tau)[0])
            self._of = (ref.trajectory, ref.t0_s)
        return self._ned_m


def sample_reference(
    ref, now_t_s: float, settings: FleetSettings, hover_ned_m=None, grid: ReferenceGrid | None = None
) -> SampledPath:
    """``ref`` (an active reference, or None: a hover at ``hover_ned_m``) over the published
    horizon, on its own grid (``grid``, kept by the caller between publications): from the last
    grid time at or before ``now_t_s``; before its start, its start point; after its end, its end
    point."""
    step_s = settings.sample_step_s
    if ref is None:
        return SampledPath("hover", now_t_s, step_s, np.atleast_2d(np.asarray(hover_ned_m, float)))
    ned_m = (grid or ReferenceGrid(step_s)).positions(ref)
    first = math.floor((now_t_s - ref.t0_s) / step_s)
    first -= ref.t0_s + first * step_s > now_t_s  # rounding: the first is never after now
    last = max(min(first + int(settings.horizon_s / step_s), len(ned_m) - 1), first)
    rows = np.clip(np.arange(first, last + 1), 0, len(ned_m) - 1)
    return SampledPath(ref.path_id, ref.t0_s + first * step_s, step_s, ned_m[rows])


class FleetLink:
    """This vehicle among the others (see the module docstring).

    Parameters
    ----------
    settings : companion.config.Settings
        Uses ``fleet``, ``threats`` (horizon, step, inflation) and ``link.time_scale``.
    session : zenoh.Session
    sysid : int
    home_lla : tuple
    clock_now_s : callable () -> float
        Our mission time.
    reference, position_ned_m : callable
        The active reference (or None) and the vehicle's position (or None).
    """

    def __init__(
        self,
        settings,
        session,
        sysid: int,
        home_lla,
        *,
        clock_now_s: Callable[[], float],
        reference: Callable,
        position_ned_m: Callable,
    ) -> None:
        self.settings = settings
        self.fleet: FleetSettings = settings.fleet
        self.session = session
        self.sysid = sysid
        self.home_lla = tuple(float(v) for v in home_lla)
        self.clock_now_s = clock_now_s
        self.reference = reference
        self.position_ned_m = position_ned_m
        self.peers = PeerTable(sysid, self.fleet, self.home_lla)
        self.pending: SampledPath | None = None
        self.counts = {"published": 0, "rejected": 0, "delay_checks": 0, "refused": 0}
        self.delay_checks_ms: list[float] = []
        self._seq = 0
        self._loop = None
        self._publisher = None
        self._subscriber = None
        self._bad_logged_s = -float("inf")
        self._grid = ReferenceGrid(self.fleet.sample_step_s)
        self._own_key = f"uav/{sysid}/trajectory"

    # ------------------------------------------------------------------ lifecycle
    def start(self, loop) -> None:
        self._loop = loop
        self._publisher = self.session.declare_publisher(self._own_key)
        self._subscriber = self.session.declare_subscriber("uav/*/trajectory", self._on_sample)
        log.info(
            "fleet: sharing uav/%d/trajectory, avoiding uav/*/trajectory (every %.1f s%s)",
            self.sysid,
            self.fleet.publish_period_s,
            f", {self.fleet.inject_delay_s * 1000:.0f} ms injected delay" if self.fleet.inject_delay_s else "",
        )

    async def stop(self) -> None:
        for ent in (self._subscriber, self._publisher):
            try:
                if ent is not None:
                    ent.undeclare()
            except Exception as exc:  # noqa: BLE001 - the session is closing
                log.debug("undeclare: %s", exc)
        self._subscriber = self._publisher = None

    # ------------------------------------------------------------------ in
    def _on_sample(self, sample) -> None:
        """zenoh thread: decode and keep (a bad message is counted, the flight goes on); our
        own messages come back too and are not decoded."""
        received = time.time()
        if str(sample.key_expr) == self._own_key:
            return
        try:
            self.peers.receive(decode(sample.payload.to_bytes()), received)
        except ThreatPayloadError as exc:
            self.counts["rejected"] += 1
            if received - self._bad_logged_s > BAD_LOG_PERIOD_S:
                self._bad_logged_s = received
                log.warning("trajectory message on %s rejected: %s", sample.key_expr, exc)

    def threats(self, t_s: float) -> list:
        """The other vehicles as threats at our mission time ``t_s``."""
        return self.peers.threats(t_s, time.time(), self.settings.link.time_scale or 1.0)

    # ------------------------------------------------------------------ out
    def publish(self) -> None:
        """Publish what we fly (and the pending trajectory), now or after the injected delay."""
        if self._publisher is None:
            return
        now = self.clock_now_s()
        pos = self.position_ned_m()
        ref = self.reference()
        if ref is None and pos is None:
            return
        self._seq += 1
        msg = TrajectoryMessage(
            self.sysid,
            self._seq,
            self.fleet.rotor_radius_m,
            self.home_lla,
            now,
            time.time(),
            float(self.settings.link.time_scale or 1.0),
            0.0,
            sample_reference(ref, now, self.fleet, pos, self._grid),
            self.pending,
        )
        if self.fleet.inject_delay_s > 0:
            self._loop.call_later(self.fleet.inject_delay_s, self._put, msg)
        else:
            self._put(msg)

    def _put(self, msg: TrajectoryMessage) -> None:
        if self._publisher is None:
            return
        msg = dataclasses.replace(msg, sent_unix_s=time.time(), echo=self.peers.echo())
        self._publisher.put(encode(msg))
        self.counts["published"] += 1

    # ------------------------------------------------------------------ commit
    async def delay_check(self, trajectory, start_t_s: float, path_id: str) -> bool:
        """RMADER's delay check of a new trajectory: True to fly it, False to keep the current one.

        Without other vehicles it is flown at once. Otherwise it is published as pending, and
        checked again after ``max(fleet.delay_check_s, largest measured delay + 50 ms)``.
        """
        if not len(self.peers):
            return True
        th = self.settings.threats
        t0 = time.monotonic()

        def check():
            now = self.clock_now_s()
            return commit.fleet_check(
                trajectory,
                start_t_s,
                now,
                self.threats(now),
                horizon_s=th.horizon_s,
                step_s=th.check_step_s,
                inflation_m=th.inflation_m,
            )

        before = check()
        now = self.clock_now_s()
        self.pending = sample_reference(_Ref(trajectory, start_t_s, path_id), max(now, start_t_s), self.fleet)
        self.publish()
        wait_s = max(self.fleet.delay_check_s, self.peers.max_delay_s() + DELAY_MARGIN_S)
        try:
            await asyncio.sleep(wait_s)
            after = check()
        finally:
            self.pending = None
        refused = commit.refuses(before, after)
        self.counts["delay_checks"] += 1
        self.counts["refused"] += int(refused)
        self.delay_checks_ms.append((time.monotonic() - t0) * 1000.0)
        if refused:
            conflict = after.conflicts[0]
            log.warning(
                "fleet: delay check refused %s: %s within %.1f s (waited %.0f ms)",
                path_id,
                conflict.threat_id if conflict else "?",
                conflict.time_to_conflict_s if conflict else -1,
                wait_s * 1000,
            )
            self.publish()  # the pending one is withdrawn
        return not refused

    def summary(self) -> dict:
        """Counts, the delay checks' durations and what is known of each other vehicle."""
        d = self.delay_checks_ms
        return {
            **self.counts,
            "peers": self.peers.summary(time.time()),
            "delay_check_ms_max": round(max(d), 1) if d else None,
            "delay_check_ms_median": round(float(np.median(d)), 1) if d else None,
        }


class FleetCommitGate:
    """The executor's ``CommitGate`` (``companion.flight.avoidance``): a decision is engaged
    only after ``FleetLink.delay_check`` says its trajectory still clears the others."""

    def __init__(self, fleet: FleetLink, loop: asyncio.AbstractEventLoop) -> None:
        self.fleet = fleet
        self.loop = loop

    def check(self, decision, proceed: Callable[[], None]) -> None:
        async def checked() -> None:
            if await self.fleet.delay_check(decision.trajectory, decision.start_t_s, decision.path_id):
                proceed()

        self.loop.create_task(checked(), name="fleet-delay-check")


@dataclasses.dataclass(frozen=True)
class _Ref:
    """A trajectory from ``t0_s`` (what ``sample_reference`` needs of a reference)."""

    trajectory: object
    t0_s: float
    path_id: str
