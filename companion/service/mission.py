"""The daemon's mission and vehicle, before and after the legs (``companion.daemon``).

``MissionService`` takes the mission (the file given, validated, or the vehicle's own), converts
and plans every leg before takeoff (in a planning worker; an unreachable waypoint is an error
before anything moves), starts the vehicle or joins it in the air, keeps the vehicle's current
mission item at the goal of the leg flown (a companion restarted with ``--resume`` reads it
back), puts the vehicle's previous mission back when the flight does not start, and lands or
loiters at the end. MAVLink through the ``VehicleLink``; events and the record through the
daemon's ``FlightSink``.
"""

from __future__ import annotations

import asyncio
import logging
import time

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.config import settings_to_dict
from companion.errors import CompanionError, LinkError, MissionError
from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.plan import LegPlan, plan_mission
from companion.flight.resume import resume_mission, resume_refusal
from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.service.startup import AUX_MOTOR_INTERLOCK, is_airborne, read_rotor_parameters, rotor_plan, start_vehicle
from companion.service.summary import (
    CheckerHandle,
    FlightSummary,
    feasibility_totals,
    make_checker,
    warm_process_checker,
)
from companion.world import world_to_dict
from heli_common.mavlink_ids import COPTER_MODES

log = logging.getLogger(__name__)

__all__ = ["MissionService", "GUIDED"]

GUIDED = COPTER_MODES["GUIDED"]


