"""What the companion hears of the intruders: reports, as they reach it in flight.

- *Drone-scale threats* arrive as the zenoh payload ``uav/<sysid>/threats/<id>`` carries them:
  each report is encoded (``threats.transport.codec.encode``) and decoded again on receipt
  (``codec.decode``), stamped with the receive time.
- *Manned traffic* arrives as ADSB_VEHICLE at 1 Hz: each report is packed into the MAVLink
  message (degE7, mm, cdeg, cm/s: the message's quantisation), unpacked, and turned into a
  threat by the companion's own conversion (``threats.transport.adsb.threat_from_adsb``).

A report measures the true position and velocity at its time, plus Gaussian noise
(``noise_pos_m``, ``noise_vel_m_s`` per axis), is sent every ``1 / update_hz`` seconds from
the intruder's first report to its last, is lost with probability ``dropout``, and is received
``latency_s`` later (the receiver stamps it then: its position is that much old).
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.campaign.tracks import IntruderTrack
from companion.threats.model import Threat
from companion.threats.transport import adsb, codec

__all__ = ["DEFAULT_DELIVERY", "feed_updates", "adsb_reports", "report_times", "adsb_fields", "MANNED_UPDATE_HZ"]

#: Drone-scale reports: 2 Hz, exact, on time (the robustness strata vary these).
DEFAULT_DELIVERY = {"noise_pos_m": 0.0, "noise_vel_m_s": 0.0, "update_hz": 2.0, "latency_s": 0.0, "dropout": 0.0}
MANNED_UPDATE_HZ = 1.0
#: A drone-scale threat not heard for this many report periods (at least TTL_MIN_S) expires.
TTL_PERIODS, TTL_MIN_S = 3.0, 3.0
_ADSB_FLAGS = (
    adsb.FLAG_COORDS | adsb.FLAG_ALTITUDE | adsb.FLAG_HEADING | adsb.FLAG_VELOCITY | adsb.FLAG_VERTICAL_VELOCITY
)


def report_times(track: IntruderTrack, update_hz: float) -> np.ndarray:
    """Times of the reports sent (K,): every ``1 / update_hz`` s from the first to the last."""
    period = 1.0 / update_hz
    n = int(math.floor((track.last_report_t_s - track.first_report_t_s) / period + 1e-9)) + 1
    return track.first_report_t_s + period * np.arange(max(n, 1))


def _measured(track: IntruderTrack, t: np.ndarray, delivery: dict, rng: np.random.Generator):
    pos = track.position_at(t)
    vel = np.zeros_like(pos) if track.popup else track.velocity_at(t)
    if delivery["noise_pos_m"] > 0:
        pos = pos + rng.normal(scale=delivery["noise_pos_m"], size=pos.shape)
    if delivery["noise_vel_m_s"] > 0 and not track.popup:
        vel = vel + rng.normal(scale=delivery["noise_vel_m_s"], size=vel.shape)
    return pos, vel


def _zenoh_threat(track: IntruderTrack, pos, vel, ttl_s: float, received_t_s: float) -> Threat:
    sent = Threat(
        track.id,
        "popup" if track.popup else "moving",
        "local_ned",
        tuple(float(x) for x in pos),
        (0.0, 0.0, 0.0) if track.popup else tuple(float(x) for x in vel),
        track.radius_m,
        ttl_s,
        0.0,
    )
    return codec.decode(codec.encode(sent), received_t_s=received_t_s, key_id=track.id)


def adsb_fields(track: IntruderTrack, pos_ned_m, vel_ned_m_s, home, link: mavlink.MAVLink) -> dict:
    """The fields of one ADSB_VEHICLE report, packed and unpacked (the wire's quantisation)."""
    lat, lon, alt = home.to_lla(pos_ned_m[0], pos_ned_m[1], pos_ned_m[2])
    vn, ve, vd = (float(x) for x in vel_ned_m_s)
    heading_cdeg = int(round(math.degrees(math.atan2(ve, vn)) * 100.0)) % 36000
    msg = mavlink.MAVLink_adsb_vehicle_message(
        track.icao_address,
        int(round(float(lat) * 1e7)),
        int(round(float(lon) * 1e7)),
        mavlink.ADSB_ALTITUDE_TYPE_GEOMETRIC,
        int(round(float(alt) * 1000.0)),
        heading_cdeg,
        min(int(round(math.hypot(vn, ve) * 100.0)), 65535),
        int(np.clip(round(-vd * 100.0), -32768, 32767)),
        f"N{track.icao_address % 100000:05d}".encode(),
        track.emitter_type,
        0,
        _ADSB_FLAGS,
        1200,
    )
    packed = msg.pack(link)
    return link.decode(bytearray(packed)).to_dict()


def _reports(track: IntruderTrack, update_hz: float, delivery: dict, rng: np.random.Generator):
    """(receive time, measured position, measured velocity) of each report of ``track`` that
    arrives, in time order (the draws: dropouts, then noise)."""
    t = report_times(track, update_hz)
    kept = rng.random(t.size) >= float(delivery["dropout"])
    kept[0] = True  # the first report is what makes it an encounter
    pos, vel = _measured(track, t, delivery, rng)
    return [(float(t[k] + delivery["latency_s"]), pos[k], vel[k]) for k in np.flatnonzero(kept)]


def adsb_reports(intruders, delivery: dict, rng: np.random.Generator, *, home) -> list[tuple[float, dict]]:
    """Manned traffic's ADSB_VEHICLE reports as received: (receive time, the message's fields
    packed and unpacked), in time order; the same draws as ``feed_updates`` (SITL sends these)."""
    link = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out = [
        (t, adsb_fields(track, pos, vel, home, link))
        for track in intruders
        for t, pos, vel in _reports(track, MANNED_UPDATE_HZ, delivery, rng)
    ]
    out.sort(key=lambda u: u[0])
    return out


def feed_updates(
    intruders, traffic: str, delivery: dict, rng: np.random.Generator, *, home=None, adsb_settings=None
) -> list[tuple[float, Threat, str]]:
    """The threat updates the companion receives: (receive time, Threat, id), in time order.

    Parameters
    ----------
    intruders : sequence of IntruderTrack
    traffic : str
        ``drone`` (zenoh payloads) or manned (``rotorcraft``, ``fixedwing``: ADSB_VEHICLE,
        ``adsb_reports`` turned into threats by the companion's ``threat_from_adsb``).
    delivery : dict
        ``noise_pos_m``, ``noise_vel_m_s``, ``update_hz``, ``latency_s``, ``dropout``.
    rng : numpy.random.Generator
    home : LocalFrame
        Needed for ADS-B (latitude and longitude about home).
    adsb_settings : AdsbSettings
        The companion's ``[adsb]`` settings (radius by emitter type, ttl).
    """
    if traffic != "drone":
        threats = (
            (t, adsb.threat_from_adsb(fields, adsb_settings, t, home))
            for t, fields in adsb_reports(intruders, delivery, rng, home=home)
        )
        return [(t, threat, threat.id) for t, threat in threats if threat is not None]
    ttl_s = max(TTL_PERIODS / float(delivery["update_hz"]), TTL_MIN_S)
    updates = [
        (t, _zenoh_threat(track, pos, vel, ttl_s, t), track.id)
        for track in intruders
        for t, pos, vel in _reports(track, float(delivery["update_hz"]), delivery, rng)
    ]
    updates.sort(key=lambda u: u[0])
    return updates
