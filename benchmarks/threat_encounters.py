"""Encounter geometries of the threat benchmark (seeded and pure: same index and seed, same encounter).

Used by ``benchmarks/threats.py``; DESIGN section 7 (threats are spheres moving at constant
velocity), paper section 3.3 (pop-up and moving threats, Fig. 5 and Fig. 8).

Legs. The vehicle flies a leg at down = -20 m in a 3D world whose down bounds are [-40, -5]
(so there is room to climb 20 m and to descend 15 m):

- ``open``: no obstacle, north and east in [-30, 130]; the leg is the straight line from
  (0, 0) to (99, 99);
- ``cluttered``: the public 2D benchmark world ``worlds.make_world("2d", seed)`` (30 discs in
  100 x 100 m, seeds 0-19) with every disc extruded to a vertical ``Cylinder`` over the whole
  height; the leg is GART (a fixed number of iterations, so it is deterministic) on the discs
  inflated by ``MARGIN_M`` from (0, 0) to (99, 99), G2-smoothed with K_max = 0.1 1/m.

The nominal trajectory is the speed profile of that curve (``TrajectoryLimits(speed_m_s=6)``)
lifted to down = -20 m. ``Leg.world`` (margin ``MARGIN_M``) is what the policy plans in;
``Leg.raw_world`` (no margin) is what the vehicle is judged against and what the oracle uses.

Encounters. Encounter ``i`` has the category ``CATEGORIES[i % 6]`` in the world
``WORLD_KINDS[(i // 6) % 2]`` (cluttered worlds cycle through the seeds), so every run is
balanced. At ``t_enc_s`` (uniform along the leg) the threats become known:

- ``head_on``: a threat coming along the leg towards the vehicle (velocity opposite to the
  vehicle's at the closest approach) at 0.1-1.5 x cruise speed;
- ``crossing``: crossing the vehicle's track at 30-150 degrees, either side, 0.1-1.5 x cruise;
- ``overtaking``: from behind, along the track, faster than the vehicle (1.1 x its speed at the
  encounter start, at least, up to 1.5 x cruise);
- ``popup_near`` / ``popup_far``: a static threat on the path 1-3 s / 3-6 s ahead;
- ``multi``: two or three of the above at once, each a real encounter by itself.

Every threat is aimed at a point of the nominal reference ``t_ca`` seconds ahead, offset by a
random 3D miss vector, radius 2-6 m. It is kept only if it is a real encounter against the
nominal reference (the vehicle not reacting): the closest approach is 1-8 s after the encounter
start (1-3 s / 3-6 s for the pop-ups), the miss distance is below the threat's radius, the
threat is not already within its radius + ``start_margin_m`` (the policy's inflation, 2 m) of the
vehicle at the start, and it does not block the goal: within 60 s it is within radius + start
margin + 3 m of the goal for at most 5 s in all (a mover may pass the goal, a pop-up may not sit
on it). Otherwise the draw is repeated with the same generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from benchmarks.worlds import make_world
from companion.planning import GartSettings, gart
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.model import Threat
from companion.world import Cylinder, World

__all__ = [
    "CATEGORIES",
    "WORLD_KINDS",
    "Leg",
    "Encounter",
    "make_leg",
    "encounter_world",
    "make_encounter",
    "closest_approach",
    "LIMITS",
    "KAPPA_MAX_1_M",
    "DOWN_M",
    "MARGIN_M",
    "CRUISE_SPEED_M_S",
    "N_WORLD_SEEDS",
    "START_MARGIN_M",
]

CATEGORIES = ("head_on", "crossing", "overtaking", "popup_near", "popup_far", "multi")
WORLD_KINDS = ("open", "cluttered")
#: Cruise speed (m/s) and limits of the nominal trajectories (and of the policy's).
CRUISE_SPEED_M_S = 6.0
LIMITS = TrajectoryLimits(speed_m_s=CRUISE_SPEED_M_S)
KAPPA_MAX_1_M = 0.1
#: Down coordinate of the legs (m) and the down bounds of the worlds (m).
DOWN_M = -20.0
DOWN_BOUNDS_M = (-40.0, -5.0)
#: Safety margin of the world the policy plans in (m).
MARGIN_M = 1.0
#: Seeds of the public 2D benchmark worlds.
N_WORLD_SEEDS = 20
#: GART iterations of the nominal leg in a cluttered world (fixed, so the leg is reproducible):
#: the first count that finds a path.
NOMINAL_GART_ITERATIONS = (1000, 3000, 10000)
OPEN_BOUNDS_NE_M = (-30.0, 130.0)
RADIUS_RANGE_M = (2.0, 6.0)
#: Closest approach window (s after the encounter start) of the moving threats.
CPA_WINDOW_S = (1.0, 8.0)
POPUP_WINDOWS_S = {"popup_near": (1.0, 3.0), "popup_far": (3.0, 6.0)}
#: Scan of the closest approach (s, step s) and of the goal's clearance (s).
SCAN_S, SCAN_STEP_S, GOAL_SCAN_S, GOAL_SCAN_STEP_S = 12.0, 0.02, 60.0, 0.1
#: A threat may not block the goal (come within radius + start margin + GOAL_CLEARANCE_M of it)
#: for more than GOAL_BLOCKED_S within GOAL_SCAN_S: a mover may pass it, a pop-up may not sit on it.
GOAL_CLEARANCE_M, GOAL_BLOCKED_S = 3.0, 5.0
#: A threat starts farther than its radius + this from the vehicle (m): the policy's default
#: inflation (``ThreatSettings.inflation_m``).
START_MARGIN_M = 2.0
MAX_DRAWS = 200


@dataclass(frozen=True)
class Leg:
    """One leg: its worlds, ends and nominal trajectory (3D samples, NED).

    Attributes
    ----------
    world_kind : str
        ``open`` or ``cluttered``.
    seed : int
        Seed of the benchmark world (0 for open air).
    world : World
        3D, with the safety margin ``MARGIN_M`` (the policy's world).
    raw_world : World
        3D, no margin (judging and oracle).
    start_ned_m, goal_ned_m : ndarray, shape (3,)
    trajectory : Trajectory
        The nominal reference, t = 0 at the leg start.
    """

    world_kind: str
    seed: int
    world: World
    raw_world: World
    start_ned_m: np.ndarray
    goal_ned_m: np.ndarray
    trajectory: object

    @property
    def name(self) -> str:
        return "open" if self.world_kind == "open" else f"cluttered-{self.seed}"


@dataclass(frozen=True)
class Encounter:
    """One encounter: threats that become known at ``t_enc_s`` on a leg.

    Attributes
    ----------
    index : int
    category : str
        One of ``CATEGORIES``.
    world_kind : str
    world_seed : int
    t_enc_s : float
        Clock time (s since the leg start) at which the threats become known.
    threats : tuple of Threat
        Stamped ``received_t_s = t_enc_s``.
    kinds : tuple of str
        Geometry of each threat (``head_on``, ``crossing``, ``overtaking``, ``popup``).
    cpa : tuple of (float, float)
        Time after ``t_enc_s`` (s) and distance (m) of each threat's closest approach to the
        nominal reference.
    """

    index: int
    category: str
    world_kind: str
    world_seed: int
    t_enc_s: float
    threats: tuple
    kinds: tuple
    cpa: tuple

    @property
    def label(self) -> str:
        return f"{self.category}/{self.world_kind}"


# ---------------------------------------------------------------------------- legs
def make_leg(world_kind: str, seed: int = 0) -> Leg:
    """The leg of ``world_kind`` (``open`` | ``cluttered``) and benchmark world ``seed``.

    Deterministic (GART with a fixed iteration count and a seeded generator); ~0.5 s.
    """
    down_lo, down_hi = DOWN_BOUNDS_M
    start = np.array([0.0, 0.0])
    goal = np.array([99.0, 99.0])
    if world_kind == "open":
        lo, hi = OPEN_BOUNDS_NE_M
        world = World([], [lo, lo, down_lo], [hi, hi, down_hi], margin_m=MARGIN_M)
        raw = World([], [lo, lo, down_lo], [hi, hi, down_hi])
        path2 = np.vstack([start, goal])
        curve = smooth_g2(path2, KAPPA_MAX_1_M)
    elif world_kind == "cluttered":
        bw = make_world("2d", seed)
        flat = World(bw.world.obstacles, bw.world.bounds_min, bw.world.bounds_max, margin_m=MARGIN_M)
        gs = GartSettings(kappa_max_1_m=KAPPA_MAX_1_M)
        for iterations in NOMINAL_GART_ITERATIONS:  # more only where the first finds nothing
            res = gart(flat, bw.start, bw.goal, rng=np.random.default_rng(seed), max_iterations=iterations, settings=gs)
            if res.status == "exact":
                break
        if res.status != "exact":
            raise RuntimeError(f"benchmark world {seed}: GART found no nominal path ({res.status})")
        cylinders = [Cylinder(tuple(ob.center_m), ob.radius_m, down_lo, down_hi) for ob in bw.world.obstacles]
        lo3 = [*bw.world.bounds_min, down_lo]
        hi3 = [*bw.world.bounds_max, down_hi]
        world = World(cylinders, lo3, hi3, margin_m=MARGIN_M)
        raw = World(cylinders, lo3, hi3)
        curve = smooth_g2(res.path, KAPPA_MAX_1_M, world=flat)
    else:
        raise ValueError(f"world_kind: expected one of {WORLD_KINDS}, got {world_kind!r}")
    traj = time_parameterize(curve, LIMITS).to_ned(DOWN_M)
    return Leg(world_kind, int(seed), world, raw, np.array([*start, DOWN_M]), np.array([*goal, DOWN_M]), traj)


def encounter_world(index: int) -> tuple[str, str, int]:
    """(category, world kind, world seed) of encounter ``index`` (balanced over the indices)."""
    category = CATEGORIES[index % len(CATEGORIES)]
    world_kind = WORLD_KINDS[(index // len(CATEGORIES)) % len(WORLD_KINDS)]
    seed = (index // (len(CATEGORIES) * len(WORLD_KINDS))) % N_WORLD_SEEDS if world_kind == "cluttered" else 0
    return category, world_kind, seed


# ---------------------------------------------------------------------------- threats
def closest_approach(
    trajectory, threat: Threat, t_enc_s: float, scan_s: float = SCAN_S, step_s: float = SCAN_STEP_S
) -> tuple[float, float, float]:
    """Closest approach of ``threat`` to the reference (not reacting) over [t_enc, t_enc + scan].

    Returns
    -------
    (t_rel_s, miss_m, start_m)
        Time after ``t_enc_s`` and distance (centre to reference) of the closest approach, and
        the distance at ``t_enc_s``.
    """
    t = t_enc_s + np.arange(0.0, scan_s + 0.5 * step_s, step_s)
    pos = trajectory.sample(t)[0]
    dist = np.linalg.norm(pos - threat.position_at(t), axis=1)
    k = int(np.argmin(dist))
    return float(t[k] - t_enc_s), float(dist[k]), float(dist[0])


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])


def _rotate_horizontal(u: np.ndarray, angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1], 0.0])


def _draw_threat(
    kind: str, window: tuple[float, float], leg: Leg, t_enc_s: float, tid: str, rng: np.random.Generator
) -> Threat:
    """One threat of geometry ``kind`` aimed at the reference ``t_ca`` s ahead (not yet validated)."""
    traj = leg.trajectory
    t_ca = rng.uniform(*window)
    radius = rng.uniform(*RADIUS_RANGE_M)
    p_ca, v_ca, _ = traj.sample(np.array([t_enc_s + t_ca]))
    p_ca, v_ca = p_ca[0], v_ca[0]
    v_now = traj.sample(np.array([t_enc_s]))[1][0]
    tangent = _unit(np.array([v_ca[0], v_ca[1], 0.0]))
    miss = rng.normal(size=3)
    miss *= rng.uniform(0.0, 0.75) * radius / max(float(np.linalg.norm(miss)), 1e-9)
    aim = p_ca + miss
    if kind == "popup":
        vel = np.zeros(3)
    elif kind == "head_on":
        vel = -tangent * rng.uniform(0.1, 1.5) * CRUISE_SPEED_M_S
    elif kind == "crossing":
        angle = math.radians(rng.uniform(30.0, 150.0)) * rng.choice([-1.0, 1.0])
        vel = _rotate_horizontal(tangent, angle) * rng.uniform(0.1, 1.5) * CRUISE_SPEED_M_S
    elif kind == "overtaking":
        v_vehicle = max(float(np.linalg.norm(v_now)), float(np.linalg.norm(v_ca)))
        lo = max(1.1 * v_vehicle, 0.5)
        vel = tangent * rng.uniform(lo, max(lo, 1.5 * CRUISE_SPEED_M_S))
    else:
        raise ValueError(f"kind: unknown threat geometry {kind!r}")
    center = aim - vel * t_ca
    return Threat(
        tid,
        "popup" if kind == "popup" else "moving",
        "local_ned",
        tuple(float(x) for x in center),
        tuple(float(x) for x in vel),
        float(radius),
        None,
        float(t_enc_s),
    )


def _valid(
    threat: Threat, window: tuple[float, float], leg: Leg, t_enc_s: float, start_margin_m: float
) -> tuple[float, float] | None:
    """(t_ca, miss) when ``threat`` is a real encounter (module docstring), else None."""
    t_ca, miss, start = closest_approach(leg.trajectory, threat, t_enc_s)
    if not (window[0] <= t_ca <= window[1]) or miss >= threat.radius_m:
        return None
    if start <= threat.radius_m + start_margin_m:
        return None
    t = t_enc_s + np.arange(0.0, GOAL_SCAN_S, GOAL_SCAN_STEP_S)
    to_goal = np.linalg.norm(threat.position_at(t) - leg.goal_ned_m[None, :], axis=1)
    near = np.count_nonzero(to_goal <= threat.radius_m + start_margin_m + GOAL_CLEARANCE_M)
    if near * GOAL_SCAN_STEP_S > GOAL_BLOCKED_S:
        return None
    return t_ca, miss


def make_encounter(index: int, leg: Leg, seed: int = 0, *, start_margin_m: float = START_MARGIN_M) -> Encounter | None:
    """Encounter ``index`` on ``leg`` (which must be ``encounter_world(index)``'s leg).

    Parameters
    ----------
    index : int
    leg : Leg
    seed : int
        Master seed: the generator is ``numpy.random.default_rng([seed, index])``.
    start_margin_m : float
        A threat must start farther than its radius + this from the vehicle. Default
        ``START_MARGIN_M`` (a constant, so that the encounters do not change with the policy's
        settings).

    Returns
    -------
    Encounter or None
        None if no valid encounter was found in ``MAX_DRAWS`` draws (does not happen with the
        benchmark legs).
    """
    category, world_kind, world_seed = encounter_world(index)
    if leg.world_kind != world_kind or leg.seed != world_seed:
        raise ValueError(f"leg: encounter {index} is on {world_kind}-{world_seed}, got {leg.name}")
    rng = np.random.default_rng([seed, index])
    traj = leg.trajectory
    t_hi = traj.duration_s - 10.0
    for _ in range(MAX_DRAWS):
        t_enc = float(rng.uniform(3.0, max(t_hi, 3.5)))
        if float(np.linalg.norm(traj.sample(np.array([t_enc]))[1][0])) < 1.0:
            continue
        if category == "multi":
            n = int(rng.integers(2, 4))
            kinds = tuple(rng.choice(["head_on", "crossing", "overtaking", "popup"], size=n))
        elif category.startswith("popup"):
            kinds = ("popup",)
        else:
            kinds = (category,)
        threats, cpa = [], []
        for j, kind in enumerate(kinds):
            kind = str(kind)
            window = POPUP_WINDOWS_S.get(category, (1.0, 6.0) if kind == "popup" else CPA_WINDOW_S)
            got = None
            for _ in range(10):
                th = _draw_threat(kind, window, leg, t_enc, f"t{j}", rng)
                got = _valid(th, window, leg, t_enc, start_margin_m)
                if got is not None:
                    break
            if got is None:
                break
            threats.append(th)
            cpa.append(got)
        if len(threats) == len(kinds):
            return Encounter(
                index, category, world_kind, world_seed, t_enc, tuple(threats), tuple(str(k) for k in kinds), tuple(cpa)
            )
    return None
