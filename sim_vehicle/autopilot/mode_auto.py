"""AUTO: fly the mission list (sequencing in :mod:`sim_vehicle.autopilot.mission`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from sim_vehicle.autopilot.mode import AUTO, Mode

if TYPE_CHECKING:
    from sim_vehicle.autopilot.core import Autopilot


class ModeAuto(Mode):
    """AUTO (3): needs a mission with a NAV item after the home item 0; resumes at the current item."""

    number = AUTO
    accepts_condition_yaw = True

    def arming_refusal(self, ap: Autopilot) -> str | None:
        return None if ap.has_mission else "AUTO: no mission (upload one with a NAV item after item 0)"

    def entry_refusal(self, ap: Autopilot) -> str | None:
        return "AUTO: no mission" if ap.armed and not ap.has_mission else None

    def enter(self, ap: Autopilot) -> None:
        ap._start_mission(ap._resume_seq())

    def enter_landed(self, ap: Autopilot) -> None:
        self.enter(ap)

    def on_armed(self, ap: Autopilot) -> None:
        ap._start_mission(ap._resume_seq())

    def run(self, ap: Autopilot, t_s: float) -> None:
        ap._advance_mission(t_s)
