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

**A proof that stands.** The monitor checks ten times a second, and between two reports of the
threats (0.5-1 s) nothing it checks changes but the check's own start time: the tubes' centres
and radii are functions of absolute time. ``MonitorScreen`` therefore proves the reference clear
over the horizon plus ``lead_s`` (every unexpired threat, whatever the sensor range), with twice
the chord error more and the radius of the next grid point: a check started anywhere in the next
``lead_s`` samples the same curve on other times, whose chords lie within a chord error of it
(the curve is smooth there: no standing proof before the reference starts, and its end's kink,
if it ends at speed, is added to the margin; a tube counts until a step after it expires, as a
check counts it on an interval that starts before it expires). The proof stands, for the same
reference and the very same threat reports, until ``lead_s`` has passed.

Pure: numpy only; the table is owned by the avoidance component (``companion.flight.avoidance``).
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from companion.threats.decision.prediction import is_manned, range_for, tubes_for
from companion.threats.decision.spacetime import sample_times, segment_min_distance
from companion.threats.decision.values import ActiveTrajectory

__all__ = ["ReferenceTable", "MonitorScreen", "proves_clear", "same_reports", "CHUNK_S", "LEAD_S"]

#: Reference time sampled at a time by a table (s): with a 15 s horizon, a new chunk about every
#: 15 s of flight.
CHUNK_S = 30.0
#: Rounding allowance of the proof (m).
ROUNDING_M = 1e-9
#: How long a standing proof lasts (s): about the period of the threats' reports.
LEAD_S = 1.0


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
        return (
            active.trajectory is self.trajectory
            and active.start_t_s == self.start_t_s
            and step_s == self.step_s
            and dim == self.dim
        )

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
        self._pos = np.atleast_2d(self.trajectory.sample(tau)[0])[:, : self.dim]

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

    @cached_property
    def end_speed_m_s(self) -> float:
        """Speed (m/s) at the reference's end, where it then holds still (a kink unless 0)."""
        vel = np.atleast_2d(self.trajectory.sample(np.array([float(self.trajectory.duration_s)]))[1])[0]
        return float(np.linalg.norm(vel[: self.dim]))

    def kink_m(self, t_lo_s: float, t_hi_s: float) -> float | None:
        """How far (m) the held reference leaves its chords at kinks within clock times
        [t_lo_s, t_hi_s]: 0 inside the trajectory, the end's speed times half a step when its end
        (at speed) is inside; None when its start is (it holds its first point before it starts,
        at whatever speed it then starts)."""
        if t_lo_s < self.start_t_s:
            return None
        if t_hi_s <= self.start_t_s + float(self.trajectory.duration_s):
            return 0.0
        return self.end_speed_m_s * self.step_s / 2.0


def _near(threats, t_s: float, pos: np.ndarray, dim: int, settings, extra_m: float) -> list:
    """Unexpired threats within their range (``prediction.range_for``) plus ``extra_m`` of
    ``pos`` now (``step._relevant``'s test)."""
    return [
        th
        for th in threats
        if th.expires_t_s > t_s
        and float(np.linalg.norm(th.position_at(t_s)[:dim] - pos[:dim])) - th.radius_m
        <= range_for(th, settings) + extra_m
    ]


def _radius_living_on(tube, t: np.ndarray, extra_s: float) -> np.ndarray:
    """The tube's radius (K,) at ``t``, as if it expired ``extra_s`` later: a check counts a tube
    on an interval that starts before it expires (``spacetime._tube_clearance``), and a check
    started later has its intervals elsewhere."""
    grow = np.minimum(tube.growth_max_m, tube.growth_m_s * np.maximum(t - tube.t0_s, 0.0))
    return np.where(t <= tube.expires_t_s + extra_s, tube.radius_m + grow, -np.inf)


