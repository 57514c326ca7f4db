"""From encounter-model bins to one aircraft's track (the reference's ``dediscretize.m``,
``resample_events.m`` and ``sample2track.m``).

A bin becomes a value drawn uniformly inside its edges, the outer bins between the outermost
edges, and the bin straddling zero (v-dot in [-0.25, 0.25] kt/s, h-dot in [-250, 250] ft/min,
psi-dot in [-1.5, 1.5] deg/s) exactly 0, as ``dediscretize.m`` does with ``em_read.m``'s zero
bins; a zero-width bin gives its edge. A dynamic variable's value is drawn anew when its bin
changes and, while it stays, with the model's resample rate per second; otherwise it is held.
The track is integrated once a second by forward Euler from the previous point's values, as
``sample2track.m`` does: speed by v-dot, heading by psi-dot, altitude by h-dot, position by the
speed along the heading. Like the reference, a track leaving the model's bounds (altitude
outside the L edges, 50-5000 ft AGL; speed not strictly inside the v edges, 0-300 kt) or
starting with a vertical rate above its airspeed is rejected and drawn again; nothing is
clamped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from companion.campaign.traffic_model import EncounterModel, TrafficModelError, sample_dynamic, sample_initial

__all__ = [
    "KT_TO_M_S",
    "FT_TO_M",
    "FT_MIN_TO_M_S",
    "TrafficTrack",
    "dediscretize",
    "resample_mask",
    "dynamic_values",
    "integrate",
    "sample_track",
]

KT_TO_M_S = 1852.0 / 3600.0  # 0.514444 m/s per knot
FT_TO_M = 0.3048
FT_MIN_TO_M_S = FT_TO_M / 60.0
_LABELS = {"layer": "L", "speed": "v", "accel": "\\dot v", "climb": "\\dot h", "turn": "\\dot \\psi"}


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity
class TrafficTrack:
    """One aircraft's sampled track, K points ``dt`` apart.

    Attributes
    ----------
    t_s : (K,) float array
        Time from the start, s.
    pos_neu_m : (K, 3) float array
        North, east, up from the start point, m.
    vel_neu_m_s : (K, 3) float array
        Velocity at each point, m/s (the Euler step: ``pos[k+1] = pos[k] + vel[k] * dt``).
    speed_kt, heading_deg, altitude_ft_agl : (K,) float arrays
        Airspeed (kt), heading clockwise from north in [0, 360) deg, height above ground (ft).
    domain, airspace, layer : int
        The initial G, A and L as the model codes them (1-based: G 1 mainland USA ... 5
        Canada; A 1 class B, 2 C, 3 D, 4 other; L 1 for 50-500 ft AGL ... 4 for 3000-5000).
    attempts : int
        Samples drawn until one stayed inside the bounds (1 = the first).
    """

    t_s: np.ndarray
    pos_neu_m: np.ndarray
    vel_neu_m_s: np.ndarray
    speed_kt: np.ndarray
    heading_deg: np.ndarray
    altitude_ft_agl: np.ndarray
    domain: int
    airspace: int
    layer: int
    attempts: int


def dediscretize(
    bins: ArrayLike, edges: np.ndarray | None, rng: np.random.Generator, *, zero_bin: bool = True
) -> np.ndarray:
    """Values drawn uniformly inside their bins.

    Parameters
    ----------
    bins : int array_like, any shape
        0-based bins, ``0 <= bins < edges.size - 1``.
    edges : (r + 1,) float array or None
        Non-decreasing bin edges; None (a discrete variable) gives the 1-based codes back.
    rng : numpy.random.Generator
    zero_bin : bool
        Give exactly 0 in the bin whose lower edge is < 0 and upper edge > 0.

    Returns
    -------
    float array, the shape of ``bins``
    """
    bins = np.asarray(bins, dtype=np.intp)
    if edges is None:
        return bins + 1.0
    if np.any((bins < 0) | (bins >= edges.size - 1)):
        raise TrafficModelError(f"bins outside 0..{edges.size - 2}")
    low, high = edges[bins], edges[bins + 1]
    values = low + (high - low) * rng.random(bins.shape)
    if zero_bin:
        values = np.where((low < 0) & (high > 0), 0.0, values)
    return values


def resample_mask(bins: np.ndarray, rates: ArrayLike, rng: np.random.Generator) -> np.ndarray:
    """Where a dynamic variable's value is drawn anew: row 0, a changed bin, or a resample.

    Parameters
    ----------
    bins : (T, d) int array
        Bins each second (:func:`~companion.campaign.traffic_model.sample_dynamic`).
    rates : (d,) float array_like
        Probability per second of a new draw inside an unchanged bin.

    Returns
    -------
    (T, d) bool array
    """
    mask = rng.random(bins.shape) < np.asarray(rates)
    mask[0] = True
    mask[1:] |= bins[1:] != bins[:-1]
    return mask


def dynamic_values(model: EncounterModel, bins: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(T, d) values of the dynamic variables in the model's units, held between new draws."""
    mask = resample_mask(bins, model.resample_rates[list(model.dynamic)], rng)
    values = np.empty(bins.shape)
    for k, i in enumerate(model.dynamic):
        fresh = dediscretize(bins[:, k], model.boundaries[i], rng)
        last_draw = np.maximum.accumulate(np.where(mask[:, k], np.arange(bins.shape[0]), 0))
        values[:, k] = fresh[last_draw]
    return values


