"""Geodetic <-> local NED for the SITL vehicle (WGS-84 via pymap3d).

``sim_vehicle`` must not import ``companion``, so it has its own small adapter with the same
convention as ``companion.geo``: NED metres with the origin at the home position, altitudes
in metres above mean sea level (AMSL) as MAVLink's global frames give them. The ground is the
plane ``down = 0`` through home (flat terrain).
"""

from __future__ import annotations

import math

import pymap3d


class LocalFrame:
    """Local NED frame anchored at a geodetic origin.

    Parameters
    ----------
    lat0_deg, lon0_deg : float
        Origin latitude and longitude, degrees.
    alt0_m : float
        Origin altitude AMSL, m.
    """

    def __init__(self, lat0_deg: float, lon0_deg: float, alt0_m: float) -> None:
        for name, value in (("lat0_deg", lat0_deg), ("lon0_deg", lon0_deg), ("alt0_m", alt0_m)):
            if not math.isfinite(value):
                raise ValueError(f"{name}: expected a finite number, got {value!r}")
        if not -90.0 <= lat0_deg <= 90.0:
            raise ValueError(f"lat0_deg: expected -90..90, got {lat0_deg!r}")
        if not -180.0 <= lon0_deg <= 180.0:
            raise ValueError(f"lon0_deg: expected -180..180, got {lon0_deg!r}")
        self.lat0_deg = float(lat0_deg)
        self.lon0_deg = float(lon0_deg)
        self.alt0_m = float(alt0_m)

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """Geodetic (degrees, m AMSL) -> NED (m) relative to the origin."""
        n, e, d = pymap3d.geodetic2ned(lat_deg, lon_deg, alt_m, self.lat0_deg, self.lon0_deg, self.alt0_m)
        return float(n), float(e), float(d)

    def to_lla(self, north_m: float, east_m: float, down_m: float) -> tuple[float, float, float]:
        """NED (m) -> geodetic (degrees, m AMSL)."""
        lat, lon, alt = pymap3d.ned2geodetic(north_m, east_m, down_m, self.lat0_deg, self.lon0_deg, self.alt0_m)
        return float(lat), float(lon), float(alt)
