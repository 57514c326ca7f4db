"""Brute-force oracle of avoidance: could *any* feasible manoeuvre avoid the encounter?

The threat benchmark (``benchmarks/threats.py``) and the validation campaign
(``companion.campaign.labels``) judge a policy on the encounters that can be avoided at all.
Which ones those are is decided here, independently of the policy under test (DESIGN section
7): nothing of ``companion.threats`` is used except the ``Threat`` record (its constant-velocity
prediction), and none of the policy's manoeuvres are reused. A threat is a ``Threat`` or an
intruder's true track (``companion.campaign.tracks.IntruderTrack``: ``position_at``,
``radius_m``, ``max_speed_m_s``), which may turn or climb.

Model. The vehicle is a point mass that starts at the reference state of the encounter start
(position, velocity) and flies one *manoeuvre* for ``horizon_s`` (12 s):

- the commanded acceleration is limited to ``accel_horizontal_m_s2`` (2.5 m/s^2, the lateral
  acceleration limit of the smoothing settings and the deceleration of the policy's hold) in
  the north-east plane and to ``accel_vertical_m_s2`` (1.5 m/s^2; a helicopter's collective
  margin is smaller than its cyclic one) along *down*, independently (a box-cylinder set);
- the speed is capped at ``speed_max_m_s`` = 1.2 x the 6 m/s cruise speed (7.2 m/s): a step
  that would exceed it has its new velocity projected back onto the ball (so the vehicle can
  still turn at full speed), and the resulting acceleration is shrunk if that tilted it beyond
  one axis group's limit: the applied acceleration always satisfies both limits and the cap;
- the applied acceleration is constant over each ``control_step_s`` (0.1 s, a 10 Hz guidance;
  brake and speed cap act per control step), so the flight is piecewise quadratic and is
  evaluated *exactly* at any time (``Flight.sample``); it is checked every ``step_s`` (0.02 s).

A manoeuvre has two phases, each either a constant commanded acceleration (a grid of directions
relative to the initial heading: 12 horizontal directions x 2 magnitudes x {climb, level,
descend}, pure climb/descend, none), a *brake* to a hover at the limits (optionally climbing or
descending while braking horizontally), with the switch at one of several times. The single
phase manoeuvres come first (keep going, sidestep, climb, hard stop, reverse = constant
acceleration against the velocity), then every pair (7687 in all). The search stops at the first
manoeuvre that stays clear (the *witness*). A manoeuvre that meets a threat at a control-step
boundary (a subset of the samples, no slack needed) is dropped before it is sampled every
0.02 s; labelling takes ~0.1 s for most avoidable encounters and ~0.3 s for an unavoidable one.

Clear means, at every sample of the window (and, by the margins below, at every instant):

- the distance to every threat's predicted centre is at least its radius + ``threat_allowance_m``
  (1.0 m: the tracking error a real vehicle adds to a point-mass manoeuvre; the policy's own
  inflation, 2 m in ``ThreatSettings``, is larger because it also covers the rotor);
- the clearance from the static world (``World.clearance_m`` of the world given, normally with
  no safety margin) is at least ``world_clearance_m`` (0.5 m), and the point is inside the
  world's bounds.

Sampling margins. Between two samples ``step_s`` apart the relative position of vehicle and
threat moves by at most ``(v_max + |v_threat|) step_s`` along a chord and bows away from it by at
most ``a_max step_s^2 / 8``, so the sampled distance is required to exceed the limit by
``(v_max + |v_threat|) step_s / 2 + a_max step_s^2 / 8`` (0.16 m for a 9 m/s threat); the same for
the world clearance (the SDF is 1-Lipschitz) and the bounds. A witness is therefore clear in
continuous time, which ``tests/unit/threats/test_threat_oracle.py`` checks at 0.005 s.

What the oracle does not model: reaction and decision time (the manoeuvre starts at once), the
attitude dynamics between two accelerations (jerk is unbounded), a separate climb/descent rate
limit (only the total speed is capped: a climb held longer than 1.7 s exceeds the autopilot's
WPNAV_SPEED_UP of 2.5 m/s, so vertical escapes are judged generously), and anything after the 12 s
window (an encounter whose threat is still coming after 12 s counts as avoided if the first 12 s
are clear). It is an upper bound of what a policy can do within these limits, up to the grid.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from companion.threats.model import Threat

__all__ = [
    "OracleLimits",
    "Phase",
    "Manoeuvre",
    "Flight",
    "OracleResult",
    "label_encounter",
    "manoeuvres",
    "fly",
    "sample_flights",
    "flight_margins",
    "CRUISE_SPEED_M_S",
    "TRACKING_ALLOWANCE_M",
    "WORLD_CLEARANCE_M",
]

#: Cruise speed of the benchmark's trajectories (m/s): ``TrajectoryLimits(speed_m_s=6.0)``.
CRUISE_SPEED_M_S = 6.0
#: Added to every threat radius (m): the tracking error of the real vehicle around a manoeuvre.
TRACKING_ALLOWANCE_M = 1.0
#: Smallest clearance from the static world (m).
WORLD_CLEARANCE_M = 0.5

#: Phase kinds.
ACCEL, BRAKE, BRAKE_H = 0, 1, 2
_KIND_NAMES = {ACCEL: "accel", BRAKE: "brake", BRAKE_H: "brake_h"}


@dataclass(frozen=True)
class OracleLimits:
    """Limits of the point mass and of the clearance test (see the module docstring).

    Attributes
    ----------
    accel_horizontal_m_s2 : float
        Largest north-east acceleration (m/s^2). Default 2.5.
    accel_vertical_m_s2 : float
        Largest acceleration along down (m/s^2). Default 1.5.
    speed_max_m_s : float
        Largest speed (m/s). Default 1.2 x 6 = 7.2.
    horizon_s : float
        Length of the window checked (s). Default 12.
    step_s : float
        Sampling step of the clearance test (s). Default 0.02.
    control_step_s : float
        The applied acceleration is constant over each control step (s), as a 10 Hz guidance
        would command it: brake and speed cap act per control step. Default 0.1.
    threat_allowance_m : float
        Added to every threat radius (m). Default 1.0.
    world_clearance_m : float
        Smallest clearance from the static world (m). Default 0.5.
    switch_times_s : tuple of float
        Times at which a two-phase manoeuvre switches (s).
    """

    accel_horizontal_m_s2: float = 2.5
    accel_vertical_m_s2: float = 1.5
    speed_max_m_s: float = 1.2 * CRUISE_SPEED_M_S
    horizon_s: float = 12.0
    step_s: float = 0.02
    threat_allowance_m: float = TRACKING_ALLOWANCE_M
    world_clearance_m: float = WORLD_CLEARANCE_M
    control_step_s: float = 0.1
    switch_times_s: tuple = (0.5, 1.0, 1.5, 2.0, 3.0, 4.5, 6.0)

    @property
    def steps(self) -> int:
        """Sampling steps over the window."""
        return self.control_steps * self.substeps

    @property
    def control_steps(self) -> int:
        return int(round(self.horizon_s / self.control_step_s))

    @property
    def substeps(self) -> int:
        """Samples per control step (the control step is a multiple of the sampling step)."""
        return int(round(self.control_step_s / self.step_s))

    @property
    def accel_max_m_s2(self) -> float:
        """Largest norm of an acceleration within the limits."""
        return math.hypot(self.accel_horizontal_m_s2, self.accel_vertical_m_s2)

    def sampling_slack_m(self, other_speed_m_s: float = 0.0) -> float:
        """How much closer than at the samples two bodies can come between two samples (m)."""
        dt = self.step_s
        return (self.speed_max_m_s + other_speed_m_s) * dt / 2.0 + self.accel_max_m_s2 * dt * dt / 8.0


@dataclass(frozen=True)
class Phase:
    """One phase of a manoeuvre.

    Attributes
    ----------
    kind : int
        ``ACCEL`` (constant commanded acceleration), ``BRAKE`` (to a hover at the limits, all
        axes) or ``BRAKE_H`` (horizontal brake, constant vertical acceleration).
    accel_ned_m_s2 : tuple of 3 float
        The commanded acceleration (``ACCEL``), or its vertical part (``BRAKE_H``).
    name : str
    """

    kind: int
    accel_ned_m_s2: tuple = (0.0, 0.0, 0.0)
    name: str = ""


@dataclass(frozen=True)
class Manoeuvre:
    """Two phases: ``first`` until ``switch_s``, then ``second`` (``switch_s >= horizon``: one phase)."""

    first: Phase
    switch_s: float
    second: Phase

    @property
    def name(self) -> str:
        if self.switch_s >= 1e6:
            return self.first.name
        return f"{self.first.name} for {self.switch_s:g} s, then {self.second.name}"


@dataclass(frozen=True)
class Flight:
    """A manoeuvre flown from a state: piecewise-constant applied accelerations, exact samples.

    Attributes
    ----------
    manoeuvre : Manoeuvre
    t0_s : float
        Clock time of the start (s).
    control_step_s : float
    pos_ned_m, vel_ned_m_s : ndarray, shape (N + 1, 3)
        State at the control-step boundaries.
    acc_ned_m_s2 : ndarray, shape (N, 3)
        Applied acceleration during each control step.
    """

    manoeuvre: Manoeuvre
    t0_s: float
    control_step_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    acc_ned_m_s2: np.ndarray

    @property
    def duration_s(self) -> float:
        return self.control_step_s * self.acc_ned_m_s2.shape[0]

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Exact position and velocity (K, 3) at clock times ``t_s`` (K,) within the window."""
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)) - self.t0_s, 0.0, self.duration_s)
        n = self.acc_ned_m_s2.shape[0]
        k = np.minimum((t / self.control_step_s).astype(int), n - 1)
        tau = (t - k * self.control_step_s)[:, None]
        a = self.acc_ned_m_s2[k]
        v = self.vel_ned_m_s[k]
        return self.pos_ned_m[k] + v * tau + 0.5 * a * tau * tau, v + a * tau