def _steps(duration_s: float, dt_s: float) -> tuple[int, int]:
    """Whole seconds and integration steps per second."""
    seconds, per_second = int(round(duration_s)), int(round(1.0 / dt_s)) if dt_s > 0 else 0
    if seconds < 1 or abs(seconds - duration_s) > 1e-9:
        raise TrafficModelError(f"duration_s must be a whole number of seconds >= 1, got {duration_s}")
    if per_second < 1 or abs(per_second * dt_s - 1.0) > 1e-9:
        raise TrafficModelError(f"dt_s must divide 1 s (1, 0.5, 0.1, ...), got {dt_s}")
    return seconds, per_second


def _prefix_sum(rate: np.ndarray, dt_s: float) -> np.ndarray:
    """``x[k] - x[0]`` under forward Euler: the sum of ``rate[m] * dt`` over ``m < k``."""
    return np.concatenate([[0.0], np.cumsum(rate[:-1] * dt_s)])


def integrate(
    speed0_kt: float, altitude0_ft: float, heading0_deg: float, rates: np.ndarray, dt_s: float
) -> tuple[np.ndarray, ...]:
    """Forward Euler of ``sample2track.m``.

    Parameters
    ----------
    rates : (K, 3) float array
        v-dot (kt/s), h-dot (ft/min), psi-dot (deg/s) at each point.

    Returns
    -------
    speed_kt, heading_deg (unwrapped), altitude_ft, pos_neu_m (K, 3), vel_neu_m_s (K, 3)
    """
    speed_kt = speed0_kt + _prefix_sum(rates[:, 0], dt_s)
    heading_deg = heading0_deg + _prefix_sum(rates[:, 2], dt_s)
    climb_m_s = rates[:, 1] * FT_MIN_TO_M_S
    altitude_ft = altitude0_ft + _prefix_sum(rates[:, 1] / 60.0, dt_s)
    heading_rad = np.radians(heading_deg)
    vel = np.column_stack(
        [speed_kt * KT_TO_M_S * np.cos(heading_rad), speed_kt * KT_TO_M_S * np.sin(heading_rad), climb_m_s]
    )
    pos = np.column_stack(
        [_prefix_sum(vel[:, 0], dt_s), _prefix_sum(vel[:, 1], dt_s), (altitude_ft - altitude0_ft) * FT_TO_M]
    )
    return speed_kt, heading_deg, altitude_ft, pos, vel


