"""The daemon's mission: taken from a file or the vehicle, planned before takeoff, put back
when the flight does not start; the threat snapshot; the end of the flight (``companion.daemon``)."""

from __future__ import annotations

import logging
import time

import numpy as np

from companion.config import settings_to_dict
from companion.errors import CompanionError, MissionError
from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.plan import LegPlan, plan_mission
from companion.service.startup import AUX_MOTOR_INTERLOCK, is_airborne
from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.flight.resume import resume_mission, resume_refusal
from companion.service.summary import CheckerHandle, feasibility_totals, make_checker, warm_process_checker
from companion.threats.snapshot import SnapshotWriter, load_live_threats, snapshot_path
from companion.world import world_to_dict

log = logging.getLogger(__name__)

__all__ = ["MissionTasks"]


class MissionTasks:
    """Mixin of ``CompanionDaemon``: the mission before, and the landing after, the legs."""

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
            raise MissionError("the vehicle has no mission: upload one (companion upload FILE, "
                               "QGroundControl, MAVProxy) or pass --mission FILE")
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
            self.checker = await self.closed_loop_checker(s.feasibility)
        self.legs = await self.in_worker(plan_mission, to_fly, first, pipeline=self.pipeline(),
                                         settings=s.flight, rng=self.rng)
        self.summary.legs_planned = len(self.legs)
        self.summary.feasibility = feasibility_totals(self.legs)
        self.record("world", **world_to_dict(self.local_mission.world))
        for leg in self.legs:
            self.record_plan(leg)
        self.event("planned", legs=len(self.legs), seconds=round(time.perf_counter() - t0, 3),
                   seed=s.seed, feasibility=self.summary.feasibility or None)
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
        await self._workers_ready
        await self.workers.on_each(warm_process_checker, settings)
        return CheckerHandle(settings)

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
                await self.link.missions.upload_plan(previous)
            else:
                await self.link.missions.clear_plan()
            self.event("mission_restored", reason="the flight did not start")
        except CompanionError as exc:
            log.error("could not restore the vehicle's previous mission: %s", exc)

    # ------------------------------------------------------------------ threat snapshot
    def _open_snapshots(self, home) -> None:
        """Write the threat snapshot from now on when ``state.dir`` is set (``companion.threats.snapshot``)."""
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
            await self.link.commands.land()
            self.event("landing")
            await self.link.waits.wait_for(lambda t: t.armed is False, 60.0 + 120.0 / self.clock.scale,
                                     "the landing and disarm")
            self.summary.landed = True
            self.event("landed")
            if self.rotor_plan is not None and self.rotor_plan.interlock == "command":
                await self.link.commands.aux_function(AUX_MOTOR_INTERLOCK, 0)    # as the start found it
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
        refusal = resume_refusal(mission_items=1, airborne=is_airborne(
            self.link.telemetry, self.settings.startup.join_min_height_m))
        if refusal is not None:
            raise MissionError(refusal)
        seq = await self.read_mission_current(self.settings.state.mission_current_timeout_s)
        self.summary.resumed_at_seq = seq
        self.event("resume", current_seq=seq, pos_ned_m=self.link.telemetry.pos_ned_m,
                   mode=self.link.telemetry.mode_name)
        return seq