def _clear_of_tubes(pos: np.ndarray, t: np.ndarray, threats, settings, margin_m: np.ndarray, ahead: int) -> bool:
    """Every interval's clearance from every threat's tube, less ``margin_m`` (K-1,) and the
    largest radius of the interval's ends and the ``ahead`` grid points after it (the tube living
    ``ahead`` steps longer), stays >= 0 (drone-scale threats only: ``_provable``)."""
    tubes = tubes_for(threats, settings)
    dim = pos.shape[1]
    n = t.size - 1 - ahead
    for tube in tubes:
        rel = pos - tube.center_at(t)[:, :dim]
        radius = tube.radius_at(t) if not ahead else _radius_living_on(tube, t, ahead * (t[1] - t[0]))
        reach = np.maximum(radius[:n], radius[1 : n + 1])
        for k in range(2, ahead + 2):
            reach = np.maximum(reach, radius[k : n + k])
        clearance = segment_min_distance(rel[:n], rel[1 : n + 1]) - reach
        if np.any(clearance - margin_m[:n] < ROUNDING_M):
            return False
    return True


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
        return False  # the check names the error
    dim = table.dim
    err_m = table.error_m(accel_bound_m_s2)
    near = _near(threats, t_s, table.positions_at(np.array([t_s]))[0], dim, settings, err_m)
    if not near:
        return True
    if not _provable(near):
        return False
    t = sample_times(t_s, settings.horizon_s, settings.check_step_s)
    pos = table.positions_at(t)
    dt = np.diff(t)
    return _clear_of_tubes(pos, t, near, settings, accel_bound_m_s2 * dt * dt / 8.0 + err_m, 0)


class MonitorScreen:
    """The monitor's screen over a flight: the active reference's table and the standing proof
    (module docstring). Owned by the avoidance component; exact, like ``proves_clear``.

    Parameters
    ----------
    settings : ThreatSettings
    accel_bound_m_s2 : float
    lead_s : float
        How long a proof stands (s).
    """

    def __init__(self, settings, accel_bound_m_s2: float, lead_s: float = LEAD_S) -> None:
        self.settings = settings
        self.accel_bound_m_s2 = float(accel_bound_m_s2)
        self.lead_s = float(lead_s)
        self.table: ReferenceTable | None = None
        self._proof: tuple[tuple, float] | None = None  # (threat reports, until t_s)
        self.proofs = self.standing = 0

    def proves_clear(self, active: ActiveTrajectory, threats, t_s: float, dim: int) -> bool:
        """True: ``active`` provably stays clear of ``threats`` over the horizon from ``t_s``."""
        step_s = self.settings.check_step_s
        if self.table is None or not self.table.describes(active, step_s, dim):
            self.table, self._proof = ReferenceTable(active, step_s, dim), None
        threats = tuple(threats)
        if self._proof is not None and t_s <= self._proof[1] and same_reports(self._proof[0], threats):
            self.standing += 1
            return True
        if self._proves_ahead(threats, t_s):
            self._proof = (threats, t_s + self.lead_s)
            self.proofs += 1
            return True
        self._proof = None
        return proves_clear(self.table, threats, t_s, self.settings, self.accel_bound_m_s2)

    def _proves_ahead(self, threats, t_s: float) -> bool:
        if any(th.frame != "local_ned" for th in threats):
            return False
        s = self.settings
        n = max(2, int(math.ceil((s.horizon_s + self.lead_s) / s.check_step_s)) + 2)
        t = t_s + s.check_step_s * np.arange(n)
        kink_m = self.table.kink_m(float(t[0]), float(t[-1]))
        if kink_m is None:
            return False
        live = [th for th in threats if th.expires_t_s > t_s]
        if not live:
            return True
        if not _provable(live):
            return False
        pos = self.table.positions_at(t)
        chord_err = self.accel_bound_m_s2 * s.check_step_s**2 / 8.0
        margin = np.full(n - 1, 3.0 * chord_err + self.table.error_m(self.accel_bound_m_s2) + 2.0 * kink_m)
        return _clear_of_tubes(pos, t, live, s, margin, 1)


def _provable(threats) -> bool:
    """No manned aircraft among ``threats``: the check's clearance of its cylinder is a bound
    that depends on the sample times, so no proof on other times stands for it (the check
    decides; its horizon is then the manned one)."""
    return not any(map(is_manned, threats))


def same_reports(a: tuple, b: tuple) -> bool:
    """The very same reports (identity: a new report is a new object)."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b))