def _wrap_deg(angle_deg: np.ndarray) -> np.ndarray:
    """Angles in [0, 360) (``%`` alone can give 360.0 for a tiny negative angle)."""
    wrapped = np.mod(angle_deg, 360.0)
    return np.where(wrapped >= 360.0, 0.0, wrapped)


def _inside(model: EncounterModel, speed_kt: np.ndarray, altitude_ft: np.ndarray) -> bool:
    alt_edges = model.boundaries[model.index(_LABELS["layer"])]
    speed_edges = model.boundaries[model.index(_LABELS["speed"])]
    return bool(
        np.all((altitude_ft >= alt_edges[0]) & (altitude_ft <= alt_edges[-1]))
        and np.all((speed_kt > speed_edges[0]) & (speed_kt < speed_edges[-1]))
    )


def sample_track(
    model: EncounterModel,
    rng: np.random.Generator,
    duration_s: float = 120.0,
    dt_s: float = 1.0,
    heading0_deg: float | None = None,
    *,
    max_attempts: int = 1000,
    prior: float = 0.0,
) -> TrafficTrack:
    """Sample one aircraft's track from the model.

    Parameters
    ----------
    model : EncounterModel
        With the variables L, v, v-dot, h-dot and psi-dot (the uncorrelated models).
    rng : numpy.random.Generator
        The only source of randomness (a fixed seed gives the same track).
    duration_s : float
        Whole seconds; the track has ``duration_s / dt_s + 1`` points.
    dt_s : float
        Integration step dividing 1 s; the model's values are held over each second.
    heading0_deg : float, optional
        Initial heading; uniform in [0, 360) when None.
    max_attempts : int
        Samples drawn before giving up on one inside the bounds.
    prior : float
        Dirichlet prior on the counts (the reference's default: 0).

    Raises
    ------
    TrafficModelError
        Bad ``duration_s`` / ``dt_s``, a model without those variables, or no track inside the
        bounds in ``max_attempts`` samples.
    """
    seconds, per_second = _steps(duration_s, dt_s)
    idx = {key: model.index(label) for key, label in _LABELS.items()}
    if [idx["accel"], idx["climb"], idx["turn"]] != list(model.dynamic):
        raise TrafficModelError(f"model {model.name}: dynamic variables {model.dynamic} are not v-dot, h-dot, psi-dot")
    heading0 = rng.uniform(0.0, 360.0) if heading0_deg is None else float(heading0_deg)
    for attempt in range(1, max_attempts + 1):
        initial = sample_initial(model, rng, prior=prior)
        altitude0_ft = float(dediscretize(initial[idx["layer"]], model.boundaries[idx["layer"]], rng))
        speed0_kt = float(dediscretize(initial[idx["speed"]], model.boundaries[idx["speed"]], rng))
        per_s = dynamic_values(model, sample_dynamic(model, initial, seconds + 1, rng, prior=prior), rng)
        if speed0_kt * KT_TO_M_S <= abs(per_s[0, 1]) * FT_MIN_TO_M_S:
            continue  # climbing faster than flying
        rates = np.repeat(per_s, per_second, axis=0)[: seconds * per_second + 1]
        speed_kt, heading_deg, altitude_ft, pos, vel = integrate(speed0_kt, altitude0_ft, heading0, rates, dt_s)
        if _inside(model, speed_kt, altitude_ft):
            codes = [int(initial[model.index(label)]) + 1 for label in ("G", "A", "L")]
            return TrafficTrack(
                np.arange(rates.shape[0]) * dt_s,
                pos,
                vel,
                speed_kt,
                _wrap_deg(heading_deg),
                altitude_ft,
                *codes,
                attempts=attempt,
            )
    raise TrafficModelError(
        f"model {model.name}: no {duration_s:g} s track inside the bounds (altitude in the "
        f"L edges, speed inside the v edges) in {max_attempts} samples"
    )
