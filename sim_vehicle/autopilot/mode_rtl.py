"""RTL: climb to RTL_ALT (or stay higher), fly to the nearest of home and the rally points, land."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import RTL, Mode

if TYPE_CHECKING:
    from sim_vehicle.autopilot.core import Autopilot

log = logging.getLogger(__name__)


class ModeRTL(Mode):
    """RTL (6): the stages of :func:`rtl_stages`; refused on the ground."""

    number = RTL

    def arming_refusal(self, ap: Autopilot) -> str | None:
        return f"cannot arm in {self.name}"

    def entry_refusal(self, ap: Autopilot) -> str | None:
        return "RTL: landed" if ap.armed and ap.landed else None

    def enter(self, ap: Autopilot) -> None:
        ap._stages = rtl_stages(ap)


def rtl_stages(ap: Autopilot) -> list[Stage]:
    """Climb (if below RTL_ALT), fly level to the destination, land (RTL mode and NAV_RETURN_TO_LAUNCH)."""
    f = ap.settings.flight
    pos = ap.pos_ned_m
    height = ap.frames.height_above_home(pos)
    alt_m = max(f.rtl_alt_m, height)
    down = min(ap.frames.down_at_height_above_home(alt_m), float(pos[2]))
    stages = []
    if height < alt_m - 0.5:
        stages.append(Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=1.0))
    destination = rtl_destination(ap, pos)
    stages.append(Stage("leg", target=np.array([destination[0], destination[1], down])))
    stages.append(Stage("land"))
    return stages


def rtl_destination(ap: Autopilot, pos: np.ndarray) -> np.ndarray:
    """Nearest (horizontally) of home and the rally points."""
    candidates = [ap.frames.home_ground_ned_m.copy()] + list(ap.rally_ned_m)
    distances = [math.hypot(c[0] - pos[0], c[1] - pos[1]) for c in candidates]
    best = candidates[int(np.argmin(distances))]
    if best is not candidates[0]:
        log.info("RTL to rally point at N %.1f E %.1f", best[0], best[1])
    return best
