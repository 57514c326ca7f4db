"""How close each intruder came: miss distances and the event flags, on the vehicle's own track.

Separations are taken between the helicopter's own positions (the closed-loop model's, every
executor tick) and the intruders' *true* positions at those times, never the companion's
estimates. Per intruder:

- the closest approach is the sample of least 3D distance; ``hmd`` and ``vmd`` are the horizontal
  and vertical distances there (miss distances, DO-365 style);
- *drone scale*: the volumes are spheres about the intruder: collision inside the bare radius
  (+ ``collision_extra_m``), NMAC-analogue inside radius + ``nmac_extra_m``, LoWC-analogue
  inside radius + ``lowc_extra_m``;
- *manned traffic*: cylinders: NMAC when at once horizontally within ``nmac_h_ft`` and
  vertically within ``nmac_v_ft`` (500 ft, 100 ft), loss of well clear within ``wc_h_ft`` and
  ``wc_v_ft`` (2000 ft, 250 ft, ASTM F3442), collision inside the emitter's radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.world import World

__all__ = ["Volumes", "Separation", "separation", "entries", "path_length_m", "FT_M"]

FT_M = 0.3048


@dataclass(frozen=True)
class Volumes:
    """The event volumes (``[volumes]`` of a campaign spec).

    Parameters
    ----------
    collision_extra_m, nmac_extra_m, lowc_extra_m : float
        Drone scale: metres beyond the threat's bare radius.
    nmac_h_ft, nmac_v_ft, wc_h_ft, wc_v_ft : float
        Manned traffic: the NMAC and well-clear cylinders (feet).
    """

    collision_extra_m: float = 0.0
    nmac_extra_m: float = 1.0
    lowc_extra_m: float = 3.0
    nmac_h_ft: float = 500.0
    nmac_v_ft: float = 100.0
    wc_h_ft: float = 2000.0
    wc_v_ft: float = 250.0

    def __post_init__(self) -> None:
        for name in (
            "collision_extra_m",
            "nmac_extra_m",
            "lowc_extra_m",
            "nmac_h_ft",
            "nmac_v_ft",
            "wc_h_ft",
            "wc_v_ft",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
                raise ValueError(f"volumes.{name}: must be a finite number >= 0, got {value!r}")
        if not self.collision_extra_m <= self.nmac_extra_m <= self.lowc_extra_m:
            raise ValueError("volumes: expected collision_extra_m <= nmac_extra_m <= lowc_extra_m")
        if self.nmac_h_ft > self.wc_h_ft or self.nmac_v_ft > self.wc_v_ft:
            raise ValueError("volumes: the NMAC cylinder must lie inside the well-clear one")


@dataclass(frozen=True)
class Separation:
    """One run's separation from its intruders.

    Attributes
    ----------
    hmd_m, vmd_m : tuple of float
        Per intruder, at its closest approach.
    min_sep_m : float
        Least 3D distance minus the intruder's radius, over intruders and time.
    collision, nmac, lowc : bool
    cpa_t_s : tuple of float
        Time of each closest approach.
    """

    hmd_m: tuple
    vmd_m: tuple
    min_sep_m: float
    collision: bool
    nmac: bool
    lowc: bool
    cpa_t_s: tuple


def separation(t_s: np.ndarray, own_ned_m: np.ndarray, intruders, manned: bool, volumes: Volumes) -> Separation:
    """Separation of the track ``own_ned_m`` (K, 3) at ``t_s`` (K,) from ``intruders``."""
    hmd, vmd, cpa_t = [], [], []
    min_sep, collision, nmac, lowc = np.inf, False, False, False
    for track in intruders:
        rel = own_ned_m - track.position_at(t_s)
        dh = np.hypot(rel[:, 0], rel[:, 1])
        dv = np.abs(rel[:, 2])
        d3 = np.sqrt(dh * dh + dv * dv)
        k = int(np.argmin(d3))
        hmd.append(float(dh[k]))
        vmd.append(float(dv[k]))
        cpa_t.append(float(t_s[k]))
        min_sep = min(min_sep, float(d3[k]) - track.radius_m)
        collision |= bool(d3[k] < track.radius_m + volumes.collision_extra_m)
        if manned:
            nmac |= bool(np.any((dh < volumes.nmac_h_ft * FT_M) & (dv < volumes.nmac_v_ft * FT_M)))
            lowc |= bool(np.any((dh < volumes.wc_h_ft * FT_M) & (dv < volumes.wc_v_ft * FT_M)))
        else:
            nmac |= bool(d3[k] < track.radius_m + volumes.nmac_extra_m)
            lowc |= bool(d3[k] < track.radius_m + volumes.lowc_extra_m)
    return Separation(tuple(hmd), tuple(vmd), min_sep, collision, nmac, lowc, tuple(cpa_t))


def entries(own_ned_m: np.ndarray, obstacles: tuple, lo_ned_m, hi_ned_m) -> int:
    """How many times the track entered the bare ``obstacles`` (samples going from outside to
    inside any of them); 0 without obstacles."""
    if not obstacles:
        return 0
    world = World(list(obstacles), lo_ned_m, hi_ned_m)
    inside = world.clearance_m(own_ned_m) < 0.0
    return int(inside[0]) + int(np.count_nonzero(inside[1:] & ~inside[:-1]))


def path_length_m(own_ned_m: np.ndarray) -> float:
    """Length flown (m) along the samples (K, 3)."""
    return float(np.sum(np.linalg.norm(np.diff(own_ned_m, axis=0), axis=1)))
