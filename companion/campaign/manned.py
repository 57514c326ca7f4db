"""Manned traffic against the helicopter: MIT LL model tracks paired with its own mission.

An intruder's track is sampled from an uncorrelated encounter model
(``companion.campaign.traffic_model``: rotorcraft or fixed-wing single engine, OpenSky-based) for
``before_s + after_s`` seconds. It is placed so that, ``before_s`` into the track, it is at the
closest approach to the helicopter's unmitigated flight: horizontally ``hmd`` away, across the
relative velocity, and ``vmd`` above (negative: below). ``hmd`` and ``vmd`` are importance-sampled
(``MannedSpec``) with the weight back to the nominal distribution; the intruder never flies
below ``min_agl_m``. It is heard as ADSB_VEHICLE at 1 Hz from the track's start (within the
companion's ADS-B range) to its end, with its emitter type's radius; the helicopter's flights
go on to the mission's end.
"""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.campaign.parametric import OwnFlight
from companion.campaign.tracks import Encounter, IntruderTrack
from companion.campaign.traffic_track import sample_track
from companion.threats.transport.adsb import emitter_radius_m

__all__ = ["EMITTERS", "miss_weight", "draw_miss", "make_manned"]

EMITTERS = {"rotorcraft": mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT, "fixedwing": mavlink.ADSB_EMITTER_TYPE_LIGHT}
ICAO_BASE = 0xA00000
#: The flights go on this long after the unmitigated one ended, so that the mission is flown to
#: its end: a climb or descent out of a manned aircraft's well clear and the way back take a
#: minute or more.
FLY_ON_S = 120.0


def _vmd_range(spec, own_alt_m: float) -> tuple[float, float]:
    return max(-spec.vmd_max_m, spec.min_agl_m - own_alt_m), spec.vmd_max_m


def miss_weight(hmd_m: float, vmd_m: float, spec, own_alt_m: float) -> float:
    """Nominal / proposal density of the miss distances (``MannedSpec``)."""
    s, H, Hn = spec.near_share, spec.hmd_max_m, spec.hmd_near_m
    v_lo, V = _vmd_range(spec, own_alt_m)
    vn_lo, Vn = max(-spec.vmd_near_m, v_lo), spec.vmd_near_m
    p = (2.0 * hmd_m / H**2) * (1.0 / (V - v_lo))
    q_h = s * (hmd_m <= Hn) / Hn + (1.0 - s) / H
    q_v = s * (vn_lo <= vmd_m <= Vn) / (Vn - vn_lo) + (1.0 - s) / (V - v_lo)
    return float(p / (q_h * q_v))


def draw_miss(spec, own_alt_m: float, rng: np.random.Generator) -> tuple[float, float, float]:
    """(hmd, vmd, weight) from the proposal."""
    v_lo, V = _vmd_range(spec, own_alt_m)
    hmd = rng.uniform(0.0, spec.hmd_near_m) if rng.random() < spec.near_share else rng.uniform(0.0, spec.hmd_max_m)
    if rng.random() < spec.near_share:
        vmd = rng.uniform(max(-spec.vmd_near_m, v_lo), spec.vmd_near_m)
    else:
        vmd = rng.uniform(v_lo, V)
    return float(hmd), float(vmd), miss_weight(hmd, vmd, spec, own_alt_m)


def make_manned(
    index: int, stratum: str, model_kind: str, model, own: OwnFlight, spec, adsb_settings, rng: np.random.Generator
) -> Encounter:
    """Encounter ``index`` with one manned intruder of ``model`` (an ``EncounterModel``)."""
    duration = spec.before_s + spec.after_s
    track = sample_track(model, rng, duration_s=duration)
    ned = np.column_stack([track.pos_neu_m[:, 0], track.pos_neu_m[:, 1], -track.pos_neu_m[:, 2]])
    t_cpa = float(rng.uniform(min(spec.before_s, own.end_t_s - 10.0), own.end_t_s - 10.0))
    p_own, v_own = own.at(t_cpa)
    k_cpa = int(np.searchsorted(track.t_s, spec.before_s))
    v_int = np.array([track.vel_neu_m_s[k_cpa, 0], track.vel_neu_m_s[k_cpa, 1], 0.0])
    v_rel = v_int - np.array([v_own[0], v_own[1], 0.0])
    across = np.array([-v_rel[1], v_rel[0], 0.0])
    norm = float(np.linalg.norm(across))
    across = across / norm if norm > 1e-6 else np.array([0.0, 1.0, 0.0])
    hmd, vmd, weight = draw_miss(spec, -float(p_own[2]), rng)
    target = p_own + across * hmd * rng.choice([-1.0, 1.0]) + np.array([0.0, 0.0, -vmd])
    pos = ned - ned[k_cpa] + target
    pos[:, 2] = np.minimum(pos[:, 2], -spec.min_agl_m)
    t = t_cpa - spec.before_s + track.t_s
    emitter = EMITTERS[model_kind]
    intruder = IntruderTrack(
        f"adsb-{ICAO_BASE + index % 0x100000:06x}",
        t,
        pos,
        emitter_radius_m(emitter, adsb_settings),
        float(t[0]),
        float(t[-1]),
        icao_address=ICAO_BASE + index % 0x100000,
        emitter_type=int(emitter),
    )
    speed = float(np.hypot(*track.vel_neu_m_s[k_cpa, :2]))
    params = {
        "t_cpa_s": t_cpa,
        "hmd_target_m": hmd,
        "vmd_target_m": vmd,
        "intruder_speed_m_s": speed,
        "t_report_s": float(t[0]),
    }
    return Encounter(
        index,
        stratum,
        "long",
        model_kind,
        (intruder,),
        weight,
        own.end_t_s + FLY_ON_S,
        {"noise_pos_m": 0.0, "noise_vel_m_s": 0.0, "update_hz": 1.0, "latency_s": 0.0, "dropout": 0.0},
        params,
    )
