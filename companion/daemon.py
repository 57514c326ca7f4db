"""The companion service: a mission in, a planned, smoothed and tracked flight out (DESIGN 1, 6, 7).

``CompanionDaemon.run()`` is the whole flight:

1. connect to the vehicle (MAVSDK), wait for telemetry and home;
2. take the mission: the file given (validated, planned, then uploaded so that every ground
   station shows it) or the one stored on the vehicle (a mission uploaded by any ground station
   gets flown);
3. convert it to local NED and a world (exclusion zones, inclusion fence, world file) and plan
   every leg before takeoff (GART -> G2/G1 -> speed profile, ``companion.flight_plan``): an
   unreachable waypoint is an error before anything moves;
4. GUIDED, arm, take off; stream the reference at 50 Hz (``SetpointStreamer``) leg after leg,
   each leg done when its trajectory has ended and the vehicle is within the acceptance radius,
   then the hold time;
5. land or RTL as the mission says (RTL is flown as a planned leg home, then LAND).

Around it: zenoh status at 2 Hz and on every event, the threat manager (``companion.threats``)
whose decisions swap the active reference, the flight record, link-loss handling (keep
streaming; when the link returns, hold and replan the leg from where the vehicle is), a pilot
taking over (mode changed away from GUIDED: the companion stops commanding and ends the flight),
and SIGINT/SIGTERM (hold, land or RTL per ``link.on_interrupt``, then exit).

Only this module, ``companion.link`` and ``companion.threats.bus`` do I/O. The event-loop
thread that streams setpoints runs at real-time priority when allowed
(``raise_stream_priority``); planning, threat decisions and M-GART refreshes run in worker
threads at normal priority, and a short GIL switch interval hands the GIL back to the stream
within half a millisecond, so the 50 Hz period holds while a replan runs.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import math
import sys
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from companion.config import Settings, settings_to_dict
from companion.errors import CompanionError, LinkError, MissionError
from companion.flight_plan import LegPlan, plan_leg, plan_mission
from companion.link.setpoints import (Setpoint, SetpointStreamer, hold_position,
                                      raise_stream_priority, restore_normal_priority)
from companion.link.vehicle import VehicleLink
from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.geo import LocalFrame
from companion.record import FlightRecorder
from companion.threats.bus import ThreatBus, ThreatUpdate, rejected_event
from companion.threats.manager import Decision, ThreatManager
from companion.threats.model import ThreatTable
from companion.world import world_to_dict

log = logging.getLogger(__name__)

GUIDED = 4
#: A reference that stopped short of its leg's goal (a hold) is continued after this long (s).
RESUME_AFTER_S = 2.0
#: GIL switch interval (s): a planning thread hands the GIL to the setpoint stream this often.
GIL_SWITCH_INTERVAL_S = 0.0005


class FlightAborted(CompanionError):
    """The flight cannot go on (pilot took over, vehicle disarmed, leg not reached)."""


class VehicleClock:
    """Mission time in the vehicle's seconds, extrapolated between its timestamped messages.

    The vehicle stamps LOCAL_POSITION_NED with ``time_boot_ms`` (simulated time in
    ``sim-vehicle``). With ``scale`` vehicle seconds per wall-clock second, every message gives
    a lower bound ``boot_s - scale * arrival`` of the offset between the two clocks (transport
    only delays); the largest over the last ``window_s`` is the estimate. Without messages the
    clock runs at ``scale`` from its creation. The output never goes backwards.
    """

    def __init__(self, scale: float, window_s: float = 2.0):
        self.scale = float(scale)
        self.window_s = window_s
        self._t0 = time.monotonic()
        self._offsets: deque[tuple[float, float]] = deque()
        self._offset: float | None = None
        self._last = -math.inf

    def observe(self, boot_s: float, arrival_monotonic_s: float) -> None:
        if self._offset is None:
            self._last = -math.inf       # switch from the free-running clock to vehicle time
        self._offsets.append((arrival_monotonic_s, boot_s - self.scale * arrival_monotonic_s))
        while self._offsets and self._offsets[0][0] < arrival_monotonic_s - self.window_s:
            self._offsets.popleft()
        self._offset = max(o for _, o in self._offsets)

    def now_s(self, monotonic_s: float | None = None) -> float:
        mono = time.monotonic() if monotonic_s is None else monotonic_s
        if self._offset is None:
            t = self.scale * (mono - self._t0)
        else:
            t = self.scale * mono + self._offset
        self._last = max(self._last, t)
        return self._last


class ActiveReference:
    """A trajectory flown from mission time ``t0_s``; after its end it holds the end point.

    With ``turn_from_yaw_rad`` the vehicle first turns on the spot at the trajectory's start,
    from that heading to the trajectory's initial heading at ``turn_rate_rad_s``, and the
    trajectory starts when the turn is done (a leg that starts at rest in a new direction).
    ``first_sent_monotonic_s`` is set when the stream first samples it (latency measurement).
    """

    def __init__(self, trajectory, t0_s: float, clock: VehicleClock, path_id: str, *,
                 turn_from_yaw_rad: float | None = None, turn_rate_rad_s: float = 0.6):
        self.trajectory = trajectory
        self.clock = clock
        self.path_id = path_id
        self.first_sent_monotonic_s: float | None = None
        self.turn_from_yaw_rad = turn_from_yaw_rad
        self.turn_rate_rad_s = 0.0
        turn_s = 0.0
        if turn_from_yaw_rad is not None:
            turn = wrap_pi(float(trajectory.yaw_rad(np.array([0.0]))[0]) - turn_from_yaw_rad)
            turn_s = abs(turn) / turn_rate_rad_s
            self.turn_rate_rad_s = math.copysign(turn_rate_rad_s, turn)
        self.turn_start_s = t0_s
        self.t0_s = t0_s + turn_s
        self.t_end_s = self.t0_s + trajectory.duration_s

    def state(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Position, velocity, acceleration (NED), yaw and yaw rate at mission time ``t_s``."""
        tau = min(max(t_s - self.t0_s, 0.0), self.trajectory.duration_s)
        at = np.array([tau])
        pos, vel, acc = (v[0] for v in self.trajectory.sample(at))
        if t_s < self.t0_s and self.turn_from_yaw_rad is not None:
            yaw = self.turn_from_yaw_rad + self.turn_rate_rad_s * max(t_s - self.turn_start_s, 0.0)
            return pos, np.zeros(3), np.zeros(3), wrap_pi(yaw), self.turn_rate_rad_s
        yaw = float(self.trajectory.yaw_rad(at)[0])
        if t_s >= self.t_end_s:
            return pos, np.zeros(3), np.zeros(3), yaw, 0.0
        return pos, vel, acc, yaw, float(self.trajectory.yaw_rate_rad_s(at)[0])

    def setpoint_at(self, monotonic_s: float) -> Setpoint:
        """The setpoint streamed at ``monotonic_s`` (the yaw rate as feed-forward)."""
        if self.first_sent_monotonic_s is None:
            self.first_sent_monotonic_s = monotonic_s
        return Setpoint(*self.state(self.clock.now_s(monotonic_s)))

    def finished(self, t_s: float) -> bool:
        return t_s >= self.t_end_s


