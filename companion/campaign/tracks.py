"""Intruders' true tracks and an encounter: what flies against the helicopter, in mission time.

An intruder's track is its true position sampled in time (piecewise linear between samples,
held straight beyond the ends). What the companion hears of it (reports with noise, late or
lost) is ``companion.campaign.delivery``'s; how close it came is ``companion.campaign.judge``'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["IntruderTrack", "Encounter", "straight_track"]


@dataclass(frozen=True)
class IntruderTrack:
    """One intruder's true track.

    Attributes
    ----------
    id : str
        Its threat id (a zenoh key chunk), or the ``adsb-<ICAO>`` of manned traffic.
    t_s : ndarray, shape (K,)
        Mission times, increasing, K >= 2.
    pos_ned_m : ndarray, shape (K, 3)
        True positions, local NED metres.
    radius_m : float
        The threat sphere's bare radius (drone scale), or the emitter's radius (manned).
    first_report_t_s : float
        When the companion first hears of it (it is unknown before).
    last_report_t_s : float
        When the last report is sent (the threat is then left to expire).
    popup : bool
        A static pop-up (reported with ``kind = "popup"``).
    icao_address : int
        Manned traffic's ICAO address (0 for drone-scale).
    emitter_type : int
        ADSB_EMITTER_TYPE of manned traffic.
    """

    id: str
    t_s: np.ndarray
    pos_ned_m: np.ndarray
    radius_m: float
    first_report_t_s: float
    last_report_t_s: float
    popup: bool = False
    icao_address: int = 0
    emitter_type: int = 0

    def position_at(self, t_s) -> np.ndarray:
        """True positions at ``t_s`` (K,) -> (K, 3) (straight beyond the ends)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        ts, p = self.t_s, self.pos_ned_m
        out = np.empty((t.size, 3))
        for axis in range(3):
            out[:, axis] = np.interp(t, ts, p[:, axis])
        before, after = t < ts[0], t > ts[-1]
        if before.any():
            v0 = (p[1] - p[0]) / (ts[1] - ts[0])
            out[before] = p[0] + (t[before, None] - ts[0]) * v0
        if after.any():
            v1 = (p[-1] - p[-2]) / (ts[-1] - ts[-2])
            out[after] = p[-1] + (t[after, None] - ts[-1]) * v1
        return out

    @property
    def max_speed_m_s(self) -> float:
        """Its fastest segment's speed (m/s)."""
        step = np.linalg.norm(np.diff(self.pos_ned_m, axis=0), axis=1) / np.diff(self.t_s)
        return float(step.max())

    def velocity_at(self, t_s) -> np.ndarray:
        """True velocities at ``t_s`` (K,) -> (K, 3) (the segment's)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        seg = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, self.t_s.size - 2)
        dp = self.pos_ned_m[seg + 1] - self.pos_ned_m[seg]
        return dp / (self.t_s[seg + 1] - self.t_s[seg])[:, None]


def straight_track(
    threat_id: str,
    start_t_s: float,
    end_t_s: float,
    p0_ned_m,
    v_ned_m_s,
    radius_m: float,
    *,
    turn_t_s: float | None = None,
    v_after_ned_m_s=None,
    popup: bool = False,
) -> IntruderTrack:
    """A track at constant velocity from ``p0`` at ``start_t_s``, optionally changing to
    ``v_after`` at ``turn_t_s`` (an intruder that turns or climbs)."""
    p0 = np.asarray(p0_ned_m, dtype=float)
    v = np.asarray(v_ned_m_s, dtype=float)
    if turn_t_s is None or not (start_t_s < turn_t_s < end_t_s):
        t = np.array([start_t_s, end_t_s])
        pos = np.vstack([p0, p0 + v * (end_t_s - start_t_s)])
    else:
        p_turn = p0 + v * (turn_t_s - start_t_s)
        t = np.array([start_t_s, turn_t_s, end_t_s])
        pos = np.vstack([p0, p_turn, p_turn + np.asarray(v_after_ned_m_s, dtype=float) * (end_t_s - turn_t_s)])
    return IntruderTrack(threat_id, t, pos, float(radius_m), float(start_t_s), float(end_t_s), popup)


@dataclass(frozen=True)
class Encounter:
    """One encounter: intruders against one mission, and how they are heard.

    Attributes
    ----------
    id : int
    stratum : str
    mission : str
        The ``companion.campaign.missions`` mission flown.
    traffic : str
        ``drone``, ``rotorcraft`` or ``fixedwing``.
    intruders : tuple of IntruderTrack
    weight : float
        Importance weight back to the nominal distribution (1 for the parametric strata).
    end_t_s : float
        The flight ends here at the latest (mission time).
    delivery : dict
        ``noise_pos_m``, ``noise_vel_m_s``, ``update_hz``, ``latency_s``, ``dropout``.
    params : dict
        What was drawn (for the row: target miss distances, closest-approach time).
    """

    id: int
    stratum: str
    mission: str
    traffic: str
    intruders: tuple
    weight: float
    end_t_s: float
    delivery: dict
    params: dict = field(default_factory=dict)

    @property
    def first_report_t_s(self) -> float:
        return min(tr.first_report_t_s for tr in self.intruders)
