"""The daemon's legs: start or join, then fly each leg with the phase machine of
``companion.flight.phases``; replans after a link loss and ways back after an evasion (``companion.daemon``)."""

from __future__ import annotations

import asyncio
import logging
import math
import time

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.mavlink_ids import COPTER_MODES

from companion.errors import CompanionError, FlightAborted, LinkError
from companion.flight.plan import LegPlan, plan_leg
from companion.service.startup import is_airborne, read_rotor_parameters, rotor_plan, start_vehicle
from companion.flight.phases import ActionKind, LegObservation, LegState, leg_step

log = logging.getLogger(__name__)

__all__ = ["LegTasks", "GUIDED"]

GUIDED = COPTER_MODES["GUIDED"]
#: Wall-clock period of the leg's phase machine (``leg_step``): the vehicle's position arrives at
#: 10 Hz, so stepping faster only repeats the same observation.
PHASE_STEP_PERIOD_S = 0.1


class LegTasks:
    """Mixin of ``CompanionDaemon``: starting the vehicle and flying the legs."""

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
            self.event("joined", height_m=None if tele.height_m is None else round(tele.height_m, 2),
                       mode=tele.mode_name, landed_state=tele.landed_state)
            if tele.mode != GUIDED:
                await self.link.commands.set_mode("GUIDED")
            if self.resume:        # the crashed companion engaged the interlock: put it back at the end
                self.rotor_plan = rotor_plan(st, await read_rotor_parameters(self.link, st))
            return
        self.rotor_plan = await start_vehicle(
            self.link, st, alt_m, self.clock.now_s, time_scale=self.clock.scale,
            climb_speed_m_s=self.settings.flight.climb_speed_m_s, event=self.event)
        self.event("takeoff_complete", alt_m=alt_m)

    async def resume_leg(self, leg: LegPlan) -> None:
        """Replan the rest of ``leg`` from where the vehicle is (after a link loss)."""
        self._resume_needed = False
        pos = self.link.telemetry.pos_ned_m
        s = self.settings
        new = await self.in_worker(plan_leg, leg.index, leg.waypoint, pos, self.local_mission.world,
                                   pipeline=self.pipeline(), settings=s.flight, rng=self.rng)
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
        """What the leg's state machine (``companion.flight.phases.leg_step``) sees now."""
        tele, ref = self.link.telemetry, self.reference
        radius = leg.waypoint.acceptance_radius_m
        return LegObservation(
            t_s=self.clock.now_s(), seq=leg.waypoint.seq, connected=tele.connected, armed=tele.armed,
            guided=None if tele.mode is None else tele.mode == GUIDED, mode_name=tele.mode_name,
            relink_pending=self._resume_needed,
            dist_to_goal_m=math.inf if tele.pos_ned_m is None else
            math.dist(tele.pos_ned_m.tolist(), leg.goal_ned_m.tolist()),
            acceptance_radius_m=radius, ref_end_t_s=None if ref is None else ref.t_end_s,
            ref_ends_short=ref is not None and ref.end_gap_m(leg.goal_ned_m) > radius,
            ref_resume=ref is not None and ref.resume,
            timeout_margin_s=self.settings.link.leg_timeout_margin_s)

    async def fly_leg(self, leg: LegPlan) -> None:
        """Fly one leg: observe, step the phase machine (``companion.flight.phases``), act; until the
        reference has ended and the vehicle is within the acceptance radius."""
        self.leg_index = leg.index
        self._tasks.append(asyncio.get_running_loop().create_task(
            self.set_mission_current(leg.waypoint.seq), name="set-mission-current"))
        ref = self.engage(leg.trajectory, f"leg{leg.index}", turn=True)
        if self.threats is not None:
            self.threats.on_leg_started(leg, ref)
        state = LegState()
        while True:
            await self.pause(PHASE_STEP_PERIOD_S)
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
            await asyncio.sleep(leg.waypoint.hold_s / self.clock.scale)

    async def set_mission_current(self, seq: int) -> None:
        """Make ``seq`` (the goal of the leg now flown) the vehicle's current mission item
        (MAV_CMD_DO_SET_MISSION_CURRENT, accepted in GUIDED): ground stations show it, and a
        companion restarted with ``--resume`` reads it back. Never fails the flight."""
        try:
            result = await self.link.commands.command_result(
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
            async for fields in self.link.inbound.messages("MISSION_CURRENT"):
                if fields.get("_sysid") == self.link.target_system:
                    return int(fields["seq"])
            raise LinkError("the MISSION_CURRENT subscription ended")

        task = asyncio.get_running_loop().create_task(first_seq(), name="mission-current")
        deadline = time.monotonic() + timeout_s
        try:
            while time.monotonic() < deadline:
                await self.link.commands.command_result(mavlink.MAV_CMD_REQUEST_MESSAGE,
                                               (float(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT),),
                                               what="REQUEST_MESSAGE MISSION_CURRENT", timeout_s=1.0)
                done, _ = await asyncio.wait({task}, timeout=min(1.0, max(0.0, deadline - time.monotonic())))
                if done:
                    return task.result()
        finally:
            task.cancel()
        raise LinkError(f"timed out after {timeout_s:g} s waiting for the vehicle's MISSION_CURRENT")
