"""The two local frames at the link edge: the companion's home frame and the vehicle's EKF frame.

The companion plans and flies in local NED metres about **home** (DESIGN section 3). ArduPilot's
LOCAL_POSITION_NED and SET_POSITION_TARGET_LOCAL_NED are about the **EKF origin**
(GPS_GLOBAL_ORIGIN), which is where the EKF first had a position and stays put for the whole
flight, while home may be elsewhere (MAV_CMD_DO_SET_HOME, or home reset at arming). The link
converts at its edge, in both directions, with one fixed translation:

    pos_home = pos_origin - home_in_origin,    home_in_origin = origin_frame.to_ned(home)

Velocities and accelerations are the same in both frames (both are NED tangent planes; over
the few hundred metres between the two origins their axes differ by microradians).

Why SET_POSITION_TARGET_LOCAL_NED plus this translation rather than
SET_POSITION_TARGET_GLOBAL_INT: the feedback (LOCAL_POSITION_NED) is in the vehicle's local
frame anyway, so one translation computed once serves both directions and no geodesy runs at
50 Hz; positions stay in metres (float, millimetres at these ranges) with the velocity and
acceleration feed-forward in the same frame; and a global target's altitude would refer either
to home (which ArduPilot may move at arming) or to the EKF's altitude datum, the very ambiguity
the translation removes. ``sim-vehicle`` and ArduPilot interpret LOCAL_NED targets the same way.

The planning home is frozen when the flight is planned (``VehicleLink.set_planning_home``): a
later change of the vehicle's home does not move the mission.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.geo import LocalFrame

__all__ = ["LinkFrames"]


@dataclass(frozen=True)
class LinkFrames:
    """Home frame <-> EKF-origin frame (see the module docstring).

    Parameters
    ----------
    home_lla : (lat_deg, lon_deg, alt_m AMSL) or None
        The planning home; None: not set yet (identity).
    origin_lla : (lat_deg, lon_deg, alt_m AMSL) or None
        The vehicle's EKF origin (GPS_GLOBAL_ORIGIN); None: the vehicle reports none and its
        local frame is taken to be home's (``sim-vehicle``, or a vehicle without an EKF origin).

    Attributes
    ----------
    home_in_origin_ned_m : ndarray (3,)
        Home in the origin frame (zero when the frames coincide).

    Examples
    --------
    >>> f = LinkFrames.build((47.3978, 8.5456, 490.0), (47.3977, 8.5456, 488.0))
    >>> [round(float(v), 1) + 0.0 for v in f.home_in_origin_ned_m]
    [11.1, 0.0, -2.0]
    >>> [round(float(v), 1) + 0.0 for v in f.to_home([11.12, 0.0, -2.0])]
    [0.0, 0.0, 0.0]
    """

    home_lla: tuple | None = None
    origin_lla: tuple | None = None
    home_in_origin_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def build(cls, home_lla, origin_lla=None) -> LinkFrames:
        """The frames for ``home_lla`` and the vehicle's ``origin_lla`` (None: the same)."""
        home = tuple(float(v) for v in home_lla)
        if origin_lla is None:
            return cls(home, None, np.zeros(3))
        origin = tuple(float(v) for v in origin_lla)
        n, e, d = LocalFrame(*origin).to_ned(*home)
        return cls(home, origin, np.array([float(n), float(e), float(d)]))

    @property
    def offset_m(self) -> float:
        """Distance between home and the EKF origin (m)."""
        return float(np.linalg.norm(self.home_in_origin_ned_m))

    def to_home(self, pos_origin_ned_m) -> np.ndarray:
        """A position (3,) or positions (K, 3) of the vehicle's local frame in the home frame."""
        return np.asarray(pos_origin_ned_m, dtype=np.float64) - self.home_in_origin_ned_m

    def to_origin(self, pos_home_ned_m) -> np.ndarray:
        """A position (3,) or positions (K, 3) of the home frame in the vehicle's local frame."""
        return np.asarray(pos_home_ned_m, dtype=np.float64) + self.home_in_origin_ned_m

    def to_home_floats(self, pos_origin_ned_m) -> list[float]:
        """``to_home`` of one position (a sequence of 3 numbers) as a list of 3 floats."""
        n, e, d = self.home_in_origin_ned_m.tolist()
        x, y, z = pos_origin_ned_m
        return [x - n, y - e, z - d]

    def to_origin_floats(self, pos_home_ned_m) -> list[float]:
        """``to_origin`` of one position (a sequence of 3 numbers) as a list of 3 floats (the
        setpoint stream's fast path: no numpy call)."""
        n, e, d = self.home_in_origin_ned_m.tolist()
        x, y, z = pos_home_ned_m
        return [x + n, y + e, z + d]
