"""Flight modes: the numbers (from pymavlink) and the base class every ``mode_*`` module extends.

As ArduCopter's ``Mode`` (``mode.h``): each mode says whether it allows arming and entry, what
the vehicle does when it is entered, and what it runs every control tick. A mode keeps no state
of its own; it acts on the vehicle it is given through the small interface of
:mod:`~sim_vehicle.autopilot.mode_context` (the :class:`~sim_vehicle.autopilot.Autopilot`
provides it), as ArduPilot's modes act on ``copter``. With no RC pilot, STABILIZE and ALT_HOLD hold
position like LOITER.
"""

from __future__ import annotations

from heli_common.mavlink_ids import COPTER_MODES, copter_mode_name
from sim_vehicle.autopilot.legs import Stage
from sim_vehicle.autopilot.mode_context import ModeContext

# ArduCopter flight modes (custom_mode of HEARTBEAT; numbers from pymavlink's mode_mapping_acm)
STABILIZE = COPTER_MODES["STABILIZE"]
ALT_HOLD = COPTER_MODES["ALT_HOLD"]
AUTO = COPTER_MODES["AUTO"]
GUIDED = COPTER_MODES["GUIDED"]
LOITER = COPTER_MODES["LOITER"]
RTL = COPTER_MODES["RTL"]
LAND = COPTER_MODES["LAND"]
BRAKE = COPTER_MODES["BRAKE"]
#: the modes this vehicle flies, number -> name
MODE_NAMES = {
    number: copter_mode_name(number) for number in (STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, BRAKE)
}
MODE_NUMBERS = {name: number for number, name in MODE_NAMES.items()}


class QuietRefusal(str):
    """A refusal reason that is logged but not sent as STATUSTEXT (ArduPilot sends none there)."""


def mode_name(mode: int) -> str:
    """ArduCopter mode name of ``mode`` (or ``MODE_<n>``)."""
    return MODE_NAMES.get(mode, f"MODE_{mode}")


class Mode:
    """A flight mode; the defaults are those of a mode that brakes to a hover and holds there.

    Attributes
    ----------
    number : int
        ArduCopter mode number (HEARTBEAT.custom_mode).
    accepts_condition_yaw : bool
        Whether MAV_CMD_CONDITION_YAW is obeyed in this mode.
    """

    number: int = -1
    accepts_condition_yaw: bool = False

    @property
    def name(self) -> str:
        """ArduCopter name of the mode."""
        return mode_name(self.number)

    def arming_refusal(self, ap: ModeContext) -> str | None:
        """Why the vehicle may not arm in this mode (None: it may)."""
        return None

    def entry_refusal(self, ap: ModeContext) -> str | None:
        """Why an armed vehicle may not switch to this mode now (None: it may)."""
        return None

    def enter(self, ap: ModeContext) -> None:
        """Entered while armed and in the air: brake to a hover."""
        ap.navigation.set_stages([Stage("hold", target=ap.navigation.brake_point())])

    def enter_landed(self, ap: ModeContext) -> None:
        """Entered while armed on the ground: nothing to fly."""
        ap.navigation.set_stages([])

    def on_armed(self, ap: ModeContext) -> None:
        """Called once the vehicle has armed in this mode."""

    def run(self, ap: ModeContext, t_s: float) -> None:
        """Every control tick while armed (after the fence check), before the stages advance."""
