"""Drone-scale encounters of the parametric strata (paper section 3.3, at the paper's scale).

Every intruder is aimed at the helicopter's own unmitigated flight (the track it flies when it
ignores threats, ``companion.campaign.flying``): at ``t_ca`` seconds after its first report it
passes the helicopter's position then at a miss distance drawn uniformly in
``[0, radius + MISS_EXTRA_M]``, across their relative velocity at a uniform angle about it (so,
where the helicopter flies straight, that is the closest approach). So a stratum holds collisions, NMACs, losses
of well clear and encounters that stay clear, in known proportions (the nominal distribution of
the stratum: the weight is 1).

==================  =====================================================================
geometry            the intruder
==================  =====================================================================
``head_on``         along the track towards the vehicle, 0.3-1.5 x cruise speed
``crossing``        across the track at 30-150 degrees, either side, 0.3-1.5 x cruise
``overtaking``      from behind along the track, 1.2 x the vehicle's speed to 2 x cruise
``above``           from above, descending at 1-3 m/s, horizontally 0-1 x cruise any way
``below``           from below, climbing at 1-3 m/s
``popup_near``      a static threat on the path 1-3 s ahead
``popup_far``       a static threat on the path 3-6 s ahead
``popup_mover``     appears 2-5 s before the closest approach, crossing at 0.3-1 x cruise
``multi``           two or three of head-on, crossing, overtaking and pop-up at once
``turning``         a crossing or head-on intruder that turns 30-90 degrees 1-3 s after its
                    first report (after the first decision)
``climbing``        one that climbs or descends at 1-3 m/s from 1-3 s after its first report
==================  =====================================================================

Radii are 2-6 m; movers' closest approach comes 2-10 s after the first report. Every intruder is
reported until the flight's end (the end of the mission + 10 s, or 25 s after the last closest
approach). ``above`` and
``below`` aim at the climbing or descending part of the ``climb`` and ``descend`` missions. An
intruder does not start within its radius + ``START_MARGIN_M`` of the vehicle, nor sit on the
goal (a pop-up within radius + 5 m of it).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from companion.campaign.tracks import Encounter, IntruderTrack, straight_track

__all__ = ["GEOMETRIES", "OwnFlight", "make_parametric", "MISS_EXTRA_M", "CRUISE_M_S"]

GEOMETRIES = (
    "head_on",
    "crossing",
    "overtaking",
    "above",
    "below",
    "popup_near",
    "popup_far",
    "popup_mover",
    "multi",
    "turning",
    "climbing",
)
CRUISE_M_S = 6.0
RADIUS_M = (2.0, 6.0)
MISS_EXTRA_M = 6.0
START_MARGIN_M = 2.0
MOVER_CPA_S = (2.0, 10.0)
POPUP_CPA_S = {"popup_near": (1.0, 3.0), "popup_far": (3.0, 6.0), "popup": (1.0, 6.0), "popup_mover": (2.0, 5.0)}
#: The flight goes on this long after the last closest approach when the mission is not done.
AFTER_S = 25.0
MAX_DRAWS = 200


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])


def _rotate_ne(u: np.ndarray, angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1], 0.0])


class OwnFlight:
    """The helicopter's unmitigated flight, sampled: positions and velocities at any time.

    Parameters
    ----------
    t_s : ndarray, shape (K,)
    pos_ned_m : ndarray, shape (K, 3)
    """

    def __init__(self, t_s: np.ndarray, pos_ned_m: np.ndarray) -> None:
        self.t_s = np.asarray(t_s, dtype=float)
        self.pos_ned_m = np.asarray(pos_ned_m, dtype=float)

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) at ``t_s`` (velocity over +-0.2 s)."""
        p = np.array([np.interp(t_s, self.t_s, self.pos_ned_m[:, a]) for a in range(3)])
        lo, hi = max(t_s - 0.2, self.t_s[0]), min(t_s + 0.2, self.t_s[-1])
        pl = np.array([np.interp(lo, self.t_s, self.pos_ned_m[:, a]) for a in range(3)])
        ph = np.array([np.interp(hi, self.t_s, self.pos_ned_m[:, a]) for a in range(3)])
        return p, (ph - pl) / max(hi - lo, 1e-6)

    @property
    def end_t_s(self) -> float:
        return float(self.t_s[-1])