class MissionService:
    """The mission before and after the legs (see the module docstring).

    Parameters
    ----------
    settings : companion.config.Settings
        The flight's settings (time scale and zenoh prefix already resolved).
    link : VehicleLink
    sink : FlightSink
        ``event`` and ``record``.
    workers : PlanningWorkers
        Where the legs are planned (warm: ``workers_ready`` awaited first).
    workers_ready : awaitable
    summary : FlightSummary
    clock : VehicleClock
    mission_path, world_path : path or None
    resume : bool
    rng : numpy.random.Generator
    """

    def __init__(
        self,
        settings,
        *,
        link,
        sink,
        workers,
        workers_ready,
        summary: FlightSummary,
        clock,
        mission_path=None,
        world_path=None,
        resume: bool = False,
        rng=None,
    ) -> None:
        self.settings = settings
        self.link = link
        self.sink = sink
        self.workers = workers
        self.workers_ready = workers_ready
        self.summary = summary
        self.clock = clock
        self.mission_path = mission_path
        self.world_path = world_path
        self.resume = resume
        self.rng = rng if rng is not None else np.random.default_rng(settings.seed)
        self.local_mission = None
        self.legs: list[LegPlan] = []
        self.checker = None  # closed-loop feasibility (settings.feasibility)
        self.rotor_plan = None  # how the start-up handled the rotor

    def event(self, name: str, **fields) -> None:
        self.sink.event(name, **fields)

    def record(self, line_type: str, /, **fields) -> None:
        self.sink.record(line_type, **fields)

    async def in_worker(self, fn, /, *args, **kwargs):
        await self.workers_ready
        return await self.workers.run(fn, *args, **kwargs)

    async def take_mission(self):
        """The mission to fly: the file given (validated here, uploaded after planning) or the
        vehicle's own mission and fence."""
        if self.mission_path is not None:
            return load_mission_file(self.mission_path)
        plan = await self.link.missions.download_plan()
        if self.resume:
            refusal = resume_refusal(mission_items=len(plan.items), airborne=True)
            if refusal is not None:
                raise MissionError(refusal)
        if not plan.items:
            raise MissionError(
                "the vehicle has no mission: upload one (companion upload FILE, "
                "QGroundControl, MAVProxy) or pass --mission FILE"
            )
        self.event("mission_downloaded", items=len(plan.items))
        return plan

    async def plan_flight(self, plan, home_lla, tele, current_seq: int | None = None) -> float:
        """Convert and plan every leg (in a worker thread); errors name the mission item.

        With ``current_seq`` (a resume) only the goals from that mission item on are planned
        (``companion.flight.resume.resume_mission``), the first from where the vehicle is.
        Returns the takeoff altitude (m above home): the mission's takeoff item, or where the
        vehicle already flies.
        """
        s = self.settings
        self.local_mission = mission_to_local(plan, home_lla, settings=s.mission, world_file=self.world_path, dim=3)
        frames = self.link.frames
        self.record(
            "header",
            settings=settings_to_dict(s),
            seed=s.seed,
            home_lla=home_lla,
            ekf_origin_lla=frames.origin_lla,
            home_in_origin_ned_m=frames.home_in_origin_ned_m,
            mission=str(self.mission_path) if self.mission_path else "from the vehicle",
            waypoints_ned_m=[w.pos_ned_m for w in self.local_mission.waypoints],
        )
        start = tele.pos_ned_m
        flying = is_airborne(tele, s.startup.join_min_height_m)
        if flying:
            alt_m = -float(start[2])
        else:
            alt_m = -float(self.local_mission.waypoints[0].pos_ned_m[2])  # the (implied) takeoff
        first = np.array([start[0], start[1], -alt_m])
        to_fly = self.local_mission if current_seq is None else resume_mission(self.local_mission, current_seq)
        t0 = time.perf_counter()
        # the check flies the helicopter model: not a multirotor's
        if s.feasibility.enabled and s.startup.vehicle == "helicopter" and self.checker is None:
            self.checker = await self.closed_loop_checker(s.feasibility)
        self.legs = await self.in_worker(  # a generator of its own: values travel, not state
            plan_mission,
            to_fly,
            first,
            pipeline=self.pipeline(),
            settings=s.flight,
            rng=np.random.default_rng(self.rng.integers(2**63)),
        )
        self.summary.legs_planned = len(self.legs)
        self.summary.feasibility = feasibility_totals(self.legs)
        self.record("world", **world_to_dict(self.local_mission.world))
        for leg in self.legs:
            self.record_plan(leg)
        self.event(
            "planned",
            legs=len(self.legs),
            seconds=round(time.perf_counter() - t0, 3),
            seed=s.seed,
            feasibility=self.summary.feasibility or None,
        )
        return alt_m

    def pipeline(self) -> TrajectoryPipeline:
        """The legs' trajectory pipeline: the settings' planner, smoother and limits, and the
        closed-loop checker once it is designed (``closed_loop_checker``)."""
        s = self.settings
        return TrajectoryPipeline.from_settings(s.smoothing, s.planning, s.feasibility, closed_loop=self.checker)

    async def closed_loop_checker(self, settings):
        """The legs' feasibility checker: designed in a planning thread, or in every planning
        process (each keeps its own: ``CheckerHandle``)."""
        if self.workers.kind == "thread":
            return await self.in_worker(make_checker, settings)
        await self.workers_ready
        await self.workers.on_each(warm_process_checker, settings)
        return CheckerHandle(settings)

    def record_plan(self, leg: LegPlan) -> None:
        t = np.linspace(0.0, leg.trajectory.duration_s, max(2, int(leg.trajectory.duration_s * 5)))
        ref = leg.trajectory.sample(t)[0]
        tree = leg.plan.tree if leg.plan is not None else None
        self.record(
            "plan",
            leg=leg.index,
            seq=leg.waypoint.seq,
            path_id=f"leg{leg.index}",
            path_ned_m=leg.path_ned_m,
            reference_ne=ref[:, :2],
            tree={"nodes": tree.nodes, "parents": tree.parents} if tree is not None else None,
            summary=leg.plan.summary() if leg.plan is not None else None,
            duration_s=leg.trajectory.duration_s,
            notes=list(leg.notes),
            feasibility=leg.feasibility,
        )

    async def restore_mission(self, previous) -> None:
        """Put the vehicle's previous lists back (the flight did not start)."""
        try:
            if previous.items:
                await self.link.missions.upload_plan(previous)
            else:
                await self.link.missions.clear_plan()
            self.event("mission_restored", reason="the flight did not start")
        except CompanionError as exc:
            log.error("could not restore the vehicle's previous mission: %s", exc)

    async def wait_vehicle_clock(self, timeout_s: float) -> None:
        """Wait until the mission clock runs on the vehicle's time (a first LOCAL_POSITION_NED
        seen by the clock's watcher): references are timed on it."""
        await self.link.waits.wait_for(lambda t: self.clock.synced, timeout_s, "the vehicle's clock")

    async def start_or_join(self, alt_m: float) -> None:
        """Join a flying vehicle where it is (GUIDED, no arming, no takeoff), or start it
        (``companion.service.startup.start_vehicle``) and climb to ``alt_m`` above home."""
        tele = self.link.telemetry
        st = self.settings.startup
        if is_airborne(tele, st.join_min_height_m):
            self.summary.joined = True
            self.event(
                "joined",
                height_m=None if tele.height_m is None else round(tele.height_m, 2),
                mode=tele.mode_name,
                landed_state=tele.landed_state,
            )
            if tele.mode != GUIDED:
                await self.link.commands.set_mode("GUIDED")
            if self.resume:  # the crashed companion engaged the interlock: put it back at the end
                self.rotor_plan = rotor_plan(st, await read_rotor_parameters(self.link, st))
            return
        self.rotor_plan = await start_vehicle(
            self.link,
            st,
            alt_m,
            self.clock.now_s,
            time_scale=self.clock.scale,
            climb_speed_m_s=self.settings.flight.climb_speed_m_s,
            event=self.event,
        )
        self.event("takeoff_complete", alt_m=alt_m)

    async def set_mission_current(self, seq: int) -> None:
        """Make ``seq`` (the goal of the leg now flown) the vehicle's current mission item
        (MAV_CMD_DO_SET_MISSION_CURRENT, accepted in GUIDED): ground stations show it, and a
        companion restarted with ``--resume`` reads it back. Never fails the flight."""
        try:
            result = await self.link.commands.command_result(
                mavlink.MAV_CMD_DO_SET_MISSION_CURRENT,
                (float(seq),),
                what=f"DO_SET_MISSION_CURRENT {seq}",
                timeout_s=3.0,
            )
        except CompanionError as exc:  # the link is down: set again at the next leg
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
            async for fields in self.link.inbound.messages("MISSION_CURRENT"):
                if fields.get("_sysid") == self.link.target_system:
                    return int(fields["seq"])
            raise LinkError("the MISSION_CURRENT subscription ended")

        task = asyncio.get_running_loop().create_task(first_seq(), name="mission-current")
        deadline = time.monotonic() + timeout_s
        try:
            while time.monotonic() < deadline:
                await self.link.commands.command_result(
                    mavlink.MAV_CMD_REQUEST_MESSAGE,
                    (float(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT),),
                    what="REQUEST_MESSAGE MISSION_CURRENT",
                    timeout_s=1.0,
                )
                done, _ = await asyncio.wait({task}, timeout=min(1.0, max(0.0, deadline - time.monotonic())))
                if done:
                    return task.result()
        finally:
            task.cancel()
        raise LinkError(f"timed out after {timeout_s:g} s waiting for the vehicle's MISSION_CURRENT")

    async def finish(self, end_action: str) -> None:
        """Land (LAND or RTL missions) and wait for the disarm, or hover in LOITER."""
        if end_action in ("land", "rtl"):
            await self.link.commands.land()
            self.event("landing")
            await self.link.waits.wait_for(
                lambda t: t.armed is False, 60.0 + 120.0 / self.clock.scale, "the landing and disarm"
            )
            self.summary.landed = True
            self.event("landed")
            if self.rotor_plan is not None and self.rotor_plan.interlock == "command":
                await self.link.commands.aux_function(AUX_MOTOR_INTERLOCK, 0)  # as the start found it
        else:
            await self.link.commands.set_mode("LOITER")
            self.event("loiter", reason="the mission ends without LAND or RTL")

    async def safe_stop(self, reason: str) -> None:
        """Bring the vehicle to a hold, landing or RTL (per settings) when the flight stops."""
        tele = self.link.telemetry
        if not (tele.connected and tele.armed):
            return
        action = self.settings.link.on_interrupt
        try:
            if action == "land":
                await self.link.commands.land()
            elif action == "rtl":
                await self.link.commands.return_to_launch()
            else:
                await self.link.commands.set_mode("LOITER")
            self.event("safe_stop", action=action, reason=reason)
        except CompanionError as exc:
            log.error("safe stop (%s) failed: %s", action, exc)

    async def resume_point(self) -> int:
        """A resume: check that the vehicle flies and read its current mission item."""
        refusal = resume_refusal(
            mission_items=1, airborne=is_airborne(self.link.telemetry, self.settings.startup.join_min_height_m)
        )
        if refusal is not None:
            raise MissionError(refusal)
        seq = await self.read_mission_current(self.settings.state.mission_current_timeout_s)
        self.summary.resumed_at_seq = seq
        self.event(
            "resume", current_seq=seq, pos_ned_m=self.link.telemetry.pos_ned_m, mode=self.link.telemetry.mode_name
        )
        return seq
