"""The companion service: a mission in, a planned, smoothed and tracked flight out (DESIGN 1, 6, 7).

``CompanionDaemon.run()`` is the whole flight:

1. connect to the vehicle (MAVSDK; the telemetry it needs is requested, ``companion.link.streams``),
   wait for telemetry, home and the vehicle's EKF origin, and freeze the planning frame (home;
   the link converts to and from the vehicle's local frame, ``companion.link.frames``);
2. take the mission: the file given (validated, planned, then uploaded so that every ground
   station shows it) or the one stored on the vehicle (a mission uploaded by any ground station
   gets flown);
3. convert it to local NED and a world (exclusion zones, inclusion fence, world file) and plan
   every leg before takeoff (GART -> G2/G1 -> speed profile, ``companion.flight.plan``): an
   unreachable waypoint is an error before anything moves;
4. start the vehicle (``companion.service.startup``: GUIDED, motor interlock low, arm, interlock
   after the arming delay, rotor run-up, take off), or *join* it where it flies (armed and in
   the air: no arming, no takeoff); a start that fails leaves the vehicle disarmed on the
   ground or holding in the air; stream the reference at 50 Hz (``SetpointStreamer``) leg after leg,
   each leg flown by the pure phase machine of ``companion.flight.phases`` (observe, step, act;
   ``companion.flight.legs``): done
   when its reference has ended and the vehicle is within the acceptance radius, then the hold
   time; a reference that ended short of the goal (an evasion or a hold) is followed by a plan
   back to the mission;
5. land or RTL as the mission says (RTL is flown as a planned leg home, then LAND).

Around it: zenoh status at 2 Hz and on every event, the threat reactor
(``companion.threats.reactor``: threats in, events, path and STATUSTEXT out; the executor's
``companion.flight.avoidance``: a >= 10 Hz monitor and decisions that swap the active reference), ADS-B traffic as threats (``[adsb] enabled``,
``companion.threats.transport.adsb``), the flight record, link-loss handling (keep
streaming; when the link returns, hold and replan the leg from where the vehicle is), a pilot
taking over (mode changed away from GUIDED: the companion stops commanding and ends the flight),
and SIGINT/SIGTERM (hold, land or RTL per ``link.on_interrupt``, then exit).

Crash and restart (``resume=True``, ``companion run --resume``): the vehicle's current mission
item is kept at the goal of the leg flown (DO_SET_MISSION_CURRENT at every leg) and the threats
held are written to a snapshot as they change (``companion.threats.snapshot``, ``state.dir``); a companion
started with ``resume`` joins the hovering vehicle, reads MISSION_CURRENT, plans from where it
is to that item and on (``companion.flight.resume``) and puts the snapshot's live threats back before
the first leg. zenoh router loss: events ``zenoh_lost`` / ``zenoh_back``; the session reconnects
by itself (``companion.threats.transport.bus.CONNECT_RETRY``).

The legs are flown by the flight executor (``companion.flight.executor``): the reference owner,
the phase machine, the threat monitor and decisions, on one schedule of named tasks at declared
rates, driven here by a 50 Hz ``PeriodicDriver`` (``companion.link.periodic``) over MAVLink;
the same executor flies in fast time in the benchmarks and the campaign
(``companion.flight.fast_time``). This module composes it with its real-time ports: the
vehicle's telemetry (``companion.link``), the planning worker processes for its jobs
(``companion.service.jobs``), the record, zenoh and STATUSTEXT for what it tells
(``companion.service.sink``), the daemon's own rows of the schedule and the telemetry watchers
(``companion.service.background``), and the mission before and the landing after the legs
(``companion.service.mission``). Only these, ``companion.link`` and ``companion.threats``
(transport, reactor) do I/O. The event-loop thread that streams setpoints runs at real-time
priority when allowed (``raise_stream_priority``); planning, smoothing, the feasibility check,
threat decisions and M-GART refreshes run in two warm, niced worker processes
(``companion.workers``: values in, values out), so the 50 Hz period holds while a replan runs; a
short GIL switch interval hands the GIL back to the stream from the link's own threads.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import sys
import time

import numpy as np

from companion.config import Settings
from companion.errors import CompanionError, FlightAborted, LinkError, MissionError, VehicleRefused
from companion.flight.active import ReferenceOwner
from companion.flight.avoidance import AlternativesPlan, Avoidance
from companion.flight.executor import FlightExecutor
from companion.flight.legs import FlightOutcome, LegReplanner
from companion.flight.ports import VehicleView
from companion.flight.reference import VehicleClock
from companion.link.gate import SigningKey
from companion.link.periodic import PeriodicDriver
from companion.link.setpoints import SetpointStreamer, normal_priority, raise_stream_priority
from companion.link.vehicle import VehicleLink
from companion.service.background import ZENOH_WATCH_PERIOD_S, DaemonTasks, TelemetryWatchers
from companion.service.jobs import WorkerJobs
from companion.service.mission import GUIDED, MissionService
from companion.service.sink import DaemonSink
from companion.service.startup import is_airborne
from companion.service.summary import FlightSummary, feasibility_totals, make_checker
from companion.service.threat_memory import open_snapshots, restore_threats
from companion.threats.decision.step import DecisionPolicy, DecisionState
from companion.threats.reactor import ThreatReactor
from companion.view.sinks import RecordSinks, open_record_sinks, parse_foxglove_address
from companion.workers import PlanningWorkers

log = logging.getLogger(__name__)

#: GIL switch interval (s): another thread of this process hands the GIL to the setpoint
#: stream this often.
GIL_SWITCH_INTERVAL_S = 0.0005
#: A reference's first setpoint is sent this long after its start (s of wall clock): the
#: vehicle clock's estimate must have passed the start for the setpoint to be the new one.
SEND_AT_SLACK_S = 0.0005


__all__ = [
    "CompanionDaemon",
    "FlightAborted",
    "FlightSummary",
    "feasibility_totals",
    "make_checker",
    "GUIDED",
    "ZENOH_WATCH_PERIOD_S",
]


def companion_link(settings: Settings, onboard=None) -> VehicleLink:
    """The companion's link to its vehicle, as ``settings.link`` and ``settings.adsb`` say (not
    connected yet); ``onboard``: speak as the companion component too (``companion serve``)."""
    return VehicleLink(
        "companion",
        streams=settings.link.streams,
        adsb=settings.adsb.enabled,
        signing_key=SigningKey.from_file(settings.link.signing_key_file),
        tlog_path=settings.link.tlog_file or None,
        onboard=onboard,
    )


class LinkVehicle:
    """The executor's ``VehiclePort`` in real time: the link's telemetry."""

    def __init__(self, link: VehicleLink) -> None:
        self.link = link

    def view(self) -> VehicleView:
        tele = self.link.telemetry
        att = tele.attitude_rad
        return VehicleView(
            tele.connected,
            tele.armed,
            None if tele.mode is None else tele.mode == GUIDED,
            tele.mode_name,
            tele.pos_ned_m,
            float(att[2]) if att is not None else 0.0,
        )


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
        Where to write the flight record (JSON Lines or MCAP).
    resume : bool
        Take over a vehicle that is already flying its mission (a previous companion crashed):
        the vehicle's mission from its current item (MISSION_CURRENT), the threats of the
        snapshot in ``state.dir`` (``companion.threats.snapshot``). Refused (``MissionError``)
        without a mission on the vehicle or with the vehicle on the ground.
    workers : str
        Where planning runs (``companion.workers.PlanningWorkers``): ``"process"`` (default)
        or ``"thread"``.
    link : VehicleLink, optional
        A link already connected that outlives this flight (``companion serve``'s,
        ``companion.service.serve``): used as it is, left open. Default: a link of its own,
        connected by ``run`` (after raising the stream's priority) and closed at the end.
    bus : ThreatBus, optional
        A zenoh session that outlives this flight (``companion serve``'s): the threat reactor
        subscribes on it for the flight and leaves it open.
    live : companion.view.live.LiveView, optional
        A live Foxglove view that outlives this flight (``companion serve``'s, already feeding
        the vehicle's state): the flight's channels go on it and it stays up. Default: with
        ``view.foxglove``, a view of its own from the start of ``run`` to its end.
    """

    def __init__(
        self,
        settings: Settings,
        *,
        mission_path=None,
        world_path=None,
        record_path=None,
        resume: bool = False,
        workers: str = "process",
        link: VehicleLink | None = None,
        bus=None,
        live=None,
    ):
        if resume and mission_path is not None:
            raise MissionError("--resume flies the mission stored on the vehicle: leave out --mission")
        self.settings = settings
        self.resume = resume
        self.mission_path = mission_path
        self.world_path = world_path
        self.record_path = record_path
        self.rng = np.random.default_rng(settings.seed)
        self.owns_link = link is None
        self.link = link if link is not None else companion_link(settings)
        self.bus = bus
        self.live = live
        self._owns_live = False
        self.clock = VehicleClock(settings.link.time_scale or 1.0)  # the vehicle's, once connected
        self.owner = ReferenceOwner(
            self.clock, turn_rate_rad_s=settings.flight.turn_rate_rad_s, yaw_now_rad=self._current_yaw
        )
        self.summary = FlightSummary()
        self.workers = PlanningWorkers(workers)
        self.recorder: RecordSinks | None = None
        self.sink = DaemonSink(self)
        self.home_lla: tuple | None = None
        self.mission: MissionService | None = None
        self.threats: ThreatReactor | None = None  # when zenoh is enabled
        self.watchers: TelemetryWatchers | None = None
        self.streamer: SetpointStreamer | None = None
        self.driver: PeriodicDriver | None = None
        self.executor: FlightExecutor | None = None
        self.snapshots = None
        self.takeoff_alt_m = 0.0
        self._stop_link_listener = None
        self._link_lost_at: float | None = None
        self._workers_ready: asyncio.Future | None = None
        self._tasks: list[asyncio.Task] = []

    # ------------------------------------------------------------------ what it tells
    def _open_record(self) -> RecordSinks:
        """The record's sinks: ``--record`` (MCAP or JSON Lines) and the live Foxglove view
        (its own, fed from the link's telemetry, unless it was given one)."""
        s = self.settings
        with normal_priority():  # the live server's threads never at the stream's priority
            if self.live is None and s.view.foxglove:
                from companion.extras import require

                require("view", "foxglove")
                from companion.view.live import LiveView  # foxglove-sdk only when used

                self.live = LiveView(self.link, *parse_foxglove_address(s.view.foxglove, "view.foxglove"))
                self._owns_live = True
            return open_record_sinks(
                self.record_path,
                None,
                s.threats.horizon_s,
                s.threats.uncertainty_m_s,
                live=self.live.server if self.live is not None else None,
            )

    def status(self) -> dict:
        """The status message of ``uav/<sysid>/status``."""
        tele = self.link.telemetry
        ref = self.owner.current
        errors = self.watchers.errors_m if self.watchers is not None else []
        legs = self.mission.legs if self.mission is not None else []
        return {
            "t_s": round(self.clock.now_s(), 3),
            "sysid": self.settings.zenoh.sysid,
            "home_lla": self.home_lla,
            "mode": tele.mode_name,
            "armed": tele.armed,
            "leg": self.leg_index,
            "legs": len(legs),
            "path_id": ref.path_id if ref else None,
            "pos_ned_m": None if tele.pos_ned_m is None else [round(float(v), 3) for v in tele.pos_ned_m],
            "tracking_error_m": round(errors[-1], 3) if errors else None,
            "link": tele.connected,
            "outcome": self.summary.outcome,
        }

    @property
    def leg_index(self) -> int:
        return self.executor.legs.index if self.executor is not None else -1

    def hold_here(self, pos_ned_m, reason: str) -> None:
        """Hover at ``pos_ned_m`` (no trajectory)."""
        self.owner.hold(pos_ned_m)
        self.sink.event("hold", reason=reason, pos_ned_m=np.asarray(pos_ned_m))

    def send_statustext(self, text: str, severity: str) -> None:
        """Tell the ground stations (STATUSTEXT through the vehicle); logged if the link is down."""
        if not self.link.connected:
            log.info("STATUSTEXT %r not sent: the link is down", text)
            return
        self.link.direct.send_statustext(text, severity=severity)

    def send_message(self, name: str, fields: dict) -> None:
        """One broadcast message to the ground stations through the vehicle (``COLLISION``);
        logged if the link is down or the message is refused."""
        if not self.link.connected:
            log.info("%s not sent: the link is down", name)
            return
        try:
            self.link.direct.send_message(name, fields)
        except CompanionError as exc:
            log.info("%s not sent: %s", name, exc)

    def _current_yaw(self) -> float:
        att = self.link.telemetry.attitude_rad
        return float(att[2]) if att is not None else 0.0

    # ------------------------------------------------------------------ the flight
    async def run(self) -> FlightSummary:
        """Fly the mission (see the module docstring); returns the summary."""
        s = self.settings
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
        # the workers start before the stream's priority is raised and before any thread of
        # the link exists (the forkserver is exec'd from here); they warm up meanwhile
        self._workers_ready = self.workers.start()
        self.recorder = self._open_record()
        if self.owns_link:
            raise_stream_priority()  # before connect: MAVSDK's threads inherit it
            await self.link.connect(s.link.connect, s.link.connect_timeout_s)
        try:
            await self._take_time_scale()
            return await self._fly()
        except asyncio.CancelledError:
            self.summary.outcome = "interrupted"
            if self.mission is not None:
                await asyncio.shield(self.mission.safe_stop("interrupted (SIGINT/SIGTERM)"))
            raise
        except VehicleRefused as exc:
            self.summary.outcome = f"refused: {exc}"
            raise
        except FlightAborted as exc:
            self.summary.outcome = f"aborted: {exc}"
            log.error("flight aborted: %s", exc)
            if self.link.telemetry.mode == GUIDED and self.mission is not None:
                await self.mission.safe_stop(str(exc))
            raise
        finally:
            await self.shutdown()

    async def _take_time_scale(self) -> None:
        """The vehicle's speed-up (``SIM_SPEEDUP``) unless ``link.time_scale`` is given; 1 for a
        vehicle without that parameter. Every later reader sees it in ``self.settings``."""
        link = self.settings.link
        scale, source = link.time_scale, "given"
        if scale is None:
            got = await self.link.commands.read_params(["SIM_SPEEDUP"], timeout_s=self.settings.startup.param_timeout_s)
            value = got.get("SIM_SPEEDUP", math.nan)
            scale, source = (
                (value, "the vehicle's SIM_SPEEDUP")
                if math.isfinite(value) and value > 0
                else (1.0, "real time: the vehicle has no SIM_SPEEDUP")
            )
        self.settings = dataclasses.replace(self.settings, link=dataclasses.replace(link, time_scale=float(scale)))
        self.clock.scale = float(scale)
        log.info("time scale %g (%s)", scale, source)

    def resolve_sysid(self) -> None:
        """The zenoh prefix ``uav/<sysid>`` follows the vehicle's system id unless it was set."""
        zenoh = self.settings.zenoh.for_vehicle(self.link.target_system)
        if zenoh is not self.settings.zenoh:
            self.settings = dataclasses.replace(self.settings, zenoh=zenoh)
            log.info("zenoh prefix uav/%d: the vehicle's system id", zenoh.sysid)

    async def _fly(self) -> FlightSummary:
        s = self.settings
        await self.link.waits.wait_ready(s.link.connect_timeout_s)
        self.resolve_sysid()
        s = self.settings
        home = await self.link.waits.wait_home(s.link.connect_timeout_s)
        await self.link.waits.wait_origin(s.link.origin_timeout_s)
        frames = self.link.set_planning_home(home)
        self.home_lla = home
        self.sink.event(
            "frames",
            home_lla=home,
            ekf_origin_lla=frames.origin_lla,
            home_in_origin_ned_m=np.round(frames.home_in_origin_ned_m, 3),
        )
        self.mission = MissionService(
            s,
            link=self.link,
            sink=self.sink,
            workers=self.workers,
            workers_ready=self._workers_ready,
            summary=self.summary,
            clock=self.clock,
            mission_path=self.mission_path,
            world_path=self.world_path,
            resume=self.resume,
            rng=self.rng,
        )
        previous = await self._plan(home)
        if s.zenoh.enabled:
            await self._start_threats(home)
        self._start_watchers(home)
        await self.mission.wait_vehicle_clock(s.link.connect_timeout_s)
        if self.resume:
            restore_threats(self)
        elif self.snapshots is not None:
            self.threats.table_changed()  # a new flight: the previous flight's threats go
        self.summary.outcome = "flying"
        try:
            await self.mission.start_or_join(self.takeoff_alt_m)
        except LinkError:
            if previous is not None and not is_airborne(self.link.telemetry, s.startup.join_min_height_m):
                await self.mission.restore_mission(previous)
            raise
        await self._fly_legs()
        await self.mission.finish(self.mission.local_mission.end_action)
        self.summary.outcome = "completed"
        return self.summary

    async def _plan(self, home):
        """Take and plan the mission (upload it when it came from a file); returns the
        vehicle's previous lists (None when the vehicle's own mission is flown)."""
        tele = self.link.telemetry  # positions about home from here on
        current_seq = await self.mission.resume_point() if self.resume else None
        plan = await self.mission.take_mission()
        self.takeoff_alt_m = await self.mission.plan_flight(plan, home, tele, current_seq)
        if self.mission_path is None:
            return None
        previous = await self.link.missions.download_plan()  # planned: every item is reachable
        await self.link.missions.upload_plan(plan)
        self.sink.event("mission_uploaded", file=str(self.mission_path), items=len(plan.items))
        return previous

    async def _start_threats(self, home) -> None:
        self.threats = ThreatReactor(
            self.settings,
            clock_now_s=self.clock.now_s,
            record=self.sink.record,
            statustext=self.send_statustext,
            bus=self.bus,
            keep_bus_open=self.bus is not None,
        )
        with normal_priority():  # zenoh's threads never at the stream's priority
            await self.threats.start(
                home, reference=lambda: self.owner.current, position_ned_m=lambda: self.link.telemetry.pos_ned_m
            )
        self.owner.listen(lambda ref: self.threats.fleet_publish())
        self.snapshots = open_snapshots(self.settings, self.threats, home)

    def _start_watchers(self, home) -> None:
        s = self.settings
        if s.adsb.enabled and self.threats is None:
            log.warning("ADS-B traffic is ignored: threats need zenoh (zenoh.enabled)")
        self.watchers = TelemetryWatchers(
            self.link,
            self.clock,
            self.owner,
            reactor=self.threats,
            adsb_settings=s.adsb if s.adsb.enabled else None,
            home_lla=home,
            now_s=self.clock.now_s,
        )
        self.watchers.start()
        self._stop_link_listener = self.link.on_link_change(self._on_link_change)

    # ------------------------------------------------------------------ the legs
    def _send_at(self, t_s: float) -> None:
        """Send the setpoint when mission time ``t_s`` comes (a reference that starts then)."""
        wait_s = (t_s - self.clock.now_s()) / self.clock.scale + SEND_AT_SLACK_S
        asyncio.get_running_loop().call_later(max(wait_s, 0.0), self.streamer.send_now)

    def _build_executor(self) -> FlightExecutor:
        """The flight executor with its real-time ports and the daemon's rows."""
        s = self.settings
        loop = asyncio.get_running_loop()
        jobs = WorkerJobs(self.workers, loop)
        avoidance = None
        if self.threats is not None:
            policy = DecisionPolicy.from_settings(s)
            f = s.flight
            avoidance = Avoidance(
                policy=policy,
                state=DecisionState.initial(policy, int(self.rng.integers(2**31))),
                owner=self.owner,
                threats=self.threats,
                jobs=jobs,
                sink=self.sink,
                now_s=self.clock.now_s,
                monotonic_s=time.monotonic,
                send_now=self.streamer.send_now,
                send_at=self._send_at,
                position_ned_m=lambda: self.link.telemetry.pos_ned_m,
                alternatives=AlternativesPlan(f.alternatives_k, f.alternatives_budget_s, f.alternatives_lead_s),
                commit_gate=self.threats.commit_gate(loop),
                alerts=s.alerts,
            )
            self.threats.on_change = avoidance.on_threats_changed
        mission = self.mission
        executor = FlightExecutor(
            mission.legs,
            owner=self.owner,
            vehicle=LinkVehicle(self.link),
            jobs=jobs,
            sink=self.sink,
            stream=self.streamer.tick,
            now_s=self.clock.now_s,
            clock_s=time.monotonic,
            setpoint_rate_hz=s.link.setpoint_rate_hz,
            timeout_margin_s=s.link.leg_timeout_margin_s,
            replanner=LegReplanner.in_world(mission.local_mission.world, mission.pipeline(), s.flight),
            avoidance=avoidance,
            alternatives_rate_hz=s.link.time_scale / s.flight.alternatives_period_s,
            alerts_rate_hz=s.link.time_scale * s.alerts.rate_hz,
            leg_started=self._leg_started,
            seed=int(self.rng.integers(2**31)),
            slack_s=0.5 / s.link.setpoint_rate_hz,
        )
        tasks = DaemonTasks(
            s,
            link=self.link,
            owner=self.owner,
            watchers=self.watchers,
            summary=self.summary,
            sink=self.sink,
            status=self.status,
            reactor=self.threats,
            recorder=self.recorder,
            leg_index=lambda: self.leg_index,
        )
        for row in tasks.rows():
            executor.schedule.add(row)
        return executor

    def _leg_started(self, leg) -> None:
        """A leg starts: its goal becomes the vehicle's current mission item (in the background)."""
        self._tasks.append(
            asyncio.get_running_loop().create_task(
                self.mission.set_mission_current(leg.waypoint.seq), name="set-mission-current"
            )
        )

    async def _fly_legs(self) -> None:
        """Stream and fly every leg on the executor's schedule, then hover where it ends."""
        s = self.settings
        self.streamer = SetpointStreamer(
            self.link.direct.send_setpoint, self.owner.setpoint_at, rate_hz=s.link.setpoint_rate_hz
        )
        self.executor = self._build_executor()
        self.driver = PeriodicDriver(s.link.setpoint_rate_hz, self.executor.tick)
        self.hold_here(
            self.link.telemetry.pos_ned_m, "joined in the air" if self.summary.joined else "takeoff complete"
        )
        self.recorder.pace(True)  # the record is written between sends
        self.link.inbound.batch_reads(self.driver)  # telemetry taken at the schedule's ticks
        self.driver.start()
        self.executor.start()
        await self.driver.until(lambda: self.executor.done)
        self.summary.legs_reached = self.executor.legs.reached
        if self.executor.outcome is FlightOutcome.ABORTED:
            raise FlightAborted(self.executor.legs.reason)
        self.hold_here(self.link.telemetry.pos_ned_m, "mission legs done")
        await self._stop_streaming()

    async def _stop_streaming(self) -> None:
        if self.driver is None:
            return
        self.link.inbound.batch_reads(None)
        await self.driver.stop()
        self.streamer.missed = self.driver.missed
        if self.recorder is not None:
            self.recorder.pace(False)

    def _on_link_change(self, connected: bool) -> None:
        if not connected:
            self._link_lost_at = self.clock.now_s()
            self.sink.event("link_lost")
            return
        lost_s = self.clock.now_s() - (self._link_lost_at or self.clock.now_s())
        self.sink.event("link_back", lost_s=round(lost_s, 2))
        if self.executor is not None:
            self.executor.legs.on_link_back(self.link.telemetry.pos_ned_m)

    # ------------------------------------------------------------------ the end
    async def shutdown(self) -> None:
        """Stop streaming and background tasks, write the summary, close the link."""
        if self.streamer is not None:
            await self._stop_streaming()
            self.sink.record("event", name="setpoint_jitter", **self.streamer.stats().as_dict())
        if self.executor is not None:
            self.sink.record("event", name="schedule", tasks=self.executor.schedule.report())
        if self.threats is not None:
            counts = self.threats.bus.stats()
            self.summary.threat_updates = counts["received"]
            self.sink.record("event", name="threat_bus", **counts)
            if self.threats.fleet is not None:
                self.summary.fleet = self.threats.fleet.summary()
                self.sink.record("event", name="fleet", **self.summary.fleet)
            await self.threats.stop()
        if self.snapshots is not None:
            self.snapshots.close()
        if self.watchers is not None:
            await self.watchers.stop()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._summarise()
        self.sink.record("summary", **self.summary.as_dict())
        if self.recorder is not None:
            self.recorder.close()
        if self._owns_live:
            self.live.close()
        self.workers.shutdown()
        if self._stop_link_listener is not None:
            self._stop_link_listener()
        if self.owns_link:
            await self.link.aclose()

    def _summarise(self) -> None:
        avoidance = self.executor.avoidance if self.executor is not None else None
        if self.threats is not None:
            self.summary.decisions = self.threats.rejected + (avoidance.decisions if avoidance else 0)
        if avoidance is not None:
            self.summary.latency_ms = {
                kind: {
                    "n": len(v),
                    "p50": float(np.percentile(v, 50)),
                    "p99": float(np.percentile(v, 99)),
                    "max": float(np.max(v)),
                }
                for kind, v in avoidance.latencies_ms.items()
            }
        errors = self.watchers.errors_m if self.watchers is not None else []
        if errors:
            err = np.asarray(errors)
            self.summary.rms_tracking_error_m = float(np.sqrt(np.mean(err**2)))
            self.summary.max_tracking_error_m = float(err.max())