@dataclass(frozen=True)
class OracleResult:
    """The oracle's label of one encounter.

    Attributes
    ----------
    avoidable : bool
    witness : Flight or None
        The first manoeuvre found clear (None when unavoidable).
    tried : int
        Manoeuvres flown.
    best_margin_m : float
        Largest, over the manoeuvres tried, of the smallest margin over the window to the threats
        (distance - radius - allowance - sampling slack; the world's margins too when a
        manoeuvre is clear of the threats). >= 0 exactly when avoidable.
    elapsed_ms : float
    """

    avoidable: bool
    witness: Flight | None
    tried: int
    best_margin_m: float
    elapsed_ms: float = field(default=0.0, compare=False)


# ---------------------------------------------------------------------------- manoeuvre grid
def _heading_frame(vel_ned_m_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forward and right vectors (horizontal) of the initial velocity (north if hovering)."""
    vh = np.array([vel_ned_m_s[0], vel_ned_m_s[1]], dtype=float)
    speed = float(np.linalg.norm(vh))
    fwd = vh / speed if speed > 1e-6 else np.array([1.0, 0.0])
    right = np.array([-fwd[1], fwd[0]])
    return fwd, right


def _first_phases(vel_ned_m_s: np.ndarray, limits: OracleLimits) -> list[Phase]:
    fwd, right = _heading_frame(vel_ned_m_s)
    ah, av = limits.accel_horizontal_m_s2, limits.accel_vertical_m_s2
    out = [
        Phase(ACCEL, (0.0, 0.0, 0.0), "keep going"),
        Phase(BRAKE, name="hard stop"),
        Phase(BRAKE_H, (0.0, 0.0, -av), "stop and climb"),
        Phase(BRAKE_H, (0.0, 0.0, av), "stop and descend"),
        Phase(ACCEL, (0.0, 0.0, -av), "climb"),
        Phase(ACCEL, (0.0, 0.0, av), "descend"),
    ]
    for frac in (1.0, 0.5):
        for deg in range(0, 360, 30):
            d = math.cos(math.radians(deg)) * fwd + math.sin(math.radians(deg)) * right
            for vz, vname in ((0.0, ""), (-av, " climbing"), (av, " descending")):
                out.append(
                    Phase(
                        ACCEL, (frac * ah * d[0], frac * ah * d[1], vz), f"accelerate {frac:g} g_h at {deg} deg{vname}"
                    )
                )
    return out


def _second_phases(vel_ned_m_s: np.ndarray, limits: OracleLimits) -> list[Phase]:
    fwd, right = _heading_frame(vel_ned_m_s)
    ah, av = limits.accel_horizontal_m_s2, limits.accel_vertical_m_s2
    out = [
        Phase(BRAKE, name="hard stop"),
        Phase(BRAKE_H, (0.0, 0.0, -av), "stop and climb"),
        Phase(BRAKE_H, (0.0, 0.0, av), "stop and descend"),
        Phase(ACCEL, (0.0, 0.0, 0.0), "coast"),
        Phase(ACCEL, (0.0, 0.0, -av), "climb"),
        Phase(ACCEL, (0.0, 0.0, av), "descend"),
    ]
    for deg in range(0, 360, 45):
        d = math.cos(math.radians(deg)) * fwd + math.sin(math.radians(deg)) * right
        out.append(Phase(ACCEL, (ah * d[0], ah * d[1], 0.0), f"accelerate at {deg} deg"))
    return out


def manoeuvres(vel_ned_m_s, limits: OracleLimits = OracleLimits()) -> list[Manoeuvre]:
    """Every manoeuvre tried, in the order tried: single phases, then pairs by switch time.

    Parameters
    ----------
    vel_ned_m_s : array_like, shape (3,)
        Initial velocity: directions are relative to its heading.
    """
    vel = np.asarray(vel_ned_m_s, dtype=float)
    first = _first_phases(vel, limits)
    second = _second_phases(vel, limits)
    out = [Manoeuvre(p, 1e9, p) for p in first]
    for switch in limits.switch_times_s:
        for p in first:
            for q in second:
                if q == p:
                    continue
                out.append(Manoeuvre(p, float(switch), q))
    return out


# ---------------------------------------------------------------------------- flying
def fly(
    pos0_ned_m, vel0_ned_m_s, batch: list[Manoeuvre], limits: OracleLimits = OracleLimits()
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fly a batch of manoeuvres from one state (applied accelerations constant per control step).

    Each control step: the phase's commanded acceleration (a brake asks for the acceleration
    that stops within the step, limited per axis group), then the speed cap (the new velocity
    projected onto the ball of radius ``speed_max_m_s``), then exact constant-acceleration motion.

    Returns
    -------
    pos, vel : ndarray, shape (M, N + 1, 3)
        State at the control-step boundaries (N = horizon / control step).
    acc : ndarray, shape (M, N, 3)
        Applied accelerations (constant within each control step).
    """
    m = len(batch)
    n = limits.control_steps
    dt = limits.control_step_s
    ah, av = limits.accel_horizontal_m_s2, limits.accel_vertical_m_s2
    a1 = np.array([b.first.accel_ned_m_s2 for b in batch], dtype=float)
    a2 = np.array([b.second.accel_ned_m_s2 for b in batch], dtype=float)
    k1 = np.array([b.first.kind for b in batch])
    k2 = np.array([b.second.kind for b in batch])
    brake_h = (k1 != ACCEL)[:, None], (k2 != ACCEL)[:, None]
    brake_v = k1 == BRAKE, k2 == BRAKE
    switch = np.array([int(round(min(b.switch_s, 1e6) / dt)) for b in batch])
    pos = np.empty((m, n + 1, 3))
    vel = np.empty((m, n + 1, 3))
    acc = np.empty((m, n, 3))
    p = np.tile(np.asarray(pos0_ned_m, dtype=float), (m, 1))
    v = np.tile(np.asarray(vel0_ned_m_s, dtype=float), (m, 1))
    vmax = max(limits.speed_max_m_s, float(np.linalg.norm(v[0])))  # a start above the cap keeps its speed
    pos[:, 0], vel[:, 0] = p, v
    a = np.empty((m, 3))
    for k in range(n):
        second = k >= switch
        const = np.where(second[:, None], a2, a1)
        stop_h = -v[:, :2] / dt  # stop within this step ...
        norm = np.sqrt(stop_h[:, 0] ** 2 + stop_h[:, 1] ** 2)
        stop_h *= np.minimum(1.0, ah / np.maximum(norm, 1e-12))[:, None]  # ... within the limit
        a[:, :2] = np.where(np.where(second[:, None], brake_h[1], brake_h[0]), stop_h, const[:, :2])
        a[:, 2] = np.where(np.where(second, brake_v[1], brake_v[0]), np.clip(-v[:, 2] / dt, -av, av), const[:, 2])
        w = v + a * dt
        sp = np.sqrt(np.einsum("ij,ij->i", w, w))
        w *= np.minimum(1.0, vmax / np.maximum(sp, 1e-12))[:, None]  # onto the speed ball
        applied = (w - v) / dt
        # the projection can tilt the acceleration beyond one axis group's limit: shrink it
        # towards zero (v + s (w - v), s in [0, 1], stays in the ball)
        h = np.sqrt(applied[:, 0] ** 2 + applied[:, 1] ** 2)
        shrink = np.minimum(1.0, np.minimum(ah / np.maximum(h, 1e-12), av / np.maximum(np.abs(applied[:, 2]), 1e-12)))
        applied *= shrink[:, None]
        w = v + applied * dt
        p = p + v * dt + (0.5 * dt * dt) * applied
        v = w
        pos[:, k + 1], vel[:, k + 1], acc[:, k] = p, v, applied
    return pos, vel, acc


def sample_flights(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, limits: OracleLimits) -> np.ndarray:
    """Exact positions (M, S + 1, 3) every ``step_s`` from the control-step states of ``fly``."""
    sub = limits.substeps
    tau = limits.step_s * np.arange(sub)  # (sub,)
    inner = (
        pos[:, :-1, None, :]
        + vel[:, :-1, None, :] * tau[None, None, :, None]
        + 0.5 * acc[:, :, None, :] * (tau * tau)[None, None, :, None]
    )
    m = pos.shape[0]
    return np.concatenate([inner.reshape(m, -1, 3), pos[:, -1:, :]], axis=1)


def _speed_m_s(threat) -> float:
    """A bound of the threat's speed: a track's fastest segment, a record's constant velocity."""
    if hasattr(threat, "max_speed_m_s"):
        return float(threat.max_speed_m_s)
    return float(np.linalg.norm(threat.velocity_ned_m_s))


def _threat_tracks(threats, t0_s: float, limits: OracleLimits):
    t = t0_s + limits.step_s * np.arange(limits.steps + 1)
    out = []
    for th in threats:
        limit = th.radius_m + limits.threat_allowance_m + limits.sampling_slack_m(_speed_m_s(th))
        out.append((np.asarray(th.position_at(t), dtype=float).reshape(-1, 3), limit))
    return out


def _speeds(threats) -> list[float]:
    return [_speed_m_s(th) for th in threats]


def _threat_margins(pos: np.ndarray, tracks) -> np.ndarray:
    """Smallest margin (M,) over the window and every threat (inf without threats)."""
    out = np.full(pos.shape[0], np.inf)
    for centers, limit in tracks:
        diff = pos - centers[None, :, :]
        dist = np.sqrt(np.einsum("mki,mki->mk", diff, diff))
        out = np.minimum(out, dist.min(axis=1) - limit)
    return out


def _world_margins(pos: np.ndarray, world, limits: OracleLimits, slack: bool = True) -> np.ndarray:
    """Smallest margin (M,) to the static world and its bounds over the window (``slack``: with
    the sampling slack, for samples every ``step_s``; without, a necessary condition at any subset)."""
    slack = limits.sampling_slack_m() if slack else 0.0
    lo = np.asarray(world.bounds_min, dtype=float)
    hi = np.asarray(world.bounds_max, dtype=float)
    inside = np.minimum((pos - lo).min(axis=2), (hi - pos).min(axis=2)).min(axis=1) - slack
    if not world.obstacles:
        return inside
    m, k, _ = pos.shape
    clear = world.clearance_m(pos.reshape(-1, 3)).reshape(m, k).min(axis=1)
    return np.minimum(inside, clear - limits.world_clearance_m - slack)


def flight_margins(flight: Flight, threats, world=None, *, step_s: float = 0.005) -> tuple[float, float]:
    """Re-check a flight at ``step_s`` without sampling slack.

    Returns
    -------
    (threat_margin_m, world_margin_m)
        Smallest distance - radius - allowance over every threat, and smallest clearance -
        ``world_clearance_m`` (or distance to the bounds), over the window (inf when absent).
    """
    t = flight.t0_s + np.arange(0.0, flight.duration_s + 0.5 * step_s, step_s)
    pos = flight.sample(t)[0]
    threat = math.inf
    for th in threats:
        dist = np.linalg.norm(pos - th.position_at(t), axis=1)
        threat = min(threat, float(dist.min()) - th.radius_m - TRACKING_ALLOWANCE_M)
    worldm = math.inf
    if world is not None:
        lo = np.asarray(world.bounds_min, dtype=float)
        hi = np.asarray(world.bounds_max, dtype=float)
        worldm = float(min((pos - lo).min(), (hi - pos).min()))
        if world.obstacles:
            worldm = min(worldm, float(world.clearance_m(pos).min()) - WORLD_CLEARANCE_M)
    return threat, worldm


def _first_clear(pos0, vel0, batch: list, tracks, coarse_tracks, world, limits: OracleLimits):
    """(the first manoeuvre of ``batch`` that stays clear or None, the best margin seen)."""
    pos_c, vel_c, acc_c = fly(pos0, vel0, batch, limits)
    # a manoeuvre that meets a threat at a control-step boundary (a subset of the samples)
    # fails for sure: only the others are sampled every step_s
    coarse = _threat_margins(pos_c, coarse_tracks)
    keep = np.flatnonzero(coarse >= 0.0)
    if keep.size == 0:
        return None, float(coarse.max())
    batch = [batch[i] for i in keep]
    pos = sample_flights(pos_c[keep], vel_c[keep], acc_c[keep], limits)
    margin = _threat_margins(pos, tracks)
    ok = np.flatnonzero(margin >= 0.0)
    if ok.size == 0:
        return None, float(margin.max())
    best = -math.inf
    start, chunk = 0, 16
    while start < ok.size:  # world and bounds, in order, until one is clear
        idx = ok[start : start + chunk]
        start, chunk = start + chunk, 4 * chunk
        both = margin[idx]
        if world is not None:
            # coarse first (the control-step boundaries, no slack: a failure there is final)
            coarse_w = _world_margins(pos_c[keep][idx], world, limits, slack=False)
            idx, both = idx[coarse_w >= 0.0], both[coarse_w >= 0.0]
            if idx.size == 0:
                best = max(best, float(coarse_w.max()))
                continue
            both = np.minimum(both, _world_margins(pos[idx], world, limits))
        best = max(best, float(both.max()))
        good = np.flatnonzero(both >= 0.0)
        if good.size:
            return batch[idx[good[0]]], best
    return None, best


# ---------------------------------------------------------------------------- the label
def label_encounter(
    pos0_ned_m,
    vel0_ned_m_s,
    threats,
    t0_s: float,
    world=None,
    *,
    limits: OracleLimits = OracleLimits(),
    batch_size: int = 4000,
) -> OracleResult:
    """Is the encounter avoidable? Brute force over ``manoeuvres`` (see the module docstring).

    Parameters
    ----------
    pos0_ned_m, vel0_ned_m_s : array_like, shape (3,)
        Reference state at the encounter start (NED, m and m/s).
    threats : sequence of companion.threats.model.Threat or IntruderTrack
        Local-frame threats, stamped on the same clock as ``t0_s``, or true tracks on it.
    t0_s : float
        Clock time of the encounter start (s).
    world : companion.world.World (3D) or None
        Static obstacles and bounds; normally without a safety margin (the oracle adds
        ``world_clearance_m``). None: open air without bounds.
    limits : OracleLimits

    Returns
    -------
    OracleResult
    """
    t_start = time.perf_counter()
    pos0 = np.asarray(pos0_ned_m, dtype=float).reshape(3)
    vel0 = np.asarray(vel0_ned_m_s, dtype=float).reshape(3)
    threats = list(threats)
    for th in threats:
        if isinstance(th, Threat) and th.frame != "local_ned":
            raise ValueError(f"threats: expected local-frame Threat records, got {th!r}")
        if not (hasattr(th, "position_at") and hasattr(th, "radius_m")):
            raise ValueError(f"threats: expected Threat records or tracks (position_at, radius_m), got {th!r}")
    tracks = _threat_tracks(threats, t0_s, limits)
    coarse_tracks = [
        (centers[:: limits.substeps], limit - limits.sampling_slack_m(speed))
        for (centers, limit), speed in zip(tracks, _speeds(threats))
    ]
    candidates = manoeuvres(vel0, limits)
    best = -math.inf
    tried = 0
    # the single phases first (cheap, and most avoidable encounters end there), then the pairs
    n_single = sum(1 for c in candidates if c.switch_s >= 1e6)
    bounds = [(0, n_single)] + [
        (s, min(s + batch_size, len(candidates))) for s in range(n_single, len(candidates), batch_size)
    ]
    for lo, hi in bounds:
        batch = candidates[lo:hi]
        tried += len(batch)
        found, margin = _first_clear(pos0, vel0, batch, tracks, coarse_tracks, world, limits)
        best = max(best, margin)
        if found is not None:
            return _result(pos0, vel0, found, limits, t0_s, tried, best, t_start)
    return OracleResult(False, None, tried, best, (time.perf_counter() - t_start) * 1e3)


def _result(pos0, vel0, man: Manoeuvre, limits, t0_s, tried, best, t_start) -> OracleResult:
    pos, vel, acc = fly(pos0, vel0, [man], limits)
    flight = Flight(man, float(t0_s), limits.control_step_s, pos[0], vel[0], acc[0])
    return OracleResult(True, flight, tried, best, (time.perf_counter() - t_start) * 1e3)
