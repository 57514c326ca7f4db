"""Geodesy: latitude/longitude/altitude <-> local NED metres about a geodetic origin.

The one local-frame conversion of the project, shared by the companion (``companion.geo``
re-exports it; DESIGN.md section 3) and the SITL vehicle (``sim_vehicle.frames``).
The local frame is the WGS-84 tangent plane at the home position, north-east-down, metres, as
in the paper's simulation frame (section 2.1) and in ArduPilot's LOCAL_POSITION_NED. The
conversion is the exact geodetic <-> ENU/NED transform of ``pymap3d`` (no flat-earth
approximation), vectorised over arrays of any shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d


class GeoError(ValueError):
    """A latitude, longitude or altitude is out of range or not finite."""


LAT_LIMIT_DEG = 90.0
LON_LIMIT_DEG = 180.0


def check_lat_lon(lat_deg, lon_deg, *, what: str = "position") -> tuple[np.ndarray, np.ndarray]:
    """Validate latitudes and longitudes in degrees.

    Parameters
    ----------
    lat_deg, lon_deg : array_like, same shape
        Latitude in [-90, 90] and longitude in [-180, 180] degrees.
    what : str
        Name used in the error message (e.g. ``"mission item 3"``).

    Returns
    -------
    lat, lon : ndarray of float64

    Raises
    ------
    GeoError
        Naming ``what`` and the offending value.
    """
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    if not np.all(np.isfinite(lat)):
        raise GeoError(f"{what}: latitude is not a finite number")
    if not np.all(np.isfinite(lon)):
        raise GeoError(f"{what}: longitude is not a finite number")
    bad_lat = np.abs(lat) > LAT_LIMIT_DEG
    if np.any(bad_lat):
        raise GeoError(f"{what}: latitude {float(lat[bad_lat].flat[0])} deg is out of range [-90, 90]")
    bad_lon = np.abs(lon) > LON_LIMIT_DEG
    if np.any(bad_lon):
        raise GeoError(f"{what}: longitude {float(lon[bad_lon].flat[0])} deg is out of range [-180, 180]")
    return lat, lon


def check_finite(value, *, what: str) -> np.ndarray:
    """Return ``value`` as float64 or raise ``GeoError`` naming ``what`` if any entry is not finite."""
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise GeoError(f"{what} is not a finite number")
    return arr


@dataclass(frozen=True)
class LocalFrame:
    """A local NED frame whose origin is a geodetic point (usually home).

    Parameters
    ----------
    lat0_deg, lon0_deg : float
        Origin latitude and longitude in degrees (WGS-84).
    alt0_m : float
        Origin altitude in metres above mean sea level (AMSL, as in MAVLink GLOBAL frames).

    Examples
    --------
    >>> frame = LocalFrame(47.397742, 8.545594, 488.0)
    >>> n, e, d = frame.to_ned(47.397742, 8.545594, 498.0)
    >>> round(float(d), 6)
    -10.0
    """

    lat0_deg: float
    lon0_deg: float
    alt0_m: float

    def __post_init__(self) -> None:
        check_lat_lon(self.lat0_deg, self.lon0_deg, what="frame origin")
        check_finite(self.alt0_m, what="frame origin altitude alt0_m")
        object.__setattr__(self, "lat0_deg", float(self.lat0_deg))
        object.__setattr__(self, "lon0_deg", float(self.lon0_deg))
        object.__setattr__(self, "alt0_m", float(self.alt0_m))

    def to_ned(self, lat_deg, lon_deg, alt_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Geodetic -> local NED.

        Parameters
        ----------
        lat_deg, lon_deg : array_like, shape (K,) or scalar
            Degrees; validated.
        alt_m : array_like, shape (K,) or scalar
            Metres AMSL.

        Returns
        -------
        north_m, east_m, down_m : ndarray, same shape as the inputs
        """
        lat, lon = check_lat_lon(lat_deg, lon_deg, what="to_ned")
        alt = check_finite(alt_m, what="to_ned: alt_m")
        n, e, d = pymap3d.geodetic2ned(lat, lon, alt, self.lat0_deg, self.lon0_deg, self.alt0_m)
        return np.asarray(n, dtype=np.float64), np.asarray(e, dtype=np.float64), np.asarray(d, dtype=np.float64)

    def to_lla(self, north_m, east_m, down_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Local NED -> geodetic.

        Parameters
        ----------
        north_m, east_m, down_m : array_like, shape (K,) or scalar

        Returns
        -------
        lat_deg, lon_deg, alt_m : ndarray, same shape as the inputs (altitude AMSL)
        """
        n = check_finite(north_m, what="to_lla: north_m")
        e = check_finite(east_m, what="to_lla: east_m")
        d = check_finite(down_m, what="to_lla: down_m")
        lat, lon, alt = pymap3d.ned2geodetic(n, e, d, self.lat0_deg, self.lon0_deg, self.alt0_m)
        return np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64), np.asarray(alt, dtype=np.float64)

    def to_ned_array(self, lla) -> np.ndarray:
        """Geodetic rows -> NED rows.

        Parameters
        ----------
        lla : array_like, shape (K, 3)
            Columns latitude deg, longitude deg, altitude m AMSL.

        Returns
        -------
        ndarray, shape (K, 3)
            Columns north, east, down in metres.
        """
        arr = np.asarray(lla, dtype=np.float64).reshape(-1, 3)
        n, e, d = self.to_ned(arr[:, 0], arr[:, 1], arr[:, 2])
        return np.column_stack([n, e, d])

    def to_lla_array(self, ned) -> np.ndarray:
        """NED rows ``(K, 3)`` -> geodetic rows ``(K, 3)`` (lat deg, lon deg, alt m AMSL)."""
        arr = np.asarray(ned, dtype=np.float64).reshape(-1, 3)
        lat, lon, alt = self.to_lla(arr[:, 0], arr[:, 1], arr[:, 2])
        return np.column_stack([lat, lon, alt])
