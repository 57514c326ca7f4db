"""companion.threats.transport.adsb: ADSB_VEHICLE reports as moving threats."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.config import load_settings
from companion.errors import ConfigError
from companion.geo import LocalFrame
from companion.threats.model import ThreatTable
from companion.threats.transport import codec
from companion.threats.transport.adsb import AdsbSettings, adsb_threat_id, emitter_radius_m, threat_from_adsb

HOME = LocalFrame(47.397742, 8.545594, 488.0)
ALL_VALID = 511  # every flag ArduPilot's SITL sets (not SOURCE_UAT)


def report(**changes) -> dict:
    """An ADSB_VEHICLE as the SITL sends it (fields as MavlinkDirect decodes them)."""
    lat, lon, alt = HOME.to_lla(100.0, 0.0, -50.0)
    out = {
        "ICAO_address": 0x4B1805,
        "lat": int(round(float(lat) * 1e7)),
        "lon": int(round(float(lon) * 1e7)),
        "altitude_type": 0,
        "altitude": int(round(float(alt) * 1000)),
        "heading": 9000,
        "hor_velocity": 2000,
        "ver_velocity": -300,
        "callsign": "SIM1",
        "emitter_type": 1,
        "tslc": 1,
        "flags": ALL_VALID,
        "squawk": 1200,
    }
    out.update(changes)
    return out


def test_a_report_becomes_a_global_moving_threat_with_its_velocity():
    threat = threat_from_adsb(report(), AdsbSettings(), now_t_s=50.0, home=HOME)
    assert threat.id == "adsb-4b1805" and threat.kind == "moving" and threat.frame == "global"
    vn, ve, vd = threat.velocity_ned_m_s
    assert vn == pytest.approx(0.0, abs=1e-9) and ve == pytest.approx(20.0) and vd == pytest.approx(3.0)
    assert threat.ttl_s == 5.0 and threat.received_t_s == 49.0  # tslc 1 s before receipt
    assert threat.radius_m == 20.0  # light aircraft
    local = threat.to_local(HOME)
    assert local.pos_ned_m == pytest.approx([100.0, 0.0, -50.0], abs=0.05)
    assert codec.decode(codec.encode(threat), received_t_s=0.0).id == threat.id  # republishable


def test_heading_is_the_course_over_ground():
    threat = threat_from_adsb(
        report(heading=22500, hor_velocity=1000, flags=ALL_VALID & ~mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID),
        AdsbSettings(),
        0.0,
    )
    vn, ve, vd = threat.velocity_ned_m_s
    assert vn == pytest.approx(-10 / math.sqrt(2)) and ve == pytest.approx(-10 / math.sqrt(2)) and vd == 0.0


def test_fields_are_used_only_when_flagged_valid():
    assert threat_from_adsb(report(flags=ALL_VALID & ~mavlink.ADSB_FLAGS_VALID_COORDS), AdsbSettings(), 0.0) is None
    assert threat_from_adsb(report(flags=ALL_VALID & ~mavlink.ADSB_FLAGS_VALID_ALTITUDE), AdsbSettings(), 0.0) is None
    still = threat_from_adsb(
        report(flags=mavlink.ADSB_FLAGS_VALID_COORDS | mavlink.ADSB_FLAGS_VALID_ALTITUDE), AdsbSettings(), 0.0
    )
    assert still.velocity_ned_m_s == (0.0, 0.0, 0.0)


def test_far_traffic_is_ignored():
    lat, lon, alt = HOME.to_lla(6000.0, 0.0, -300.0)
    far = report(lat=int(float(lat) * 1e7), lon=int(float(lon) * 1e7), altitude=int(float(alt) * 1000))
    assert threat_from_adsb(far, AdsbSettings(), 0.0, home=HOME) is None
    assert threat_from_adsb(far, AdsbSettings(max_range_m=10_000.0), 0.0, home=HOME) is not None


def test_radius_by_emitter_type():
    s = AdsbSettings()
    assert emitter_radius_m(mavlink.ADSB_EMITTER_TYPE_HEAVY, s) == s.radius_large_m
    assert emitter_radius_m(mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT, s) == s.radius_rotorcraft_m
    assert emitter_radius_m(mavlink.ADSB_EMITTER_TYPE_UAV, s) == s.radius_uav_m
    assert emitter_radius_m(mavlink.ADSB_EMITTER_TYPE_POINT_OBSTACLE, s) == s.radius_surface_m
    assert emitter_radius_m(mavlink.ADSB_EMITTER_TYPE_NO_INFO, s) == s.radius_m
    assert adsb_threat_id(2556) == "adsb-0009fc"


def test_each_report_refreshes_the_same_threat_in_the_table():
    table = ThreatTable(HOME)
    table.put(threat_from_adsb(report(), AdsbSettings(), now_t_s=10.0))  # stamped 9 (tslc 1 s)
    assert table.expire(13.5) == []
    table.put(threat_from_adsb(report(), AdsbSettings(), now_t_s=13.6))  # refreshed: one threat
    assert len(table) == 1 and table.expire(17.5) == []
    assert table.expire(17.7) == ["adsb-4b1805"]


def test_settings_are_validated_and_in_the_tree():
    with pytest.raises(ConfigError, match="adsb.ttl_s"):
        load_settings(None, {"adsb": {"ttl_s": 0}})
    assert load_settings(None, {"adsb": {"enabled": True}}).adsb.enabled
