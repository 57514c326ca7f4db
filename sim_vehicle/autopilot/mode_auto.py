"""AUTO: fly the mission list (sequencing in :mod:`sim_vehicle.autopilot.mission`)."""

from __future__ import annotations

from sim_vehicle.autopilot.mode import AUTO, Mode
from sim_vehicle.autopilot.mode_context import ModeContext


class ModeAuto(Mode):
    """AUTO (3): needs a mission with a NAV item after the home item 0; resumes at the current item."""

    number = AUTO
    accepts_condition_yaw = True

    def arming_refusal(self, ap: ModeContext) -> str | None:
        return None if ap.mission.has_mission else "AUTO: no mission (upload one with a NAV item after item 0)"

    def entry_refusal(self, ap: ModeContext) -> str | None:
        return "AUTO: no mission" if ap.armed and not ap.mission.has_mission else None

    def enter(self, ap: ModeContext) -> None:
        ap.mission.start(ap.mission.resume_seq())

    def enter_landed(self, ap: ModeContext) -> None:
        self.enter(ap)

    def on_armed(self, ap: ModeContext) -> None:
        ap.mission.start(ap.mission.resume_seq())

    def run(self, ap: ModeContext, t_s: float) -> None:
        ap.mission.advance(t_s)
