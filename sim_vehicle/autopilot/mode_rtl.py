"""RTL: climb to RTL_ALT (or stay higher), fly to the nearest of home and the rally points, land."""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np

from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode import RTL, Mode
from sim_vehicle.autopilot.mode_context import ModeContext
from sim_vehicle.config import FlightSettings
from sim_vehicle.frames import Frames

log = logging.getLogger(__name__)


class ModeRTL(Mode):
    """RTL (6): the stages of :func:`rtl_stages`; refused on the ground."""

    number = RTL

    def arming_refusal(self, ap: ModeContext) -> str | None:
        return f"cannot arm in {self.name}"

    def entry_refusal(self, ap: ModeContext) -> str | None:
        return "RTL: landed" if ap.armed and ap.landed else None

    def enter(self, ap: ModeContext) -> None:
        ap.navigation.set_stages(rtl_stages(ap.pos_ned_m, ap.frames, ap.settings.flight, ap.mission.rally_ned_m))


def rtl_stages(pos: np.ndarray, frames: Frames, f: FlightSettings, rally_ned_m: Sequence[np.ndarray]) -> list[Stage]:
    """Climb (if below RTL_ALT), fly level to the destination, land (RTL mode and NAV_RETURN_TO_LAUNCH).

    From ``pos`` (3,) m NED in the ground frame to the nearest of home and the rally points
    (each (3,) m NED), at RTL_ALT (``f.rtl_alt_m``) above home or higher.
    """
    height = frames.height_above_home(pos)
    alt_m = max(f.rtl_alt_m, height)
    down = min(frames.down_at_height_above_home(alt_m), float(pos[2]))
    stages = []
    if height < alt_m - 0.5:
        stages.append(Stage("leg", target=np.array([pos[0], pos[1], down]), radius_m=1.0))
    destination = rtl_destination(pos, frames, rally_ned_m)
    stages.append(Stage("leg", target=np.array([destination[0], destination[1], down])))
    stages.append(Stage("land"))
    return stages


def rtl_destination(pos: np.ndarray, frames: Frames, rally_ned_m: Sequence[np.ndarray]) -> np.ndarray:
    """Nearest (horizontally) to ``pos`` of home and the rally points, (3,) m NED."""
    candidates = [frames.home_ground_ned_m.copy()] + list(rally_ned_m)
    distances = [math.hypot(c[0] - pos[0], c[1] - pos[1]) for c in candidates]
    best = candidates[int(np.argmin(distances))]
    if best is not candidates[0]:
        log.info("RTL to rally point at N %.1f E %.1f", best[0], best[1])
    return best
