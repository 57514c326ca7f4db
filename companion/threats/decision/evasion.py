"""Evade: a library of dynamically feasible escape manoeuvres, always ready (DESIGN 7.4).

Every manoeuvre leaves the current reference state (p0, v0) and ends in a hover:

1. change the velocity to a target v1 at the vehicle's acceleration limits (horizontal
   ``accel_m_s2``, vertical ``vertical_accel_m_s2``; constant acceleration);
2. coast at v1 for ``coast_s``;
3. brake to rest at the same limits, then hover.

The targets span a hard brake (v1 = 0), the eight horizontal directions around the current
heading (ahead, sidesteps left/right, diagonal, retreat) at half and full evasion speed,
swerves (the current velocity plus a sideways one), each combined with a climb or a descent
when the world is 3D, and pure climbs and descents. This is
the ADS-B avoidance repertoire of ArduPilot's ``AP_Avoidance`` (climb, descend, move
perpendicular, hover) made kinodynamic. Positions are closed-form piecewise quadratics, so the
whole library is sampled and checked in one vectorised pass (a few milliseconds).

Escapes are neither smoothed nor timed by the trajectory pipeline (``companion.flight.pipeline``):
their kinematics are closed-form. Their speed comes from the pipeline's limits
(``candidates.Situation.escape_speed_m_s``: at most 1.2 times its speed limit).

Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["EscapeLimits", "EscapeLibrary", "EscapeManoeuvre", "escape_library"]


@dataclass(frozen=True)
class EscapeLimits:
    """Limits of the escape manoeuvres (from the vehicle profile and the settings).

    Attributes
    ----------
    speed_m_s : float
        Full evasion speed (horizontal, m/s).
    accel_m_s2 : float
        Horizontal acceleration and braking limit (m/s^2).
    climb_m_s, descent_m_s : float
        Vertical speeds (m/s).
    vertical_accel_m_s2 : float
    coasts_s : tuple of float
        Coast durations tried (s).
    """

    speed_m_s: float = 6.0
    accel_m_s2: float = 2.5
    climb_m_s: float = 2.5
    descent_m_s: float = 1.5
    vertical_accel_m_s2: float = 1.5
    coasts_s: tuple = (1.0, 2.5, 5.0)


#: Horizontal directions (deg, clockwise from the heading: +90 is right) and their names.
DIRECTIONS = (
    (0, "ahead"),
    (45, "ahead right"),
    (90, "right"),
    (135, "back right"),
    (180, "back"),
    (-135, "back left"),
    (-90, "left"),
    (-45, "ahead left"),
)


def _directions(heading: np.ndarray, lim: EscapeLimits) -> list:
    """Horizontal target velocities in the eight directions around the heading, at half and
    full evasion speed (a sidestep, a retreat ...)."""
    right = np.array([-heading[1], heading[0]])
    out = []
    for deg, name in DIRECTIONS:
        rad = math.radians(deg)
        direction = math.cos(rad) * heading + math.sin(rad) * right
        out += [(frac * lim.speed_m_s * direction, name) for frac in (0.5, 1.0)]
    return out


def _swerves(vel_ne_m_s: np.ndarray, heading: np.ndarray, lim: EscapeLimits) -> list:
    """Keep the current velocity and add a sideways one (half and full evasion speed), capped
    at the evasion speed: a swerve, against a threat from behind or ahead."""
    right = np.array([-heading[1], heading[0]])
    out = []
    for side, name in ((1.0, "swerve right"), (-1.0, "swerve left")):
        for frac in (0.5, 1.0):
            v = vel_ne_m_s + side * frac * lim.speed_m_s * right
            out.append((_capped(v, lim.speed_m_s), name))
    return out


def _phase_times(v0: np.ndarray, v1: np.ndarray, lim: EscapeLimits) -> tuple[np.ndarray, np.ndarray]:
    """Durations (C,) of the velocity change v0 -> v1 and of the final stop from v1."""

    def duration(dv):
        t = np.linalg.norm(dv[:, :2], axis=1) / lim.accel_m_s2
        if dv.shape[1] == 3:
            t = np.maximum(t, np.abs(dv[:, 2]) / lim.vertical_accel_m_s2)
        return t

    return duration(v1 - v0[None, :]), duration(v1)


def _phase_accels(p0, v0, v1, coast_s, lim: EscapeLimits):
    """Phase durations and accelerations, and the positions where phases 2 and 3 start."""
    t1, t3 = _phase_times(v0, v1, lim)
    a1 = (v1 - v0[None, :]) / np.maximum(t1, 1e-9)[:, None]
    a3 = -v1 / np.maximum(t3, 1e-9)[:, None]
    p1 = p0[None, :] + v0[None, :] * t1[:, None] + 0.5 * a1 * t1[:, None] ** 2
    p2 = p1 + v1 * coast_s[:, None]
    return t1, t3, a1, a3, p1, p2


def _positions(p0, v0, v1, coast_s, t_rel, lim: EscapeLimits):
    """Positions (C, K, D) of manoeuvres (C,) at times ``t_rel`` (K,), and durations (C,)."""
    t1, t3, a1, a3, p1, p2 = _phase_accels(p0, v0, v1, coast_s, lim)
    t = t_rel[None, :, None]
    ta = np.minimum(t, t1[:, None, None])
    tb = np.clip(t - t1[:, None, None], 0.0, coast_s[:, None, None])
    tc = np.clip(t - (t1 + coast_s)[:, None, None], 0.0, t3[:, None, None])
    pos = p0 + v0 * ta + 0.5 * a1[:, None, :] * ta**2  # phase 1, then frozen at p1
    pos += v1[:, None, :] * tb  # coast
    pos += v1[:, None, :] * tc + 0.5 * a3[:, None, :] * tc**2  # brake, then hover
    return pos, t1 + coast_s + t3


def _kinematics(p0, v0, v1, coast_s, t_rel, lim: EscapeLimits):
    """Position, velocity, acceleration (C, K, D) at times ``t_rel`` (K,), and durations (C,)."""
    pos, duration = _positions(p0, v0, v1, coast_s, t_rel, lim)
    t1, t3, a1, a3, _, _ = _phase_accels(p0, v0, v1, coast_s, lim)
    t = t_rel[None, :, None]
    in1 = t < t1[:, None, None]
    in2 = ~in1 & (t < (t1 + coast_s)[:, None, None])
    in3 = ~in1 & ~in2 & (t < duration[:, None, None])
    ta = np.minimum(t, t1[:, None, None])
    tc = np.clip(t - (t1 + coast_s)[:, None, None], 0.0, t3[:, None, None])
    vel = np.where(
        in1,
        v0 + a1[:, None, :] * ta,
        np.where(in2, v1[:, None, :], np.where(in3, v1[:, None, :] + a3[:, None, :] * tc, 0.0)),
    )
    acc = np.where(in1, a1[:, None, :], np.where(in3, a3[:, None, :], 0.0))
    return pos, vel, acc, duration


class EscapeLibrary:
    """Escape manoeuvres from one reference state, sampled together.

    Parameters
    ----------
    pos_ned_m, vel_ned_m_s : array_like, shape (D,)
        Reference state (D = 2 or 3).
    targets : array_like, shape (C, D)
        Target velocities v1.
    coasts_s : array_like, shape (C,)
    labels : list of str
    limits : EscapeLimits
    """

    def __init__(self, pos_ned_m, vel_ned_m_s, targets, coasts_s, labels, limits: EscapeLimits):
        self.p0 = np.asarray(pos_ned_m, dtype=float)
        self.v0 = np.asarray(vel_ned_m_s, dtype=float)
        self.targets = np.asarray(targets, dtype=float).reshape(-1, self.p0.shape[0])
        self.coasts_s = np.asarray(coasts_s, dtype=float)
        self.labels = list(labels)
        self.limits = limits

    def __len__(self) -> int:
        return len(self.labels)

    def positions(self, t_rel_s: np.ndarray):
        """Positions (C, K, D) and durations (C,) at times (K,) since the manoeuvres start."""
        return _positions(self.p0, self.v0, self.targets, self.coasts_s, np.asarray(t_rel_s, float), self.limits)

    def manoeuvre(self, i: int, yaw_rad: float) -> EscapeManoeuvre:
        """Manoeuvre ``i`` as a trajectory (holding ``yaw_rad``)."""
        return EscapeManoeuvre(
            self.p0, self.v0, self.targets[i], float(self.coasts_s[i]), self.limits, yaw_rad, self.labels[i]
        )

    def refined(self, indices) -> EscapeLibrary:
        """Variants around manoeuvres ``indices`` (a local search when none of them is clear):
        the target turned by +-15 and +-30 degrees, 25 % slower or faster (capped at the
        evasion speed), with each
        vertical option, and the coast 40 % shorter or 60 % longer."""
        lim = self.limits
        d = self.p0.shape[0]
        verticals = [0.0, -lim.climb_m_s, lim.descent_m_s] if d == 3 else [0.0]
        targets, coasts, labels = [], [], []
        for i in indices:
            v1, coast, label = self.targets[i], float(self.coasts_s[i]), self.labels[i]
            horizontal = [_turned(v1[:2], deg) for deg in (-30.0, -15.0, 15.0, 30.0)] + [
                _capped(v1[:2] * f, lim.speed_m_s) for f in (0.75, 1.25)
            ]
            for v_h in horizontal + [v1[:2]]:
                for vz in verticals:
                    for c in (0.6 * coast, coast, 1.6 * coast):
                        v = np.zeros(d)
                        v[:2] = v_h
                        if d == 3:
                            v[2] = vz
                        targets.append(v)
                        coasts.append(c)
                        labels.append(f"{label} (refined)")
        return EscapeLibrary(self.p0, self.v0, targets, coasts, labels, lim)


def _turned(v_ne: np.ndarray, deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([c * v_ne[0] - s * v_ne[1], s * v_ne[0] + c * v_ne[1]])


def _capped(v_ne: np.ndarray, cap_m_s: float) -> np.ndarray:
    speed = float(np.linalg.norm(v_ne))
    return v_ne * min(1.0, cap_m_s / max(speed, 1e-9))


def escape_library(pos_ned_m, vel_ned_m_s, limits: EscapeLimits, *, vertical: bool, away_from=None) -> EscapeLibrary:
    """The library around the current heading (or, at a hover, facing away from ``away_from``,
    a horizontal point such as the nearest threat; north when none): candidate 0 is the hard
    brake; then every horizontal target (directions, swerves, a stop) with each vertical option
    (level, climb, descend in 3D) and each coast time."""
    p0 = np.asarray(pos_ned_m, dtype=float)
    v0 = np.asarray(vel_ned_m_s, dtype=float)
    d = p0.shape[0]
    speed = float(np.linalg.norm(v0[:2]))
    if speed > 0.3:
        heading = v0[:2] / speed
    elif away_from is not None and np.linalg.norm(p0[:2] - np.asarray(away_from)[:2]) > 1e-6:
        rel = p0[:2] - np.asarray(away_from, dtype=float)[:2]
        heading = rel / np.linalg.norm(rel)
    else:
        heading = np.array([1.0, 0.0])
    verticals = [(0.0, "")]
    if vertical and d == 3:
        verticals += [(-limits.climb_m_s, "climb"), (limits.descent_m_s, "descend")]
    horizontals = [(np.zeros(2), "brake")] + _directions(heading, limits) + _swerves(v0[:2], heading, limits)
    targets, coasts, labels = [np.zeros(d)], [0.0], ["brake"]
    for v_h, name in horizontals:
        for vz, vname in verticals:
            if name == "brake" and not vname:
                continue  # the hard brake is candidate 0
            v1 = np.zeros(d)
            v1[:2] = v_h
            if d == 3:
                v1[2] = vz
            label = vname if name == "brake" else f"{name}{' + ' + vname if vname else ''}"
            for coast in limits.coasts_s:
                targets.append(v1)
                coasts.append(coast)
                labels.append(label)
    return EscapeLibrary(p0, v0, targets, coasts, labels, limits)


class EscapeManoeuvre:
    """One escape manoeuvre as a ``companion.flight.trajectory.FlyableReference`` (t = 0 at its start;
    a hover after its end).

    Attributes
    ----------
    duration_s, length_m : float
    end_pos_ned_m : ndarray, shape (D,)
    label : str
    """

    def __init__(self, p0, v0, v1, coast_s: float, limits: EscapeLimits, yaw_rad: float, label: str):
        self._args = (
            np.asarray(p0, float),
            np.asarray(v0, float),
            np.atleast_2d(v1).astype(float),
            np.array([coast_s]),
        )
        self.limits = limits
        self.yaw = float(yaw_rad)
        self.label = label
        _, dur = _positions(*self._args, np.zeros(1), limits)
        self.duration_s = float(dur[0])
        t = np.linspace(0.0, self.duration_s, 50)
        pos = self.sample(t)[0]
        self.length_m = float(np.sum(np.linalg.norm(np.diff(pos, axis=0), axis=1)))
        self.end_pos_ned_m = pos[-1]

    def sample(self, t_s):
        """Position, velocity, acceleration (K, D) at times ``t_s`` (K,)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        pos, vel, acc, _ = _kinematics(*self._args, np.maximum(t, 0.0), self.limits)
        return pos[0], vel[0], acc[0]

    def yaw_rad(self, t_s) -> np.ndarray:
        return np.full(np.atleast_1d(t_s).shape, self.yaw)

    def yaw_rate_rad_s(self, t_s) -> np.ndarray:
        return np.zeros(np.atleast_1d(t_s).shape)