def wrap_pi(angle_rad: float) -> float:
    """``angle_rad`` wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


class ThreatReactor:
    """The daemon's side of threat management (DESIGN sections 6 and 7).

    zenoh samples arrive on the event loop (``ThreatBus.subscribe(loop=...)``); every PUT or
    DELETE updates the ``ThreatTable`` and asks the ``ThreatManager`` (in a worker thread, one
    decision at a time; updates that arrive meanwhile are folded into the next decision, the
    newest state always wins) whether the remaining reference conflicts. A decision's trajectory
    becomes the active reference from the manager's start time, so the setpoint does not jump;
    its latency is measured from the threat's receipt on the zenoh thread to the first setpoint
    of the new trajectory handed to the vehicle link. M-GART alternatives are refreshed in the
    background at every leg start, after every decision and every ``alternatives_period_s``,
    from the reference ``alternatives_lead_s`` ahead (entry nodes the vehicle can still reach).
    """

    def __init__(self, daemon: "CompanionDaemon"):
        self.daemon = daemon
        s = daemon.settings
        self.bus = ThreatBus.from_settings(s.zenoh, clock=daemon.clock.now_s)
        self.table = ThreatTable()
        self.manager: ThreatManager | None = None
        self.leg: LegPlan | None = None
        self._busy = False
        self._pending_receipt: float | None = None
        self._alt_busy = False
        self._alt_dirty = False
        self.latencies_ms: dict[str, list[float]] = {}

    async def start(self, home_lla) -> None:
        self.table.set_home(LocalFrame(*home_lla))
        self.bus.open()
        self.bus.subscribe(self.on_update, loop=asyncio.get_running_loop())
        self.bus.serve_threats(lambda: self.table.snapshot(self.daemon.clock.now_s()))

    async def stop(self) -> None:
        self.bus.close()

    def publish_status(self, status: dict) -> None:
        self.table.expire(self.daemon.clock.now_s())
        status["threats"] = len(self.table)
        self.bus.publish_status(status)

    # ------------------------------------------------------------------ threats in
    def on_update(self, update: ThreatUpdate) -> None:
        """One zenoh sample (on the loop): store it, then decide."""
        d = self.daemon
        if update.action == "rejected":
            self.reject(rejected_event(update))
            return
        if update.action == "delete":
            known = self.table.delete(update.threat_id)
            d.record("threat", id=update.threat_id, removed=True, known=known, t_s=update.received_t_s)
            log.info("threat %s removed%s", update.threat_id, "" if known else " (was not known)")
        else:
            try:
                self.table.put(update.threat)
            except CompanionError as exc:           # e.g. a global threat before home
                self.reject({"event": "rejected", "threat_id": update.threat_id,
                             "field": getattr(exc, "field", "payload"), "reason": str(exc)})
                return
            th = self.table.get(update.threat_id)
            d.record("threat", id=th.id, kind=th.kind, position_ned_m=th.pos_ned_m,
                     velocity_ned_m_s=th.velocity_ned_m_s, radius_m=th.radius_m,
                     t_s=update.received_t_s)
        self.schedule(update.received_mono_s)

    def reject(self, event: dict) -> None:
        d = self.daemon
        event = {**event, "t_s": d.clock.now_s()}
        log.warning("threat rejected: %s", event.get("reason"))
        self.bus.publish_event(event)
        d.record("decision", kind="rejected", reason=event.get("reason"), t_s=event["t_s"],
                 field=event.get("field"), threat_id=event.get("threat_id"))

    async def resume(self) -> None:
        """Ask the manager to plan on from a hold (unless a decision is under way)."""
        if self.manager is None or self._busy:
            await asyncio.sleep(0.05)
            return
        self._busy = True
        await self._decide_loop(time.monotonic(), resume=True)

    def schedule(self, receipt_mono_s: float) -> None:
        """Decide now, or right after the decision under way (with the newest threats)."""
        if self.manager is None:
            return                      # not in a leg: checked when the next leg starts
        if self._busy:
            if self._pending_receipt is None:
                self._pending_receipt = receipt_mono_s
            return
        self._busy = True
        asyncio.get_running_loop().create_task(self._decide_loop(receipt_mono_s), name="threat-decision")

    async def _decide_loop(self, receipt_mono_s: float, resume: bool = False) -> None:
        try:
            while True:
                leg = self.leg
                t = self.daemon.clock.now_s()
                self.table.expire(t)
                decide = self.manager.resume if resume else self.manager.on_threats
                resume = False
                decision = await self.daemon.in_worker(decide, self.table.snapshot(t), t)
                if leg is self.leg:
                    await self.apply(decision, receipt_mono_s)
                if self._pending_receipt is not None:
                    receipt_mono_s, self._pending_receipt = self._pending_receipt, None
                elif decision.resume:
                    await asyncio.sleep(max(0.1, 0.5 / self.daemon.settings.link.time_scale))
                    receipt_mono_s = time.monotonic()
                else:
                    break
        except Exception:  # noqa: BLE001 - a failed decision must not stop the flight
            log.exception("threat decision failed; the current reference is kept")
        finally:
            self._busy = False

    async def apply(self, decision: Decision, receipt_mono_s: float) -> None:
        """Engage the decision's trajectory, measure its latency, publish and record it."""
        if decision.kind == "none":
            log.debug("threat check: %s (%.1f ms)", decision.reason, decision.decide_ms)
            return
        d = self.daemon
        latency_ms = None
        if decision.trajectory is not None:
            ref = d.engage(decision.trajectory, decision.path_id, t0_s=decision.start_t_s)
            d.streamer.send_now()
            deadline = time.monotonic() + 1.0
            while ref.first_sent_monotonic_s is None and time.monotonic() < deadline:
                await asyncio.sleep(0.001)
            if ref.first_sent_monotonic_s is not None:
                latency_ms = (ref.first_sent_monotonic_s - receipt_mono_s) * 1000.0
                self.latencies_ms.setdefault(decision.kind, []).append(latency_ms)
        pos = d.link.telemetry.pos_ned_m
        event = {**decision.as_event(), "latency_ms": latency_ms, "t_s": d.clock.now_s(),
                 "pos_ned_m": pos, "leg": d.leg_index}
        d.summary.decisions += 1
        log.warning("decision %s: %s (latency %s ms, decide %.1f ms, plan %.1f ms, seed %d)",
                    decision.kind, decision.reason,
                    "n/a" if latency_ms is None else f"{latency_ms:.1f}", decision.decide_ms,
                    decision.plan_ms, d.settings.seed)
        self.bus.publish_event(event)
        d.record("decision", kind=decision.kind, path_ned_m=decision.path_ned_m, **event)
        self.publish_path()
        self.refresh_alternatives()

    # ------------------------------------------------------------------ legs and alternatives
    def on_leg_started(self, leg: LegPlan, ref: ActiveReference) -> None:
        s = self.daemon.settings
        if self.manager is None:
            self.manager = ThreatManager(leg.world, leg.goal_ned_m, settings=s.threats,
                                         limits=s.smoothing.limits,
                                         kappa_max_1_m=s.smoothing.kappa_max_1_m,
                                         gart_settings=s.gart, rng=self.daemon.rng)
        self.manager.set_leg(leg.world, leg.goal_ned_m)
        self.manager.set_active(leg.trajectory, ref.t0_s, ref.path_id)
        self.manager.set_alternatives([])
        self.leg = leg
        self.publish_path()
        self.refresh_alternatives()
        if len(self.table):
            self.schedule(time.monotonic())

    def on_leg_ended(self) -> None:
        self.leg = None
        if self.manager is not None:
            self.manager.set_alternatives([])

    def refresh_alternatives(self) -> None:
        """Recompute the M-GART alternatives from the current reference in the background."""
        if self.manager is None or self.leg is None or self.daemon.settings.flight.alternatives_k == 0:
            return
        if self._alt_busy:
            self._alt_dirty = True
            return
        self._alt_busy = True
        asyncio.get_running_loop().create_task(self._alternatives_loop(), name="alternatives")

    async def _alternatives_loop(self) -> None:
        f = self.daemon.settings.flight
        try:
            while True:
                self._alt_dirty = False
                leg, t = self.leg, self.daemon.clock.now_s()
                if leg is None:
                    break
                threats = self.table.snapshot(t)
                rng = np.random.default_rng(self.daemon.rng.integers(2**63))
                ref = self.daemon.reference
                start = None if ref is None else ref.state(t + f.alternatives_lead_s)[0]
                alternatives = await self.daemon.in_worker(
                    self.manager.compute_alternatives, threats, t, f.alternatives_k, rng=rng,
                    max_time_s=f.alternatives_budget_s, start_ned_m=start)
                if leg is self.leg and alternatives:     # none found: keep the previous ones
                    self.manager.set_alternatives(alternatives)
                    self.publish_path()
                    self.daemon.record("alternatives", leg=leg.index, t_s=t,
                                       paths=[a.path_ned_m for a in alternatives])
                if not self._alt_dirty:
                    break
        except Exception:  # noqa: BLE001 - without alternatives the manager replans or holds
            log.exception("refreshing the alternatives failed")
        finally:
            self._alt_busy = False

    def publish_path(self) -> None:
        ref = self.daemon.reference
        if ref is None or self.manager is None:
            return
        t = np.linspace(0.0, ref.trajectory.duration_s, max(2, int(ref.trajectory.duration_s * 2)))
        self.bus.publish_path({
            "t_s": self.daemon.clock.now_s(), "leg": self.daemon.leg_index, "path_id": ref.path_id,
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


@dataclass
class FlightSummary:
    """What ``run`` returns and prints."""

    legs_planned: int = 0
    legs_reached: int = 0
    landed: bool = False
    rms_tracking_error_m: float = math.nan
    max_tracking_error_m: float = math.nan
    decisions: int = 0
    min_threat_separation_m: float = math.inf
    latency_ms: dict = field(default_factory=dict)
    threat_updates: int = 0
    outcome: str = "not flown"

    def as_dict(self) -> dict:
        """Plain data; an infinite separation (no threat met) is None."""
        out = dict(self.__dict__)
        if not math.isfinite(out["min_threat_separation_m"]):
            out["min_threat_separation_m"] = None
        return out


class CompanionDaemon:
    """The companion service for one vehicle (see the module docstring).

    Parameters
    ----------
    settings : Settings
    mission_path : path, optional
        A ``.plan`` or ``QGC WPL 110`` file to fly (uploaded to the vehicle first). Without it
        the vehicle's stored mission and fence are flown.
    world_path : path, optional
        A world file whose obstacles are added to the mission's exclusion zones.
    record_path : path, optional
        Where to write the flight record (JSON Lines).
    """

    def __init__(self, settings: Settings, *, mission_path=None, world_path=None,
                 record_path=None):
        self.settings = settings
        self.mission_path = mission_path
        self.world_path = world_path
        self.record_path = record_path
        self.rng = np.random.default_rng(settings.seed)
        self.link = VehicleLink("companion")
        self.clock = VehicleClock(settings.link.time_scale)
        self.streamer: SetpointStreamer | None = None
        self.reference: ActiveReference | None = None
        self.recorder: FlightRecorder | None = None
        self.summary = FlightSummary()
        self.local_mission = None
        self.legs: list[LegPlan] = []
        self.leg_index = -1
        self.threats: ThreatReactor | None = None      # when zenoh is enabled
        self._errors_m: list[float] = []
        self._servo_us: list[float] | None = None
        self._tasks: list[asyncio.Task] = []
        self._link_lost_at: float | None = None
        self._resume_needed = False
        self._last_resume_t_s = -math.inf
        self._executor = ThreadPoolExecutor(2, thread_name_prefix="planning",
                                            initializer=restore_normal_priority)

    async def in_worker(self, fn, /, *args, **kwargs):
        """Run ``fn(*args, **kwargs)`` in a planning thread (normal priority)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._executor, functools.partial(fn, *args, **kwargs))

    # ------------------------------------------------------------------ recording and status
    def record(self, line_type: str, /, **fields) -> None:
        if self.recorder is not None:
            self.recorder.write(line_type, **fields)

    def event(self, name: str, **fields) -> None:
        """Log and record one event (leg reached, link lost ...) and publish the new status."""
        log.info("%s %s", name, " ".join(f"{k}={v}" for k, v in fields.items()))
        self.record("event", name=name, t_s=self.clock.now_s(), **fields)
        if self.threats is not None:
            self.threats.publish_status(self.status())

    def status(self) -> dict:
        """The status message of ``uav/<sysid>/status``."""
        tele = self.link.telemetry
        ref = self.reference
        return {"t_s": round(self.clock.now_s(), 3), "mode": tele.mode_name, "armed": tele.armed,
                "leg": self.leg_index, "legs": len(self.legs),
                "path_id": ref.path_id if ref else None,
                "pos_ned_m": None if tele.pos_ned_m is None else [round(float(v), 3) for v in tele.pos_ned_m],
                "tracking_error_m": round(self._errors_m[-1], 3) if self._errors_m else None,
                "link": tele.connected, "outcome": self.summary.outcome}

    # ------------------------------------------------------------------ reference
    def engage(self, trajectory, path_id: str, t0_s: float | None = None,
               turn: bool = False) -> ActiveReference:
        """Make ``trajectory`` the active reference from mission time ``t0_s`` (default now),
        first turning on the spot to its heading if ``turn`` (a leg that starts at rest)."""
        ref = ActiveReference(trajectory, self.clock.now_s() if t0_s is None else t0_s,
                              self.clock, path_id, turn_from_yaw_rad=self._current_yaw() if turn else None,
                              turn_rate_rad_s=self.settings.flight.turn_rate_rad_s)
        self.reference = ref
        if self.streamer is not None:
            self.streamer.set_source(ref.setpoint_at)
        if self.threats is not None and self.threats.manager is not None:
            self.threats.manager.set_active(trajectory, ref.t0_s, path_id)
        return ref

    def hold_here(self, pos_ned_m, reason: str) -> None:
        """Hold ``pos_ned_m`` (a hover) as the active reference."""
        yaw = self._current_yaw()
        self.reference = None
        if self.streamer is not None:
            self.streamer.set_source(hold_position(pos_ned_m, yaw))
        self.event("hold", reason=reason, pos_ned_m=np.asarray(pos_ned_m))

    def _current_yaw(self) -> float:
        att = self.link.telemetry.attitude_rad
        return float(att[2]) if att is not None else 0.0

    # ------------------------------------------------------------------ background tasks
    async def _watch_local_position(self) -> None:
        """LOCAL_POSITION_NED with its timestamp: drives the clock and the tracking error."""
        async for fields in self.link.messages("LOCAL_POSITION_NED"):
            boot_s = fields.get("time_boot_ms", 0) / 1000.0
            self.clock.observe(boot_s, fields["_t_s"])
            if self.reference is not None:
                pos = np.array([fields["x"], fields["y"], fields["z"]], dtype=float)
                ref_pos = self.reference.state(boot_s)[0]      # mission time is vehicle time
                self._errors_m.append(float(np.linalg.norm(pos - ref_pos)))

    async def _watch_servos(self) -> None:
        async for fields in self.link.messages("SERVO_OUTPUT_RAW"):
            self._servo_us = [fields.get(f"servo{i}_raw", 1500) for i in range(1, 5)]

    async def _record_samples(self) -> None:
        period = 1.0 / self.settings.link.record_rate_hz
        while True:
            await asyncio.sleep(period)
            tele = self.link.telemetry
            if tele.pos_ned_m is None or self.reference is None:
                continue
            t = self.clock.now_s()
            ref_pos, ref_vel = self.reference.state(t)[:2]
            if self.threats is not None:
                self.summary.min_threat_separation_m = min(
                    self.summary.min_threat_separation_m, self.threats.min_separation_m(tele.pos_ned_m, t))
            self.record("sample", t_s=t, ref_pos_ned_m=ref_pos, ref_vel_ned_m_s=ref_vel,
                        pos_ned_m=tele.pos_ned_m, vel_ned_m_s=tele.vel_ned_m_s,
                        servo_us=self._servo_us,
                        tracking_error_m=self._errors_m[-1] if self._errors_m else None,
                        leg=self.leg_index, path_id=self.reference.path_id)

    async def _publish_status(self) -> None:
        period = 1.0 / self.settings.link.status_rate_hz
        while True:
            await asyncio.sleep(period)
            if self.threats is not None:
                self.threats.publish_status(self.status())

    async def _refresh_alternatives(self) -> None:
        """Keep the M-GART alternatives starting just ahead of the vehicle."""
        period_s = self.settings.flight.alternatives_period_s / self.settings.link.time_scale
        while True:
            await asyncio.sleep(period_s)
            if self.threats is not None:
                self.threats.refresh_alternatives()

    def _on_link_change(self, connected: bool) -> None:
        if not connected:
            self._link_lost_at = self.clock.now_s()
            self.event("link_lost")
        else:
            lost_s = self.clock.now_s() - (self._link_lost_at or self.clock.now_s())
            self.event("link_back", lost_s=round(lost_s, 2))
            if self.reference is not None and self.link.telemetry.pos_ned_m is not None:
                self.hold_here(self.link.telemetry.pos_ned_m, "link back: hold, then replan the leg")
                self._resume_needed = True

    def _start_background(self) -> None:
        loop = asyncio.get_running_loop()
        for coro in (self._watch_local_position(), self._watch_servos(), self._record_samples(),
                     self._publish_status(), self._refresh_alternatives()):
            self._tasks.append(loop.create_task(coro, name=coro.__name__))
        self.link.on_link_change(self._on_link_change)

    # ------------------------------------------------------------------ mission
    async def take_mission(self):
        """The mission to fly: the file given (validated here, uploaded after planning) or the
        vehicle's own mission and fence."""
        if self.mission_path is not None:
            return load_mission_file(self.mission_path)
        plan = await self.link.download_plan()
        if not plan.items:
            raise MissionError("the vehicle has no mission: upload one (companion upload FILE, "
                               "QGroundControl, MAVProxy) or pass --mission FILE")
        self.event("mission_downloaded", items=len(plan.items))
        return plan

    async def plan_flight(self, plan, home_lla, tele) -> float:
        """Convert and plan every leg (in a worker thread); errors name the mission item.

        Returns the takeoff altitude (m above home): the mission's takeoff item, or where the
        vehicle already flies.
        """
        s = self.settings
        self.local_mission = mission_to_local(plan, home_lla, settings=s.mission,
                                              world_file=self.world_path, dim=3)
        self.record("header", settings=settings_to_dict(s), seed=s.seed, home_lla=home_lla,
                    mission=str(self.mission_path) if self.mission_path else "from the vehicle",
                    waypoints_ned_m=[w.pos_ned_m for w in self.local_mission.waypoints])
        start = tele.pos_ned_m
        takeoff = self.local_mission.waypoints[0]          # always the (possibly implied) takeoff
        alt_m = -float(start[2]) if tele.in_air else -float(takeoff.pos_ned_m[2])
        first = np.array([start[0], start[1], -alt_m])
        t0 = time.perf_counter()
        self.legs = await self.in_worker(
            plan_mission, self.local_mission, first, gart_settings=s.gart,
            smoothing=s.smoothing, settings=s.flight, rng=self.rng)
        self.summary.legs_planned = len(self.legs)
        self.record("world", **world_to_dict(self.local_mission.world))
        for leg in self.legs:
            self.record_plan(leg)
        self.event("planned", legs=len(self.legs), seconds=round(time.perf_counter() - t0, 3),
                   seed=s.seed)
        return alt_m

    def record_plan(self, leg: LegPlan) -> None:
        t = np.linspace(0.0, leg.trajectory.duration_s, max(2, int(leg.trajectory.duration_s * 5)))
        ref = leg.trajectory.sample(t)[0]
        tree = leg.plan.tree if leg.plan is not None else None
        self.record("plan", leg=leg.index, seq=leg.waypoint.seq, path_id=f"leg{leg.index}",
                    path_ned_m=leg.path_ned_m, reference_ne=ref[:, :2],
                    tree={"nodes": tree.nodes, "parents": tree.parents} if tree is not None else None,
                    summary=leg.plan.summary() if leg.plan is not None else None)

    async def restore_mission(self, previous) -> None:
        """Put the vehicle's previous lists back (the flight did not start)."""
        try:
            if previous.items:
                await self.link.upload_plan(previous)
            else:
                await self.link.clear_plan()
            self.event("mission_restored", reason="the flight did not start")
        except CompanionError as exc:
            log.error("could not restore the vehicle's previous mission: %s", exc)

    # ------------------------------------------------------------------ flight phases
    async def takeoff(self, alt_m: float) -> None:
        tele = self.link.telemetry
        if tele.armed and tele.in_air:
            self.event("already_flying", alt_m=round(-float(tele.pos_ned_m[2]), 2))
            await self.link.set_mode("GUIDED")
            return
        await self.link.set_mode("GUIDED")
        await self.link.arm()
        self.event("armed")
        await self.link.takeoff(alt_m)
        self.event("takeoff", alt_m=alt_m)
        timeout = 30.0 + alt_m / self.settings.flight.climb_speed_m_s * 3 / self.settings.link.time_scale
        await self.link.wait_for(lambda t: t.pos_ned_m is not None and -t.pos_ned_m[2] >= alt_m - 0.5,
                                 timeout, f"the takeoff to {alt_m:.1f} m")

    def check_guided(self) -> None:
        tele = self.link.telemetry
        if not tele.connected:
            return              # keep streaming the reference; decided when the link is back
        if tele.armed is False:
            raise FlightAborted("the vehicle disarmed in flight")
        if tele.mode is not None and tele.mode != GUIDED:
            raise FlightAborted(f"the vehicle left GUIDED (now {tele.mode_name}): a pilot or "
                                f"the autopilot took over; the companion stops commanding")

    async def resume_leg(self, leg: LegPlan) -> None:
        """Replan the rest of ``leg`` from where the vehicle is (after a link loss)."""
        self._resume_needed = False
        pos = self.link.telemetry.pos_ned_m
        s = self.settings
        new = await self.in_worker(plan_leg, leg.index, leg.waypoint, pos,
                                      self.local_mission.world, gart_settings=s.gart,
                                      smoothing=s.smoothing, settings=s.flight, rng=self.rng)
        if new is not None:
            self.engage(new.trajectory, f"leg{leg.index}-resume", turn=True)
        self.event("resumed", leg=leg.index, from_ned_m=pos)

    def stopped_short(self, ref: ActiveReference, leg: LegPlan, t_s: float) -> bool:
        """True when ``ref`` (e.g. a threat hold) ended away from the leg's goal a while ago."""
        end_gap_m = float(np.linalg.norm(ref.trajectory.end_pos_ned_m[:3] - leg.goal_ned_m))
        return end_gap_m > leg.waypoint.acceptance_radius_m and t_s > ref.t_end_s + RESUME_AFTER_S

    async def continue_leg(self, leg: LegPlan) -> None:
        """Plan on to the leg's goal from the current reference (after a hold), at most once
        every ``RESUME_AFTER_S``."""
        t = self.clock.now_s()
        if t < self._last_resume_t_s + RESUME_AFTER_S:
            return
        self._last_resume_t_s = t
        self.event("continue", leg=leg.index, reason="the reference stopped short of the goal")
        if self.threats is not None:
            await self.threats.resume()
        else:
            await self.resume_leg(leg)

    async def fly_leg(self, leg: LegPlan) -> None:
        """Fly one leg: until its reference has ended and the vehicle is within the radius."""
        self.leg_index = leg.index
        ref = self.engage(leg.trajectory, f"leg{leg.index}", turn=True)
        if self.threats is not None:
            self.threats.on_leg_started(leg, ref)
        margin = self.settings.link.leg_timeout_margin_s
        radius = leg.waypoint.acceptance_radius_m
        while True:
            await asyncio.sleep(0.05)
            self.check_guided()
            if self._resume_needed and self.link.connected:
                await self.resume_leg(leg)
            t = self.clock.now_s()
            ref = self.reference
            pos = self.link.telemetry.pos_ned_m
            if ref is not None and ref.finished(t):
                dist = float(np.linalg.norm(pos - leg.goal_ned_m))
                if dist <= radius:
                    break
                if self.stopped_short(ref, leg, t):
                    await self.continue_leg(leg)
                    continue
                if t > ref.t_end_s + margin:
                    raise FlightAborted(f"item {leg.waypoint.seq} not reached: {dist:.1f} m away "
                                        f"{margin:.0f} s after the reference arrived")
        if self.threats is not None:
            self.threats.on_leg_ended()
        self.summary.legs_reached += 1
        self.event("reached", leg=leg.index, seq=leg.waypoint.seq,
                   error_m=round(float(np.linalg.norm(self.link.telemetry.pos_ned_m - leg.goal_ned_m)), 3))
        if leg.waypoint.hold_s > 0:
            await asyncio.sleep(leg.waypoint.hold_s / self.settings.link.time_scale)

    async def finish(self, end_action: str) -> None:
        """Land (LAND or RTL missions) and wait for the disarm, or hover in LOITER."""
        if end_action in ("land", "rtl"):
            await self.link.land()
            self.event("landing")
            await self.link.wait_for(lambda t: t.armed is False, 60.0 + 120.0 / self.settings.link.time_scale,
                                     "the landing and disarm")
            self.summary.landed = True
            self.event("landed")
        else:
            await self.link.set_mode("LOITER")
            self.event("loiter", reason="the mission ends without LAND or RTL")

    async def safe_stop(self, reason: str) -> None:
        """Bring the vehicle to a hold, landing or RTL (per settings) when the flight stops."""
        tele = self.link.telemetry
        if not (tele.connected and tele.armed):
            return
        action = self.settings.link.on_interrupt
        try:
            if action == "land":
                await self.link.land()
            elif action == "rtl":
                await self.link.return_to_launch()
            else:
                await self.link.set_mode("LOITER")
            self.event("safe_stop", action=action, reason=reason)
        except CompanionError as exc:
            log.error("safe stop (%s) failed: %s", action, exc)

    # ------------------------------------------------------------------ the whole flight
    async def run(self) -> FlightSummary:
        """Fly the mission (see the module docstring); returns the summary."""
        s = self.settings
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
        raise_stream_priority()              # before connect: MAVSDK's threads inherit it
        if self.record_path is not None:
            self.recorder = FlightRecorder(self.record_path)
        await self.link.connect(s.link.connect, s.link.connect_timeout_s)
        try:
            return await self._fly()
        except asyncio.CancelledError:
            self.summary.outcome = "interrupted"
            await asyncio.shield(self.safe_stop("interrupted (SIGINT/SIGTERM)"))
            raise
        except FlightAborted as exc:
            self.summary.outcome = f"aborted: {exc}"
            log.error("flight aborted: %s", exc)
            if self.link.telemetry.mode == GUIDED:
                await self.safe_stop(str(exc))
            raise
        finally:
            await self.shutdown()

    async def _fly(self) -> FlightSummary:
        s = self.settings
        tele = await self.link.wait_ready(s.link.connect_timeout_s)
        home = await self.link.wait_home(s.link.connect_timeout_s)
        plan = await self.take_mission()
        alt = await self.plan_flight(plan, home, tele)
        previous = None
        if self.mission_path is not None:          # planned: every item is reachable
            previous = await self.link.download_plan()
            await self.link.upload_plan(plan)
            self.event("mission_uploaded", file=str(self.mission_path), items=len(plan.items))
        if s.zenoh.enabled:
            self.threats = ThreatReactor(self)
            await self.threats.start(home)
        self._start_background()
        self.summary.outcome = "flying"
        try:
            await self.takeoff(alt)
        except LinkError:
            if previous is not None and not self.link.telemetry.in_air:
                await self.restore_mission(previous)
            raise
        self.streamer = SetpointStreamer(self.link.send_setpoint, rate_hz=s.link.setpoint_rate_hz)
        self.hold_here(self.link.telemetry.pos_ned_m, "takeoff complete")
        self.streamer.start()
        for leg in self.legs:
            await self.fly_leg(leg)
        self.hold_here(self.link.telemetry.pos_ned_m, "mission legs done")
        await self.streamer.stop()
        await self.finish(self.local_mission.end_action)
        self.summary.outcome = "completed"
        return self.summary

    async def shutdown(self) -> None:
        """Stop streaming and background tasks, write the summary, close the link."""
        if self.streamer is not None:
            await self.streamer.stop()
            jitter = self.streamer.stats()
            self.record("event", name="setpoint_jitter", **jitter.as_dict())
        if self.threats is not None:
            counts = self.threats.bus.stats()
            self.summary.threat_updates = counts["received"]
            self.record("event", name="threat_bus", **counts)
            await self.threats.stop()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.threats is not None:
            for kind, values in self.threats.latencies_ms.items():
                self.summary.latency_ms[kind] = {"n": len(values), "p50": float(np.percentile(values, 50)),
                                                 "p99": float(np.percentile(values, 99)),
                                                 "max": float(np.max(values))}
        if self._errors_m:
            err = np.asarray(self._errors_m)
            self.summary.rms_tracking_error_m = float(np.sqrt(np.mean(err**2)))
            self.summary.max_tracking_error_m = float(err.max())
        self.record("summary", **self.summary.as_dict())
        if self.recorder is not None:
            self.recorder.close()
        self._executor.shutdown(wait=False, cancel_futures=True)
        await self.link.aclose()