def _across(rel_m_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A unit vector across the relative velocity, its angle about it uniform: the miss at the
    aim is then the closest approach of two straight tracks."""
    axis = _unit(rel_m_s) if float(np.linalg.norm(rel_m_s)) > 1e-6 else np.array([1.0, 0.0, 0.0])
    ref = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = _unit(np.cross(axis, ref))
    e2 = np.cross(axis, e1)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return math.cos(angle) * e1 + math.sin(angle) * e2


def _velocity(kind: str, tangent: np.ndarray, v_own: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    if kind in ("popup", "popup_near", "popup_far"):
        return np.zeros(3)
    if kind == "head_on":
        return -tangent * rng.uniform(0.3, 1.5) * CRUISE_M_S
    if kind in ("crossing", "popup_mover"):
        angle = math.radians(rng.uniform(30.0, 150.0)) * rng.choice([-1.0, 1.0])
        top = 1.0 if kind == "popup_mover" else 1.5
        return _rotate_ne(tangent, angle) * rng.uniform(0.3, top) * CRUISE_M_S
    if kind == "overtaking":
        lo = max(1.2 * float(np.linalg.norm(v_own)), 1.0)
        return tangent * rng.uniform(lo, max(lo, 2.0 * CRUISE_M_S))
    if kind in ("above", "below"):
        horizontal = _rotate_ne(np.array([1.0, 0.0, 0.0]), rng.uniform(0.0, 2 * math.pi))
        vertical = rng.uniform(1.0, 3.0) * (1.0 if kind == "above" else -1.0)  # down positive
        return horizontal * rng.uniform(0.0, 1.0) * CRUISE_M_S + np.array([0.0, 0.0, vertical])
    raise ValueError(f"geometry: unknown intruder geometry {kind!r}")


def _manoeuvre(kind: str, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The velocity after a ``turning`` or ``climbing`` intruder's manoeuvre."""
    if kind == "turning":
        return _rotate_ne(v, math.radians(rng.uniform(30.0, 90.0)) * rng.choice([-1.0, 1.0])) + np.array(
            [0.0, 0.0, v[2]]
        )
    return v + np.array([0.0, 0.0, rng.uniform(1.0, 3.0) * rng.choice([-1.0, 1.0])])


def _aim_times(kind: str, own: OwnFlight, rng: np.random.Generator, vertical: bool) -> tuple[float, float]:
    """(first report time, closest-approach delay) for one intruder."""
    window = POPUP_CPA_S.get(kind, MOVER_CPA_S)
    t_ca = float(rng.uniform(*window))
    if vertical:  # aim inside the climb or descent
        speeds = np.abs(np.gradient(own.pos_ned_m[:, 2], own.t_s))
        moving = own.t_s[speeds > 0.5]
        t_aim = float(rng.uniform(moving[0], moving[-1])) if moving.size else float(rng.uniform(2.0, 10.0))
        return max(t_aim - t_ca, 0.5), t_ca
    return float(rng.uniform(3.0, max(own.end_t_s - 12.0, 4.0))), t_ca


def _draw_intruder(
    kind: str,
    tid: str,
    own: OwnFlight,
    goal_ned_m: np.ndarray,
    t_report: float,
    t_ca: float,
    end_t_s: float,
    rng: np.random.Generator,
    manoeuvre: str | None,
) -> IntruderTrack | None:
    radius = float(rng.uniform(*RADIUS_M))
    p_ca, v_ca = own.at(t_report + t_ca)
    p_now, v_now = own.at(t_report)
    if float(np.linalg.norm(v_now)) < 1.0 and kind not in ("above", "below"):
        return None
    tangent = _unit(np.array([v_ca[0], v_ca[1], 0.0]) if np.hypot(v_ca[0], v_ca[1]) > 0.5 else goal_ned_m - p_ca)
    tangent[2] = 0.0
    base = (
        "head_on"
        if kind == "turning" and rng.random() < 0.5
        else ("crossing" if kind in ("turning", "climbing") else kind)
    )
    v = _velocity(base, tangent, v_now, rng)
    miss = _across(v - v_ca, rng) * rng.uniform(0.0, radius + MISS_EXTRA_M)
    start = p_ca + miss - v * t_ca
    if float(np.linalg.norm(start - p_now)) <= radius + START_MARGIN_M:
        return None
    popup = base in ("popup", "popup_near", "popup_far")
    if popup and float(np.linalg.norm(start - goal_ned_m)) <= radius + 5.0:
        return None
    turn_t = v_after = None
    if manoeuvre is not None:
        turn_t = t_report + float(rng.uniform(1.0, 3.0))
        v_after = _manoeuvre(manoeuvre, v, rng)
    return straight_track(
        tid, t_report, end_t_s, start, v, radius, turn_t_s=turn_t, v_after_ned_m_s=v_after, popup=popup
    )


def make_parametric(
    index: int,
    stratum: str,
    geometry: str,
    mission: str,
    own: OwnFlight,
    goal_ned_m: np.ndarray,
    delivery: dict,
    rng: np.random.Generator,
) -> Encounter:
    """Encounter ``index`` of a parametric stratum against the unmitigated flight ``own``.

    Raises
    ------
    RuntimeError
        No valid geometry in ``MAX_DRAWS`` draws (the mission is too short for the stratum).
    """
    if geometry not in GEOMETRIES:
        raise ValueError(f"geometry: expected one of {', '.join(GEOMETRIES)}, got {geometry!r}")
    vertical = geometry in ("above", "below")
    for _ in range(MAX_DRAWS):
        if geometry == "multi":
            kinds = [
                str(k) for k in rng.choice(["head_on", "crossing", "overtaking", "popup"], size=int(rng.integers(2, 4)))
            ]
        else:
            kinds = [geometry]
        t_report, _ = _aim_times(kinds[0], own, rng, vertical)
        intruders, cpas = [], []
        for j, kind in enumerate(kinds):
            t_ca = float(rng.uniform(*POPUP_CPA_S.get(kind, MOVER_CPA_S)))
            if vertical and j == 0:
                t_report, t_ca = _aim_times(kind, own, rng, True)
            end = t_report + t_ca + AFTER_S
            manoeuvre = geometry if geometry in ("turning", "climbing") else None
            track = _draw_intruder(kind, f"t{j}", own, goal_ned_m, t_report, t_ca, end, rng, manoeuvre)
            if track is None:
                break
            intruders.append(track)
            cpas.append(t_report + t_ca)
        if len(intruders) == len(kinds):
            end = max(max(cpas) + AFTER_S, own.end_t_s + 10.0)
            params = {"t_report_s": t_report, "t_cpa_s": max(cpas), "kinds": kinds}
            heard = tuple(dataclasses.replace(tr, last_report_t_s=end) for tr in intruders)  # to the end
            return Encounter(index, stratum, mission, "drone", heard, 1.0, end, delivery, params)
    raise RuntimeError(f"encounter {index} ({stratum}): no valid geometry in {MAX_DRAWS} draws")
