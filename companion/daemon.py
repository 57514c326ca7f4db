"""The companion service: a mission in, a planned, smoothed and tracked flight out (DESIGN 1, 6, 7).

``CompanionDaemon.run()`` is the whole flight:

1. connect to the vehicle (MAVSDK; the telemetry it needs is requested, ``companion.link.streams``),
   wait for telemetry, home and the vehicle's EKF origin, and freeze the planning frame (home;
   the link converts to and from the vehicle's local frame, ``companion.link.frames``);
2. take the mission: the file given (validated, planned, then uploaded so that every ground
   station shows it) or the one stored on the vehicle (a mission uploaded by any ground station
   gets flown);
3. convert it to local NED and a world (exclusion zones, inclusion fence, world file) and plan
   every leg before takeoff (GART -> G2/G1 -> speed profile, ``companion.flight_plan``): an
   unreachable waypoint is an error before anything moves;
4. start the vehicle (``companion.link.startup``: GUIDED, motor interlock low, arm, interlock
   after the arming delay, rotor run-up, take off), or *join* it where it flies (armed and in
   the air: no arming, no takeoff); a start that fails leaves the vehicle disarmed on the
   ground or holding in the air; stream the reference at 50 Hz (``SetpointStreamer``) leg after leg,
   each leg flown by the pure phase machine of ``companion.phases`` (observe, step, act): done
   when its reference has ended and the vehicle is within the acceptance radius, then the hold
   time; a reference that ended short of the goal (an evasion or a hold) is followed by a plan
   back to the mission;
5. land or RTL as the mission says (RTL is flown as a planned leg home, then LAND).

Around it: zenoh status at 2 Hz and on every event, the threat reactor
(``companion.threats.reactor``: threats in, a >= 10 Hz monitor, decisions that swap the active
reference, events, path and STATUSTEXT out), ADS-B traffic as threats (``[adsb] enabled``,
``companion.threats.adsb``), the flight record, link-loss handling (keep
streaming; when the link returns, hold and replan the leg from where the vehicle is), a pilot
taking over (mode changed away from GUIDED: the companion stops commanding and ends the flight),
and SIGINT/SIGTERM (hold, land or RTL per ``link.on_interrupt``, then exit).

Crash and restart (``resume=True``, ``companion run --resume``): the vehicle's current mission
item is kept at the goal of the leg flown (DO_SET_MISSION_CURRENT at every leg) and the threats
held are written to a snapshot as they change (``companion.state``, ``state.dir``); a companion
started with ``resume`` joins the hovering vehicle, reads MISSION_CURRENT, plans from where it
is to that item and on (``companion.resume``) and puts the snapshot's live threats back before
the first leg. zenoh router loss: events ``zenoh_lost`` / ``zenoh_back``; the session reconnects
by itself (``companion.threats.bus.CONNECT_RETRY``).

Only this module, ``companion.link`` and ``companion.threats`` (bus, reactor) do I/O. The event-loop
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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.mavlink_ids import COPTER_MODES

from companion.config import Settings, settings_to_dict
from companion.errors import CompanionError, FlightAborted, LinkError, MissionError, VehicleRefused
from companion.geo import LocalFrame
from companion.flight_plan import LegPlan, plan_leg, plan_mission
from companion.reference import ActiveReference, VehicleClock
from companion.link.gate import SigningKey
from companion.link.setpoints import (SetpointStreamer, hold_position,
                                      raise_stream_priority, restore_normal_priority)
from companion.link.startup import (AUX_MOTOR_INTERLOCK, is_airborne, read_rotor_parameters, rotor_plan,
                                    start_vehicle)
from companion.link.vehicle import VehicleLink
from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.phases import ActionKind, LegObservation, LegState, leg_step
from companion.record import FlightRecorder
from companion.resume import resume_mission, resume_refusal
from companion.state import SnapshotWriter, load_live_threats, snapshot_path
from companion.threats.adsb import threat_from_adsb
from companion.threats.reactor import ThreatReactor
from companion.world import world_to_dict

log = logging.getLogger(__name__)

GUIDED = COPTER_MODES["GUIDED"]
#: How often (wall clock, s) the zenoh session's peers and routers are counted (router loss).
ZENOH_WATCH_PERIOD_S = 1.0
#: GIL switch interval (s): a planning thread hands the GIL to the setpoint stream this often.
GIL_SWITCH_INTERVAL_S = 0.0005


__all__ = ["CompanionDaemon", "FlightAborted", "FlightSummary"]


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
    joined: bool = False
    resumed_at_seq: int | None = None
    threats_restored: int = 0
    feasibility: dict = field(default_factory=dict)
    outcome: str = "not flown"

    def as_dict(self) -> dict:
        """Plain data; an infinite separation (no threat met) is None."""
        out = dict(self.__dict__)
        if not math.isfinite(out["min_threat_separation_m"]):
            out["min_threat_separation_m"] = None
        return out


def make_checker(settings):
    """The closed-loop checker of every leg, on the default (R-50-class) model, its LQI
    designed now (python-control, about 2.5 s once; cached on the model)."""
    from companion.smoothing.feasibility import FeasibilityChecker
    from sim_vehicle.model import HeliModel

    checker = FeasibilityChecker(HeliModel.default(), settings)
    log.info("feasibility: closed-loop model ready in %.2f s", checker.warm_up())
    return checker


def feasibility_totals(legs) -> dict:
    """The flight's closed-loop figures over its checked legs (empty when none was checked)."""
    checked = [leg.feasibility for leg in legs if leg.feasibility is not None]
    if not checked:
        return {}
    return {
        "legs_checked": len(checked),
        "legs_stretched": sum(1 for f in checked if f["stretch"] > 1.0),
        "legs_infeasible": sum(1 for f in checked if not f["feasible"]),
        "max_stretch": max(f["stretch"] for f in checked),
        "max_abs_delta": max(f["max_abs_delta"] for f in checked),
        "initial_max_abs_delta": max(f["initial_max_abs_delta"] for f in checked),
        "max_tracking_error_m": max(f["max_tracking_error_m"] for f in checked),
        "check_s": sum(f["check_s"] for f in checked),
    }


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
    resume : bool
        Take over a vehicle that is already flying its mission (a previous companion crashed):
        the vehicle's mission from its current item (MISSION_CURRENT), the threats of the
        snapshot in ``state.dir`` (``companion.state``). Refused (``MissionError``) without a
        mission on the vehicle or with the vehicle on the ground.
    """

    def __init__(self, settings: Settings, *, mission_path=None, world_path=None,
                 record_path=None, resume: bool = False):
        if resume and mission_path is not None:
            raise MissionError("--resume flies the mission stored on the vehicle: leave out --mission")
        self.settings = settings
        self.resume = resume
        self.snapshots: SnapshotWriter | None = None
        self.mission_path = mission_path
        self.world_path = world_path
        self.record_path = record_path
        self.rng = np.random.default_rng(settings.seed)
        self.link = VehicleLink("companion", streams=settings.link.streams,
                                adsb=settings.adsb.enabled,
                                signing_key=SigningKey.from_file(settings.link.signing_key_file))
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
        self.home_lla: tuple | None = None
        self.rotor_plan = None                    # how the start-up handled the rotor
        self.checker = None                       # closed-loop feasibility (settings.feasibility)
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
    def engage(self, trajectory, path_id: str, t0_s: float | None = None, turn: bool = False,
               resume: bool = False) -> ActiveReference:
        """Make ``trajectory`` the active reference from mission time ``t0_s`` (default now; a
        later ``t0_s`` keeps the current reference until then), first turning on the spot to its
        heading if ``turn`` (a leg that starts at rest);
        ``resume``: it stops short of the leg's goal on purpose (``ActiveReference``)."""
        now = self.clock.now_s()
        later = t0_s is not None and t0_s > now
        ref = ActiveReference(trajectory, now if t0_s is None else t0_s,
                              self.clock, path_id, turn_from_yaw_rad=self._current_yaw() if turn else None,
                              turn_rate_rad_s=self.settings.flight.turn_rate_rad_s, resume=resume,
                              previous=self.reference if later else None)
        self.reference = ref
        if self.streamer is not None:
            self.streamer.set_source(ref.setpoint_at)
        if self.threats is not None:
            self.threats.set_active(ref)
        return ref

    def send_now(self) -> None:
        """Send the current setpoint at once (a new reference's first setpoint)."""
        if self.streamer is not None:
            self.streamer.send_now()

    def send_statustext(self, text: str, severity: str) -> None:
        """Tell the ground stations (STATUSTEXT through the vehicle); logged if the link is down."""
        if not self.link.connected:
            log.info("STATUSTEXT %r not sent: the link is down", text)
            return
        self.link.send_statustext(text, severity=severity)

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
            if fields.get("_sysid") != self.link.target_system:
                continue
            boot_s = fields.get("time_boot_ms", 0) / 1000.0
            self.clock.observe(boot_s, fields["_t_s"])
            if self.reference is not None:
                pos = self.link.to_home_frame([fields["x"], fields["y"], fields["z"]])
                ref_pos = self.reference.state(boot_s)[0]      # mission time is vehicle time
                self._errors_m.append(float(np.linalg.norm(pos - ref_pos)))

    async def _watch_servos(self) -> None:
        async for fields in self.link.messages("SERVO_OUTPUT_RAW"):
            if fields.get("_sysid") == self.link.target_system:
                self._servo_us = [fields.get(f"servo{i}_raw", 1500) for i in range(1, 5)]

    async def _watch_adsb(self) -> None:
        """ADSB_VEHICLE reports become threats, treated as zenoh PUTs (``companion.threats.adsb``)."""
        home = LocalFrame(*self.home_lla)
        async for fields in self.link.messages("ADSB_VEHICLE"):
            if fields.get("_sysid") != self.link.target_system or self.threats is None:
                continue
            try:
                threat = threat_from_adsb(fields, self.settings.adsb, self.clock.now_s(), home)
            except (CompanionError, ValueError, TypeError) as exc:
                log.info("ADSB_VEHICLE ignored: %s", exc)
                continue
            if threat is not None:
                self.threats.on_local_threat(threat, fields["_t_s"])

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

    async def _watch_zenoh(self) -> None:
        """Event ``zenoh_lost`` when the session loses its last peer or router (e.g. the router
        stopped), ``zenoh_back`` when one is connected again. zenoh reconnects by itself
        (``connect/retry``) and redeclares the subscriptions; the flight goes on meanwhile on
        the threats already held."""
        had = None
        while True:
            await asyncio.sleep(ZENOH_WATCH_PERIOD_S)
            try:
                now = self.threats.bus.connected_peers() > 0
            except Exception as exc:  # noqa: BLE001 - the session is closing
                log.debug("zenoh session info: %s", exc)
                continue
            if had is not None and now != had:
                self.event("zenoh_back" if now else "zenoh_lost")
            had = now

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
        coros = [self._watch_local_position(), self._watch_servos(), self._record_samples(),
                 self._publish_status()]
        if self.settings.adsb.enabled:
            if self.threats is None:
                log.warning("ADS-B traffic is ignored: threats need zenoh (zenoh.enabled)")
            else:
                coros.append(self._watch_adsb())
        if self.threats is not None:
            coros.append(self._watch_zenoh())
        for coro in coros:
            self._tasks.append(loop.create_task(coro, name=coro.__name__))
        self.link.on_link_change(self._on_link_change)

    # ------------------------------------------------------------------ mission
    async def take_mission(self):
        """The mission to fly: the file given (validated here, uploaded after planning) or the
        vehicle's own mission and fence."""
        if self.mission_path is not None:
            return load_mission_file(self.mission_path)
        plan = await self.link.download_plan()
        if self.resume:
            refusal = resume_refusal(mission_items=len(plan.items), airborne=True)
            if refusal is not None:
                raise MissionError(refusal)
        if not plan.items:
            raise MissionError("the vehicle has no mission: upload one (companion upload FILE, "
                               "QGroundControl, MAVProxy) or pass --mission FILE")
        self.event("mission_downloaded", items=len(plan.items))
        return plan

    async def plan_flight(self, plan, home_lla, tele, current_seq: int | None = None) -> float:
        """Convert and plan every leg (in a worker thread); errors name the mission item.

        With ``current_seq`` (a resume) only the goals from that mission item on are planned
        (``companion.resume.resume_mission``), the first from where the vehicle is.
        Returns the takeoff altitude (m above home): the mission's takeoff item, or where the
        vehicle already flies.
        """
        s = self.settings
        self.local_mission = mission_to_local(plan, home_lla, settings=s.mission,
                                              world_file=self.world_path, dim=3)
        frames = self.link.frames
        self.record("header", settings=settings_to_dict(s), seed=s.seed, home_lla=home_lla,
                    ekf_origin_lla=frames.origin_lla, home_in_origin_ned_m=frames.home_in_origin_ned_m,
                    mission=str(self.mission_path) if self.mission_path else "from the vehicle",
                    waypoints_ned_m=[w.pos_ned_m for w in self.local_mission.waypoints])
        start = tele.pos_ned_m
        flying = is_airborne(tele, s.startup.join_min_height_m)
        if flying:
            alt_m = -float(start[2])
        else:
            alt_m = -float(self.local_mission.waypoints[0].pos_ned_m[2])   # the (implied) takeoff
        first = np.array([start[0], start[1], -alt_m])
        to_fly = self.local_mission if current_seq is None else resume_mission(self.local_mission, current_seq)
        t0 = time.perf_counter()
        # the check flies the helicopter model: not a multirotor's
        if s.feasibility.enabled and s.startup.vehicle == "helicopter" and self.checker is None:
            self.checker = await self.in_worker(make_checker, s.feasibility)
        self.legs = await self.in_worker(
            plan_mission, to_fly, first, gart_settings=s.gart,
            smoothing=s.smoothing, settings=s.flight, rng=self.rng, feasibility=self.checker)
        self.summary.legs_planned = len(self.legs)
        self.summary.feasibility = feasibility_totals(self.legs)
        self.record("world", **world_to_dict(self.local_mission.world))
        for leg in self.legs:
            self.record_plan(leg)
        self.event("planned", legs=len(self.legs), seconds=round(time.perf_counter() - t0, 3),
                   seed=s.seed, feasibility=self.summary.feasibility or None)
        return alt_m

    def record_plan(self, leg: LegPlan) -> None:
        t = np.linspace(0.0, leg.trajectory.duration_s, max(2, int(leg.trajectory.duration_s * 5)))
        ref = leg.trajectory.sample(t)[0]
        tree = leg.plan.tree if leg.plan is not None else None
        self.record("plan", leg=leg.index, seq=leg.waypoint.seq, path_id=f"leg{leg.index}",
                    path_ned_m=leg.path_ned_m, reference_ne=ref[:, :2],
                    tree={"nodes": tree.nodes, "parents": tree.parents} if tree is not None else None,
                    summary=leg.plan.summary() if leg.plan is not None else None,
                    duration_s=leg.trajectory.duration_s, notes=list(leg.notes),
                    feasibility=leg.feasibility)

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
    async def wait_vehicle_clock(self, timeout_s: float) -> None:
        """Wait until the mission clock runs on the vehicle's time (a first LOCAL_POSITION_NED
        seen by the clock's watcher): references are timed on it."""
        await self.link.wait_for(lambda t: self.clock.synced, timeout_s, "the vehicle's clock")

    async def start_or_join(self, alt_m: float) -> None:
        """Join a flying vehicle where it is (GUIDED, no arming, no takeoff), or start it
        (``companion.link.startup.start_vehicle``) and climb to ``alt_m`` above home."""
        tele = self.link.telemetry
        st = self.settings.startup
        if is_airborne(tele, st.join_min_height_m):
            self.summary.joined = True
            self.event("joined", height_m=None if tele.height_m is None else round(tele.height_m, 2),
                       mode=tele.mode_name, landed_state=tele.landed_state)
            if tele.mode != GUIDED:
                await self.link.set_mode("GUIDED")
            if self.resume:        # the crashed companion engaged the interlock: put it back at the end
                self.rotor_plan = rotor_plan(st, await read_rotor_parameters(self.link, st))
            return
        self.rotor_plan = await start_vehicle(
            self.link, st, alt_m, self.clock.now_s, time_scale=self.settings.link.time_scale,
            climb_speed_m_s=self.settings.flight.climb_speed_m_s, event=self.event)
        self.event("takeoff_complete", alt_m=alt_m)

    async def resume_leg(self, leg: LegPlan) -> None:
        """Replan the rest of ``leg`` from where the vehicle is (after a link loss)."""
        self._resume_needed = False
        pos = self.link.telemetry.pos_ned_m
        s = self.settings
        new = await self.in_worker(plan_leg, leg.index, leg.waypoint, pos,
                                   self.local_mission.world, gart_settings=s.gart,
                                   smoothing=s.smoothing, settings=s.flight, rng=self.rng,
                                   feasibility=self.checker)
        if new is not None:
            self.engage(new.trajectory, f"leg{leg.index}-resume", turn=True)
        checked = None if new is None or new.feasibility is None else \
            {k: v for k, v in new.feasibility.items() if k != "pieces"}
        self.event("resumed", leg=leg.index, from_ned_m=pos, feasibility=checked)

    async def continue_leg(self, leg: LegPlan, reason: str) -> None:
        """Plan back to the leg's goal from a reference that ended short of it (an evasion or
        a hold): the threat manager's way back, or a replan from the vehicle without threats."""
        if self.threats is None:
            self.event("continue", leg=leg.index, reason=reason)
            await self.resume_leg(leg)
            return
        decision = await self.threats.resume()
        if decision is not None and decision.trajectory is not None:
            self.event("continue", leg=leg.index, reason=reason, decision=decision.kind,
                       path_id=decision.path_id)
        else:
            log.info("leg %d: no clear way back to the mission yet (%s)", leg.index,
                     "no decision" if decision is None else decision.reason)

    def observe(self, leg: LegPlan) -> LegObservation:
        """What the leg's state machine (``companion.phases.leg_step``) sees now."""
        tele, ref = self.link.telemetry, self.reference
        radius = leg.waypoint.acceptance_radius_m
        return LegObservation(
            t_s=self.clock.now_s(), seq=leg.waypoint.seq, connected=tele.connected, armed=tele.armed,
            guided=None if tele.mode is None else tele.mode == GUIDED, mode_name=tele.mode_name,
            relink_pending=self._resume_needed,
            dist_to_goal_m=math.inf if tele.pos_ned_m is None else
            float(np.linalg.norm(tele.pos_ned_m - leg.goal_ned_m)),
            acceptance_radius_m=radius, ref_end_t_s=None if ref is None else ref.t_end_s,
            ref_ends_short=ref is not None and ref.end_gap_m(leg.goal_ned_m) > radius,
            ref_resume=ref is not None and ref.resume,
            timeout_margin_s=self.settings.link.leg_timeout_margin_s)

    async def fly_leg(self, leg: LegPlan) -> None:
        """Fly one leg: observe, step the phase machine (``companion.phases``), act; until the
        reference has ended and the vehicle is within the acceptance radius."""
        self.leg_index = leg.index
        self._tasks.append(asyncio.get_running_loop().create_task(
            self.set_mission_current(leg.waypoint.seq), name="set-mission-current"))
        ref = self.engage(leg.trajectory, f"leg{leg.index}", turn=True)
        if self.threats is not None:
            self.threats.on_leg_started(leg, ref)
        state = LegState()
        while True:
            await asyncio.sleep(0.05)
            state, action = leg_step(state, self.observe(leg))
            if action.kind is ActionKind.ABORT:
                raise FlightAborted(action.reason)
            if action.kind is ActionKind.REACHED:
                break
            if action.kind is ActionKind.REPLAN:
                await self.resume_leg(leg)
            elif action.kind is ActionKind.RESUME:
                await self.continue_leg(leg, action.reason)
        if self.threats is not None:
            self.threats.on_leg_ended()
        self.summary.legs_reached += 1
        self.event("reached", leg=leg.index, seq=leg.waypoint.seq,
                   error_m=round(float(np.linalg.norm(self.link.telemetry.pos_ned_m - leg.goal_ned_m)), 3))
        if leg.waypoint.hold_s > 0:
            await asyncio.sleep(leg.waypoint.hold_s / self.settings.link.time_scale)

    async def set_mission_current(self, seq: int) -> None:
        """Make ``seq`` (the goal of the leg now flown) the vehicle's current mission item
        (MAV_CMD_DO_SET_MISSION_CURRENT, accepted in GUIDED): ground stations show it, and a
        companion restarted with ``--resume`` reads it back. Never fails the flight."""
        try:
            result = await self.link.command_result(
                mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, (float(seq),), what=f"DO_SET_MISSION_CURRENT {seq}",
                timeout_s=3.0)
        except CompanionError as exc:          # the link is down: set again at the next leg
            log.info("current mission item %d not set: %s", seq, exc)
            return
        if result != 0:
            log.warning("current mission item %d not set: MAV_RESULT %s", seq, result)

    async def read_mission_current(self, timeout_s: float) -> int:
        """The vehicle's current mission item (MISSION_CURRENT ``seq``), asked for with
        MAV_CMD_REQUEST_MESSAGE every second until it arrives (ArduPilot also streams it with
        the EXTENDED_STATUS group).

        Raises
        ------
        LinkError
            No MISSION_CURRENT within ``timeout_s``.
        """
        async def first_seq() -> int:
            async for fields in self.link.messages("MISSION_CURRENT"):
                if fields.get("_sysid") == self.link.target_system:
                    return int(fields["seq"])
            raise LinkError("the MISSION_CURRENT subscription ended")

        task = asyncio.get_running_loop().create_task(first_seq(), name="mission-current")
        deadline = time.monotonic() + timeout_s
        try:
            while time.monotonic() < deadline:
                await self.link.command_result(mavlink.MAV_CMD_REQUEST_MESSAGE,
                                               (float(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT),),
                                               what="REQUEST_MESSAGE MISSION_CURRENT", timeout_s=1.0)
                done, _ = await asyncio.wait({task}, timeout=min(1.0, max(0.0, deadline - time.monotonic())))
                if done:
                    return task.result()
        finally:
            task.cancel()
        raise LinkError(f"timed out after {timeout_s:g} s waiting for the vehicle's MISSION_CURRENT")

    # ------------------------------------------------------------------ threat snapshot
    def _open_snapshots(self, home) -> None:
        """Write the threat snapshot from now on when ``state.dir`` is set (``companion.state``)."""
        if not self.settings.state.dir or self.threats is None:
            return
        path = snapshot_path(self.settings.state.dir, self.settings.zenoh.sysid)
        self.snapshots = SnapshotWriter(path, sysid=self.settings.zenoh.sysid, home_lla=home)
        self.threats.on_table_change = self.snapshots.save

    def restore_threats(self) -> None:
        """A resume: put the live threats of the snapshot back in the table (none when there
        is no usable snapshot: that is logged, never fatal), then write the snapshot afresh."""
        if self.threats is None:
            return
        if not self.settings.state.dir:
            log.warning("resuming without a state directory (--state-dir): no threats are restored")
            return
        path = snapshot_path(self.settings.state.dir, self.settings.zenoh.sysid)
        threats = load_live_threats(path, self.clock.now_s(), sysid=self.settings.zenoh.sysid,
                                    home_lla=self.home_lla)
        ids = self.threats.restore(threats)
        self.summary.threats_restored = len(ids)
        self.event("threats_restored", ids=ids, snapshot=str(path),
                   remaining_ttl_s={t.id: round(t.expires_t_s - self.clock.now_s(), 2)
                                    for t in threats if t.ttl_s is not None})

    async def finish(self, end_action: str) -> None:
        """Land (LAND or RTL missions) and wait for the disarm, or hover in LOITER."""
        if end_action in ("land", "rtl"):
            await self.link.land()
            self.event("landing")
            await self.link.wait_for(lambda t: t.armed is False, 60.0 + 120.0 / self.settings.link.time_scale,
                                     "the landing and disarm")
            self.summary.landed = True
            self.event("landed")
            if self.rotor_plan is not None and self.rotor_plan.interlock == "command":
                await self.link.aux_function(AUX_MOTOR_INTERLOCK, 0)    # as the start found it
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
        except VehicleRefused as exc:
            self.summary.outcome = f"refused: {exc}"
            raise
        except FlightAborted as exc:
            self.summary.outcome = f"aborted: {exc}"
            log.error("flight aborted: %s", exc)
            if self.link.telemetry.mode == GUIDED:
                await self.safe_stop(str(exc))
            raise
        finally:
            await self.shutdown()

    async def resume_point(self) -> int:
        """A resume: check that the vehicle flies and read its current mission item."""
        refusal = resume_refusal(mission_items=1, airborne=is_airborne(
            self.link.telemetry, self.settings.startup.join_min_height_m))
        if refusal is not None:
            raise MissionError(refusal)
        seq = await self.read_mission_current(self.settings.state.mission_current_timeout_s)
        self.summary.resumed_at_seq = seq
        self.event("resume", current_seq=seq, pos_ned_m=self.link.telemetry.pos_ned_m,
                   mode=self.link.telemetry.mode_name)
        return seq

    async def _fly(self) -> FlightSummary:
        s = self.settings
        await self.link.wait_ready(s.link.connect_timeout_s)
        home = await self.link.wait_home(s.link.connect_timeout_s)
        await self.link.wait_origin(s.link.origin_timeout_s)
        frames = self.link.set_planning_home(home)
        self.home_lla = home
        tele = self.link.telemetry                   # positions about home from here on
        self.event("frames", home_lla=home, ekf_origin_lla=frames.origin_lla,
                   home_in_origin_ned_m=np.round(frames.home_in_origin_ned_m, 3))
        current_seq = await self.resume_point() if self.resume else None
        plan = await self.take_mission()
        alt = await self.plan_flight(plan, home, tele, current_seq)
        previous = None
        if self.mission_path is not None:          # planned: every item is reachable
            previous = await self.link.download_plan()
            await self.link.upload_plan(plan)
            self.event("mission_uploaded", file=str(self.mission_path), items=len(plan.items))
        if s.zenoh.enabled:
            self.threats = ThreatReactor(
                s, clock_now_s=self.clock.now_s, in_worker=self.in_worker, rng=self.rng,
                engage=self.engage, send_now=self.send_now, reference=lambda: self.reference,
                position_ned_m=lambda: self.link.telemetry.pos_ned_m, record=self.record,
                statustext=self.send_statustext)
            await self.threats.start(home)
            self._open_snapshots(home)
        self._start_background()
        await self.wait_vehicle_clock(s.link.connect_timeout_s)
        if self.resume:
            self.restore_threats()
        elif self.snapshots is not None:
            self.threats.table_changed()       # a new flight: the previous flight's threats go
        self.summary.outcome = "flying"
        try:
            await self.start_or_join(alt)
        except LinkError:
            if previous is not None and not is_airborne(self.link.telemetry, s.startup.join_min_height_m):
                await self.restore_mission(previous)
            raise
        self.streamer = SetpointStreamer(self.link.send_setpoint, rate_hz=s.link.setpoint_rate_hz)
        self.hold_here(self.link.telemetry.pos_ned_m,
                       "joined in the air" if self.summary.joined else "takeoff complete")
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
        if self.snapshots is not None:
            self.snapshots.close()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.threats is not None:
            self.summary.decisions = self.threats.decisions
            self.summary.latency_ms = self.threats.latency_summary()
        if self._errors_m:
            err = np.asarray(self._errors_m)
            self.summary.rms_tracking_error_m = float(np.sqrt(np.mean(err**2)))
            self.summary.max_tracking_error_m = float(err.max())
        self.record("summary", **self.summary.as_dict())
        if self.recorder is not None:
            self.recorder.close()
        self._executor.shutdown(wait=False, cancel_futures=True)
        await self.link.aclose()
