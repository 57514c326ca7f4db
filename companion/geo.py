"""Geodesy: latitude/longitude/altitude <-> local NED metres about a home position.

This is the only module of the companion where degrees and geodesy appear (DESIGN.md section 3).
The frame itself is the project's one local-frame conversion, :mod:`heli_common.frames`
(WGS-84 tangent plane, NED, pymap3d), shared with the SITL vehicle; this module re-exports it.
"""

from __future__ import annotations

from heli_common.frames import LAT_LIMIT_DEG, LON_LIMIT_DEG, GeoError, LocalFrame, check_finite, check_lat_lon

__all__ = ["LAT_LIMIT_DEG", "LON_LIMIT_DEG", "GeoError", "LocalFrame", "check_finite", "check_lat_lon"]
