"""The monitor's screen: a proof, cheaper than the check, that the active reference stays clear.

The monitor asks ``step.active_conflict`` ten times a second whether the active reference meets
a threat's tube within the horizon. That check samples the reference at every check time
(``check_step_s`` over ``horizon_s``): for a smoothed curve, a retime of a retime, or a chain of
pieces, the sampling costs far more than the geometry. Most ticks find nothing: the threats are
far, or behind.

``ReferenceTable`` samples the active reference once, on its own time grid (every ``step_s``
from its t = 0, in chunks, a few per reference), and gives its positions at any clock time by
linear interpolation. The reference's acceleration is bounded by ``a`` (``accel_bound_m_s2``,
the bound the check itself uses for its chords), so an interpolated position lies within

    e = a step_s^2 / 8

of the true one. ``proves_clear`` then runs the check's own geometry (``spacetime``: the same
times, the same tubes, the same chord error) on the interpolated positions, with every
clearance reduced by ``e``. A segment's distance from a tube centre moves by at most the largest
move of its ends, so a clearance that stays non-negative there is non-negative in the exact
check: **a proof of clear is exact** (threats are taken within the sensor range plus ``e``: a
superset of the check's). Anything else is left to ``active_conflict``, which decides as
before: the screen changes what the monitor costs, never what it finds.

Pure: numpy only; the table is owned by the avoidance component (``companion.flight.avoidance``).
"""

from __future__ import annotations

import math

import numpy as np

from companion.threats.decision.prediction import predict_tubes
from companion.threats.decision.spacetime import sample_times, segment_min_distance
from companion.threats.decision.values import ActiveTrajectory

__all__ = ["ReferenceTable", "proves_clear", "CHUNK_S"]

#: Reference time sampled at a time by a table (s): with a 15 s horizon, a new chunk about every
#: 15 s of flight.
CHUNK_S = 30.0
#: Rounding allowance of the proof (m).
ROUNDING_M = 1e-9


class ReferenceTable:
    """Positions of one active reference, sampled on its own grid (module docstring).

    Parameters
    ----------
    active : ActiveTrajectory
    step_s : float
        Grid step (s), > 0.
    dim : int
        2 (north-east) or 3 (NED).
    """

    def __init__(self, active: ActiveTrajectory, step_s: float, dim: int) -> None:
        if not step_s > 0.0:
            raise ValueError(f"step_s: must be > 0, got {step_s!r}")
        self.trajectory = active.trajectory
        self.start_t_s = active.start_t_s
        self.step_s = float(step_s)
        self.dim = int(dim)
        self._tau_s = np.empty(0)
        self._pos = np.empty((0, self.dim))

    def describes(self, active: ActiveTrajectory, step_s: float, dim: int) -> bool:
        """True when this table is of ``active`` (the same trajectory engaged at the same time)."""
        return (active.trajectory is self.trajectory and active.start_t_s == self.start_t_s
                and step_s == self.step_s and dim == self.dim)

    def _cover(self, tau_lo_s: float, tau_hi_s: float) -> None:
        """Sample the chunk that holds [tau_lo_s, tau_hi_s] (clipped to the trajectory) if the
        table does not."""
        duration = float(self.trajectory.duration_s)
        lo, hi = min(max(tau_lo_s, 0.0), duration), min(max(tau_hi_s, 0.0), duration)
        if self._tau_s.size and self._tau_s[0] <= lo and hi <= self._tau_s[-1]:
            return
        k0 = math.floor(lo / self.step_s)
        k1 = math.ceil(max(hi, lo + CHUNK_S) / self.step_s)
        tau = np.minimum(np.arange(k0, k1 + 1) * self.step_s, duration)
        if tau[-1] < hi:
            tau = np.append(tau, duration)
        tau = np.unique(tau)
        self._tau_s = tau
        self._pos = np.atleast_2d(self.trajectory.sample(tau)[0])[:, :self.dim]

    def positions_at(self, t_s: np.ndarray) -> np.ndarray:
        """Interpolated positions (K, dim) at clock times ``t_s`` (K,), increasing: held at the
        start before t = 0 and at the end after ``duration_s``, as the reference is."""
        tau = np.asarray(t_s, dtype=float) - self.start_t_s
        self._cover(float(tau[0]), float(tau[-1]))
        tau = np.clip(tau, 0.0, float(self.trajectory.duration_s))
        return np.column_stack([np.interp(tau, self._tau_s, self._pos[:, a]) for a in range(self.dim)])

    def error_m(self, accel_bound_m_s2: float) -> float:
        """Largest distance (m) of an interpolated position from the reference's."""
        return accel_bound_m_s2 * self.step_s * self.step_s / 8.0


def _near(threats, t_s: float, pos: np.ndarray, dim: int, range_m: float) -> list:
    """Unexpired threats within ``range_m`` of ``pos`` now (``step._relevant``'s test)."""
    return [th for th in threats if th.expires_t_s > t_s and
            float(np.linalg.norm(th.position_at(t_s)[:dim] - pos[:dim])) - th.radius_m <= range_m]


def proves_clear(table: ReferenceTable, threats, t_s: float, settings, accel_bound_m_s2: float) -> bool:
    """True when the active reference provably stays clear of every threat's tube over the
    horizon from ``t_s`` (module docstring); False: not proven, ask ``active_conflict``.

    Parameters
    ----------
    table : ReferenceTable
        Of the active reference.
    threats : sequence of Threat
        Local-frame threats, as in the observation.
    t_s : float
        Clock time of the check (s).
    settings : ThreatSettings
        ``horizon_s``, ``check_step_s``, ``sensor_range_m``, ``inflation_m`` and the uncertainty
        growth.
    accel_bound_m_s2 : float
        The check's bound on the reference's acceleration (``Situation.accel_bound_m_s2``).
    """
    if any(th.frame != "local_ned" for th in threats):
        return False                        # the check names the error
    dim = table.dim
    err_m = table.error_m(accel_bound_m_s2)
    t = sample_times(t_s, settings.horizon_s, settings.check_step_s)
    pos = table.positions_at(t)
    near = _near(threats, t_s, pos[0], dim, settings.sensor_range_m + err_m)
    if not near:
        return True
    tubes = predict_tubes(near, inflation_m=settings.inflation_m, uncertainty_m_s=settings.uncertainty_m_s,
                          uncertainty_max_m=settings.uncertainty_max_m)
    dt = np.diff(t)
    chord_err = accel_bound_m_s2 * dt * dt / 8.0
    for tube in tubes:
        rel = pos - tube.center_at(t)[:, :dim]
        radius = tube.radius_at(t)
        clearance = segment_min_distance(rel[:-1], rel[1:]) - np.maximum(radius[:-1], radius[1:])
        if np.any(clearance - chord_err - err_m < ROUNDING_M):
            return False
    return True
