"""The three frames of the simulated vehicle: ground, EKF origin and home (DESIGN section 5).

* **Ground frame** (internal): NED metres from the point where the vehicle starts (the
  ``--home`` given at start), flat ground at ``down = 0``. The physics, the legs and the
  flight controller work in it; nothing outside the simulation sees it.
* **EKF origin** (GPS_GLOBAL_ORIGIN, ``--origin``, default the start point): as in ArduPilot,
  LOCAL_POSITION_NED, SET_POSITION_TARGET_LOCAL_NED and MAV_FRAME_LOCAL_NED mission items are
  NED metres from it. It differs from the ground frame by a constant translation (the start
  point's NED position from the origin; the curvature between the two tangent planes is
  ignored, millimetres over the few hundred metres the vehicle flies).
* **Home** (HOME_POSITION; DO_SET_HOME moves it): relative altitudes (GLOBAL_POSITION_INT
  ``relative_alt``, takeoff altitude, ``*_RELATIVE_ALT`` frames), RTL and mission item 0. Its
  HOME_POSITION ``x, y, z`` are its NED position from the origin.

Geodesy through :class:`heli_common.frames.LocalFrame` (WGS-84, pymap3d), the project's one
local-frame conversion. Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from heli_common.frames import LocalFrame


class Frames:
    """Ground frame, EKF origin and home of one vehicle.

    Parameters
    ----------
    start_lla : (lat_deg, lon_deg, alt_m)
        Where the vehicle starts, on the ground; the first home.
    origin_lla : (lat_deg, lon_deg, alt_m), optional
        EKF origin (default: the start point).
    """

    def __init__(self, start_lla: Sequence[float], origin_lla: Sequence[float] | None = None) -> None:
        lat, lon, alt = (float(v) for v in start_lla[:3])
        self.ground = LocalFrame(lat, lon, alt)
        origin = (lat, lon, alt) if origin_lla is None else tuple(float(v) for v in origin_lla[:3])
        self.origin = LocalFrame(*origin)
        self.origin_lla: tuple[float, float, float] = origin
        self.start_in_origin_ned_m = np.array(self.origin.to_ned(lat, lon, alt))
        self.home_lla: tuple[float, float, float] = (lat, lon, alt)
        self.home_ground_ned_m = np.zeros(3)

    # ------------------------------------------------------------------ home
    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Move home (DO_SET_HOME); the origin and the ground frame stay where they are."""
        self.home_lla = (float(lat_deg), float(lon_deg), float(alt_m))
        self.home_ground_ned_m = np.array(self.ground.to_ned(lat_deg, lon_deg, alt_m))

    @property
    def home_local_ned_m(self) -> np.ndarray:
        """Home, (3,) m NED from the EKF origin (HOME_POSITION x, y, z)."""
        return self.to_local(self.home_ground_ned_m)

    @property
    def home_alt_m(self) -> float:
        """Home altitude AMSL, m."""
        return self.home_lla[2]

    def down_at_height_above_home(self, height_m: float) -> float:
        """Ground-frame ``down`` of a point ``height_m`` above home."""
        return float(self.home_ground_ned_m[2] - height_m)

    def height_above_home(self, pos_ned_m: Sequence[float]) -> float:
        """Height of a ground-frame position above home, m."""
        return float(self.home_ground_ned_m[2] - pos_ned_m[2])

    # ------------------------------------------------------------------ origin
    def to_local(self, pos_ned_m: Sequence[float]) -> np.ndarray:
        """Ground frame -> NED from the EKF origin (LOCAL_POSITION_NED)."""
        return np.asarray(pos_ned_m, dtype=float) + self.start_in_origin_ned_m

    def from_local(self, local_ned_m: Sequence[float]) -> np.ndarray:
        """NED from the EKF origin (SET_POSITION_TARGET_LOCAL_NED) -> ground frame (NaN stays NaN)."""
        return np.asarray(local_ned_m, dtype=float) - self.start_in_origin_ned_m

    # ------------------------------------------------------------------ geodesy
    def to_lla(self, pos_ned_m: Sequence[float]) -> tuple[float, float, float]:
        """Ground frame -> latitude, longitude (degrees), altitude AMSL (m)."""
        lat, lon, alt = self.ground.to_lla(float(pos_ned_m[0]), float(pos_ned_m[1]), float(pos_ned_m[2]))
        return float(lat), float(lon), float(alt)

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> np.ndarray:
        """Latitude, longitude (degrees), altitude AMSL (m) -> ground frame."""
        return np.array(self.ground.to_ned(lat_deg, lon_deg, alt_m), dtype=float)


__all__ = ["Frames"]
