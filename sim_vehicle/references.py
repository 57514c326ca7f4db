"""Standard reference manoeuvres for checking the flight controller (pure numerics).

Used by the controller's tests and by ``benchmarks/sitl_realtime.py`` (issue 2: the LQI's
tracking error on a 5 m/s circle of 30 m radius).
"""

from __future__ import annotations

import numpy as np


def circle_reference(
    t_s,
    radius_m: float = 30.0,
    speed_m_s: float = 5.0,
    ramp_s: float = 5.0,
    down_m: float = -20.0,
    heading: str = "path",
    yaw_fixed_rad: float = 0.0,
):
    """Counter-clockwise circle (seen from above) about the origin with a smoothstep speed ramp.

    Parameters
    ----------
    t_s : array_like, shape (K,)
        Times (s); the speed ramps up from 0 to ``speed_m_s`` over ``ramp_s``.
    heading : str
        ``"path"``: yaw along the tangent; ``"fixed"``: ``yaw_fixed_rad`` throughout.

    Returns
    -------
    pos, vel, acc : ndarray, shape (K, 3)
        NED position (m), velocity (m/s) and acceleration (m/s^2).
    yaw : ndarray, shape (K,)
        Heading reference (rad).
    """
    t = np.asarray(t_s, dtype=float)
    tau = np.clip(t / ramp_s, 0.0, 1.0)
    speed = speed_m_s * (3 * tau**2 - 2 * tau**3)
    dspeed = np.where(t < ramp_s, speed_m_s * (6 * tau - 6 * tau**2) / ramp_s, 0.0)
    arc = np.where(
        t < ramp_s, speed_m_s * ramp_s * (tau**3 - tau**4 / 2), speed_m_s * ramp_s / 2 + speed_m_s * (t - ramp_s)
    )
    th = arc / radius_m
    tangent = np.stack([-np.sin(th), np.cos(th), 0 * th], axis=-1)
    normal = np.stack([-np.cos(th), -np.sin(th), 0 * th], axis=-1)
    pos = np.stack([radius_m * np.cos(th), radius_m * np.sin(th), down_m + 0 * th], axis=-1)
    vel = speed[:, None] * tangent
    acc = dspeed[:, None] * tangent + (speed**2 / radius_m)[:, None] * normal
    yaw = np.arctan2(tangent[:, 1], tangent[:, 0]) if heading == "path" else np.full(t.shape, yaw_fixed_rad)
    return pos, vel, acc, yaw
