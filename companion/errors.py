"""Error hierarchy: one ``CompanionError`` subclass per stage.

Expected outcomes (no path in the budget, start inside an obstacle) are values, not exceptions.
These are for wrong arguments and bad input; every message names the argument, key, field or
line at fault, so the CLI can print it as one line.
"""


class CompanionError(Exception):
    """Base class of every error the companion raises on purpose."""


class ConfigError(CompanionError, ValueError):
    """A settings file or value is wrong (the message names the dotted key)."""


class WorldError(CompanionError, ValueError):
    """A world, obstacle or world file is invalid."""


class PlanningError(CompanionError, ValueError):
    """Planner arguments are invalid (bad shapes, NaN, non-positive step, ...)."""


class SmoothingError(CompanionError, ValueError):
    """Smoother or timing arguments are invalid (fewer than 2 nodes, K_max <= 0, ...)."""


class TrajectoryError(CompanionError, ValueError):
    """A trajectory cannot be built or sampled as asked."""


class MissionError(CompanionError, ValueError):
    """A mission file or mission item is invalid or unsupported."""


class ThreatPayloadError(CompanionError, ValueError):
    """A threat payload is invalid; the message names the field."""


class ThreatBusError(CompanionError):
    """The zenoh session cannot be opened or used (bad endpoint, port in use, closed)."""


class LinkError(CompanionError):
    """The vehicle link failed (no autopilot, refused command, upload failed)."""


class VehicleRefused(LinkError):
    """The vehicle answered a command with anything but ACCEPTED (arm, takeoff, mode, interlock)
    or did not do what it accepted; ``result`` is the MAV_RESULT (None when not a command)."""

    def __init__(self, message: str, result: int | None = None):
        super().__init__(message)
        self.result = result


class FlightAborted(CompanionError):
    """The flight cannot go on (pilot took over, vehicle disarmed, leg not reached, start-up
    failed after the vehicle left the ground): the vehicle is held, or left on the ground."""


class ProcessError(CompanionError):
    """A child process (``companion.sitl``) could not be started, or exited or timed out before
    it was ready; the message names the process and its log."""
