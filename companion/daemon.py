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
   each leg flown by the pure phase machine of ``companion.flight.phases`` (observe, step, act): done
   when its reference has ended and the vehicle is within the acceptance radius, then the hold
   time; a reference that ended short of the goal (an evasion or a hold) is followed by a plan
   back to the mission;
5. land or RTL as the mission says (RTL is flown as a planned leg home, then LAND).

Around it: zenoh status at 2 Hz and on every event, the threat reactor
(``companion.threats.reactor``: threats in, a >= 10 Hz monitor, decisions that swap the active
reference, events, path and STATUSTEXT out), ADS-B traffic as threats (``[adsb] enabled``,
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

The jobs live in ``companion.service``: the background tasks (``background``), the mission
before and the landing after the legs (``mission``), the legs (``legs``) and the summary
(``summary``); this module puts them together. Only these, ``companion.link`` and
``companion.threats`` (bus, reactor) do I/O. The event-loop thread that streams setpoints runs
at real-time priority when allowed (``raise_stream_priority``); planning, smoothing, the
feasibility check, threat decisions and M-GART refreshes run in two warm, niced worker
processes (``companion.workers``; the threat manager's state is adopted back after each call),
so the 50 Hz period holds while a replan runs; a short GIL switch interval hands the GIL back
to the stream from the link's own threads. An M-GART refresh with no threat held, on the same
leg and reference as the last one, is not run (``companion.workers.AlternativesGate``).
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import sys

import numpy as np

from companion.config import Settings
from companion.errors import FlightAborted, LinkError, MissionError, VehicleRefused
from companion.flight.plan import LegPlan
from companion.flight.reference import ActiveReference, VehicleClock
from companion.link.gate import SigningKey
from companion.link.setpoints import SetpointStreamer, hold_position, normal_priority, raise_stream_priority
from companion.service.startup import is_airborne
from companion.link.vehicle import VehicleLink
from companion.view.sinks import RecordSinks, open_record_sinks, parse_foxglove_address
from companion.service.background import ZENOH_WATCH_PERIOD_S, BackgroundTasks
from companion.service.legs import GUIDED, LegTasks
from companion.service.mission import MissionTasks
from companion.service.summary import FlightSummary, feasibility_totals, make_checker
from companion.threats.snapshot import SnapshotWriter
from companion.threats.reactor import ThreatReactor
from companion.workers import AlternativesGate, PlanningWorkers

log = logging.getLogger(__name__)

#: GIL switch interval (s): another thread of this process hands the GIL to the setpoint
#: stream this often.
GIL_SWITCH_INTERVAL_S = 0.0005


__all__ = ["CompanionDaemon", "FlightAborted", "FlightSummary", "feasibility_totals", "make_checker",
           "GUIDED", "ZENOH_WATCH_PERIOD_S"]


def companion_link(settings: Settings, onboard=None) -> VehicleLink:
    """The companion's link to its vehicle, as ``settings.link`` and ``settings.adsb`` say (not
    connected yet); ``onboard``: speak as the companion component too (``companion serve``)."""
    return VehicleLink("companion", streams=settings.link.streams, adsb=settings.adsb.enabled,
                       signing_key=SigningKey.from_file(settings.link.signing_key_file),
                       tlog_path=settings.link.tlog_file or None, onboard=onboard)


class CompanionDaemon(BackgroundTasks, MissionTasks, LegTasks):
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
        snapshot in ``state.dir`` (``companion.threats.snapshot``). Refused (``MissionError``) without a
        mission on the vehicle or with the vehicle on the ground.
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
    """

    def __init__(self, settings: Settings, *, mission_path=None, world_path=None,
                 record_path=None, resume: bool = False, workers: str = "process",
                 link: VehicleLink | None = None, bus=None):
        if resume and mission_path is not None:
            raise MissionError("--resume flies the mission stored on the vehicle: leave out --mission")
        self.settings = settings
        self.resume = resume
        self.snapshots: SnapshotWriter | None = None
        self.mission_path = mission_path
        self.world_path = world_path
        self.record_path = record_path
        self.rng = np.random.default_rng(settings.seed)
        self.owns_link = link is None
        self.link = link if link is not None else companion_link(settings)
        self.bus = bus
        self._stop_link_listener = None
        self.clock = VehicleClock(settings.link.time_scale or 1.0)   # the vehicle's, once connected
        self.streamer: SetpointStreamer | None = None
        self.reference: ActiveReference | None = None
        self.recorder: RecordSinks | None = None
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
        self.workers = PlanningWorkers(workers)
        self._workers_ready: asyncio.Future | None = None

    async def in_worker(self, fn, /, *args, **kwargs):
        """Run ``fn(*args, **kwargs)`` in a planning worker (``companion.workers``), once the
        workers are warm."""
        if self._workers_ready is not None:
            await self._workers_ready
        return await self.workers.run(fn, *args, **kwargs)

    # ------------------------------------------------------------------ recording and status
    def _open_record(self) -> RecordSinks:
        """The record's sinks: ``--record`` (MCAP or JSON Lines) and the live Foxglove server."""
        s = self.settings
        foxglove = parse_foxglove_address(s.view.foxglove, "view.foxglove") if s.view.foxglove else None
        with normal_priority():              # the live server's threads never at the stream's priority
            sinks = open_record_sinks(self.record_path, foxglove, s.threats.horizon_s, s.threats.uncertainty_m_s)
        for sink in sinks.sinks:
            if getattr(sink, "port", None):
                log.info("Foxglove live view: ws://%s:%d (Foxglove: open connection, Foxglove WebSocket)",
                         foxglove[0], sink.port)
        return sinks

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
        return {"t_s": round(self.clock.now_s(), 3), "sysid": self.settings.zenoh.sysid,
                "home_lla": self.home_lla, "mode": tele.mode_name, "armed": tele.armed,
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
            self.streamer.set_source(ref.setpoint_at, prepare=ref.prepare)
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
        self.link.direct.send_statustext(text, severity=severity)

    def hold_here(self, pos_ned_m, reason: str) -> None:
        """Hold ``pos_ned_m`` (a hover) as the active reference."""
        yaw = self._current_yaw()
        self.reference = None
        if self.streamer is not None:
            self.streamer.set_source(hold_position(pos_ned_m, yaw))
        self.event("hold", reason=reason, pos_ned_m=np.asarray(pos_ned_m))

    def pause(self, delay_s: float):
        """Sleep ``delay_s`` (the phase machine's and the record's periods): in the setpoint
        stream's wake-ups while it runs (``SetpointStreamer.sleep``)."""
        if self.streamer is not None:
            return self.streamer.sleep(delay_s)
        return asyncio.sleep(delay_s)

    def _current_yaw(self) -> float:
        att = self.link.telemetry.attitude_rad
        return float(att[2]) if att is not None else 0.0

    # ------------------------------------------------------------------ background tasks
    async def run(self) -> FlightSummary:
        """Fly the mission (see the module docstring); returns the summary."""
        s = self.settings
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
        # the workers start before the stream's priority is raised and before any thread of
        # the link exists (the forkserver is exec'd from here); they warm up meanwhile
        self._workers_ready = self.workers.start()
        self.recorder = self._open_record()
        if self.owns_link:
            raise_stream_priority()          # before connect: MAVSDK's threads inherit it
            await self.link.connect(s.link.connect, s.link.connect_timeout_s)
        try:
            await self._take_time_scale()
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

    async def _take_time_scale(self) -> None:
        """The vehicle's speed-up (``SIM_SPEEDUP``) unless ``link.time_scale`` is given; 1 for a
        vehicle without that parameter. Every later reader sees it in ``self.settings``."""
        link = self.settings.link
        scale, source = link.time_scale, "given"
        if scale is None:
            got = await self.link.commands.read_params(["SIM_SPEEDUP"],
                                                       timeout_s=self.settings.startup.param_timeout_s)
            value = got.get("SIM_SPEEDUP", math.nan)
            scale, source = ((value, "the vehicle's SIM_SPEEDUP") if math.isfinite(value) and value > 0
                             else (1.0, "real time: the vehicle has no SIM_SPEEDUP"))
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
        tele = self.link.telemetry                   # positions about home from here on
        self.event("frames", home_lla=home, ekf_origin_lla=frames.origin_lla,
                   home_in_origin_ned_m=np.round(frames.home_in_origin_ned_m, 3))
        current_seq = await self.resume_point() if self.resume else None
        plan = await self.take_mission()
        alt = await self.plan_flight(plan, home, tele, current_seq)
        previous = None
        if self.mission_path is not None:          # planned: every item is reachable
            previous = await self.link.missions.download_plan()
            await self.link.missions.upload_plan(plan)
            self.event("mission_uploaded", file=str(self.mission_path), items=len(plan.items))
        if s.zenoh.enabled:
            self.threats = ThreatReactor(
                s, clock_now_s=self.clock.now_s, in_worker=AlternativesGate(self.in_worker), rng=self.rng,
                engage=self.engage, send_now=self.send_now, reference=lambda: self.reference,
                position_ned_m=lambda: self.link.telemetry.pos_ned_m, record=self.record,
                statustext=self.send_statustext, bus=self.bus,
                keep_bus_open=self.bus is not None, pause=self.pause)
            with normal_priority():          # zenoh's threads never at the stream's priority
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
        self.streamer = SetpointStreamer(self.link.direct.send_setpoint, rate_hz=s.link.setpoint_rate_hz)
        self.recorder.pace(self.streamer.call_after_next_tick)     # the record is written between sends
        self.hold_here(self.link.telemetry.pos_ned_m,
                       "joined in the air" if self.summary.joined else "takeoff complete")
        self.streamer.start()
        self.link.inbound.batch_reads(self.streamer)              # telemetry taken at the stream's ticks
        for leg in self.legs:
            await self.fly_leg(leg)
        self.hold_here(self.link.telemetry.pos_ned_m, "mission legs done")
        self.link.inbound.batch_reads(None)
        await self.streamer.stop()
        await self.finish(self.local_mission.end_action)
        self.summary.outcome = "completed"
        return self.summary

    async def shutdown(self) -> None:
        """Stop streaming and background tasks, write the summary, close the link."""
        if self.streamer is not None:
            self.link.inbound.batch_reads(None)
            await self.streamer.stop()
            jitter = self.streamer.stats()
            self.record("event", name="setpoint_jitter", **jitter.as_dict())
        if self.threats is not None:
            counts = self.threats.bus.stats()
            self.summary.threat_updates = counts["received"]
            self.record("event", name="threat_bus", **counts)
            if self.threats.fleet is not None:
                self.summary.fleet = self.threats.fleet.summary()
                self.record("event", name="fleet", **self.summary.fleet)
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
        self.workers.shutdown()
        if self._stop_link_listener is not None:
            self._stop_link_listener()
        if self.owns_link:
            await self.link.aclose()
