"""Traffic alerts (companion.threats.alerts, companion.flight.alerting): the predicted closest
approach, the threat levels in the campaign's volumes, the COLLISION message as AP_Avoidance fills
it, and the life of an alert (first told, repeated at the rate, the decision's action, cleared)."""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hyp_settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError
from companion.flight.alerting import TrafficAlerts
from companion.threats.alerts import (
    AlertSettings,
    Approach,
    alert_statustext,
    closest_approach,
    collision_action,
    collision_fields,
    collision_id,
)
from companion.threats.model import Threat
from companion.threats.snapshot import ThreatSnapshot, snapshot_from_dict, snapshot_to_dict
from companion.threats.transport import codec
from companion.threats.transport.adsb import AdsbSettings, emitter_traffic, threat_from_adsb

NONE, LOW, HIGH = (
    mavlink.MAV_COLLISION_THREAT_LEVEL_NONE,
    mavlink.MAV_COLLISION_THREAT_LEVEL_LOW,
    mavlink.MAV_COLLISION_THREAT_LEVEL_HIGH,
)
S = AlertSettings()
coords = st.floats(-200.0, 200.0)
speeds = st.floats(-30.0, 30.0)


def _tracks(p_own, v_own, p_thr, v_thr, n=121, step=0.25):
    t = np.arange(n)[:, None] * step
    return np.asarray(p_own) + t * np.asarray(v_own), np.asarray(p_thr) + t * np.asarray(v_thr)


# ---------------------------------------------------------------------------- the approach
@hyp_settings(max_examples=200, deadline=None)
@given(
    st.tuples(coords, coords, coords),
    st.tuples(speeds, speeds, speeds),
    st.tuples(coords, coords, coords),
    st.tuples(speeds, speeds, speeds),
)
def test_the_sampled_closest_approach_is_the_analytic_one_within_half_a_step(p_own, v_own, p_thr, v_thr):
    own, thr = _tracks(p_own, v_own, p_thr, v_thr)
    a = closest_approach(own, thr, 3.0, False, S, 0.25)
    dp, dv = np.subtract(p_thr, p_own), np.subtract(v_thr, v_own)
    t_star = float(np.clip(-dp @ dv / (dv @ dv), 0.0, 30.0)) if dv @ dv > 1e-12 else 0.0
    exact = float(np.linalg.norm(dp + dv * t_star))
    sampled = float(np.hypot(a.horizontal_m, a.vertical_m))
    assert exact - 1e-6 <= sampled <= exact + np.linalg.norm(dv) * 0.125 + 1e-6
    assert 0.0 <= a.time_to_cpa_s <= 30.0


@pytest.mark.parametrize(
    "h, v, level",
    [(500.0, 20.0, LOW), (100.0, 10.0, HIGH), (100.0, 100.0, NONE), (700.0, 0.0, NONE), (150.0, 31.0, LOW)],
)
def test_manned_traffic_is_judged_in_the_aviation_cylinders(h, v, level):
    own, thr = _tracks([0, 0, -50], [0, 0, 0], [h, 0, -50 - v], [0, 0, 0])
    assert closest_approach(own, thr, 25.0, True, S, 0.25).level == level


@pytest.mark.parametrize("d, level", [(5.0, LOW), (3.5, HIGH), (7.0, NONE), (2.0, HIGH)])
def test_drone_scale_threats_are_judged_in_spheres_beyond_their_radius(d, level):
    own, thr = _tracks([0, 0, -20], [0, 0, 0], [d * 0.6, 0, -20 + d * 0.8], [0, 0, 0])
    assert closest_approach(own, thr, 3.0, False, S, 0.25).level == level


def test_the_first_loss_of_well_clear_is_timed():
    own, thr = _tracks([0, 0, -20], [0, 0, 0], [40, 0, -20], [-2, 0, 0])  # inside 6 m at t = 17 s
    a = closest_approach(own, thr, 3.0, False, S, 0.25)
    assert a.time_to_lowc_s == pytest.approx(17.0, abs=0.26) and a.time_to_cpa_s == pytest.approx(20.0)
    assert a.level == HIGH and a.horizontal_m == pytest.approx(0.0)


# ---------------------------------------------------------------------------- the messages
@pytest.mark.parametrize(
    "kind, label, action",
    [
        ("evade", "evade climb", mavlink.MAV_COLLISION_ACTION_ASCEND_OR_DESCEND),
        ("evade", "evade descend (refined)", mavlink.MAV_COLLISION_ACTION_ASCEND_OR_DESCEND),
        ("evade", "evade brake", mavlink.MAV_COLLISION_ACTION_HOVER),
        ("evade", "evade left + climb", mavlink.MAV_COLLISION_ACTION_MOVE_PERPENDICULAR),
        ("hold", "hold (brake to a hover)", mavlink.MAV_COLLISION_ACTION_HOVER),
        ("retime", "retime wait 3 s", mavlink.MAV_COLLISION_ACTION_HOVER),
        ("switch", "switch alt1", mavlink.MAV_COLLISION_ACTION_MOVE_HORIZONTALLY),
        ("replan", "replan", mavlink.MAV_COLLISION_ACTION_MOVE_HORIZONTALLY),
        ("none", "", mavlink.MAV_COLLISION_ACTION_REPORT),
    ],
)
def test_each_decision_has_its_collision_action(kind, label, action):
    assert collision_action(kind, label) == action


def test_collision_ids_follow_the_source():
    assert collision_id("adsb-a01b2c") == (mavlink.MAV_COLLISION_SRC_ADSB, 0xA01B2C)
    assert collision_id("uav3-pending") == (mavlink.MAV_COLLISION_SRC_MAVLINK_GPS_GLOBAL_INT, 3)
    assert collision_id("mover1") == (mavlink.MAV_COLLISION_SRC_MAVLINK_GPS_GLOBAL_INT, zlib.crc32(b"mover1"))
    assert collision_id("adsb-zz")[1] == zlib.crc32(b"adsb-zz")


def test_the_collision_fields_pack_as_mavlink_collision():
    a = Approach(12.5, 150.0, 20.0, 9.0, LOW)
    fields = collision_fields("adsb-a00001", a, mavlink.MAV_COLLISION_ACTION_HOVER)
    msg = mavlink.MAVLink_collision_message(**fields)
    back = mavlink.MAVLink(None).decode(bytearray(msg.pack(mavlink.MAVLink(None, 1, 191))))
    assert (back.src, back.id, back.action, back.threat_level) == (0, 0xA00001, 6, LOW)
    assert (back.time_to_minimum_delta, back.horizontal_minimum_delta, back.altitude_minimum_delta) == (12.5, 150, 20)


@given(
    st.text("abcdefghijklmnopqrstuvwxyz0123456789-_./", min_size=1, max_size=140), st.sampled_from([NONE, LOW, HIGH])
)
def test_an_alerts_statustext_fits_one_message(threat_id, level):
    text, severity = alert_statustext(threat_id, Approach(3.2, 1234.0, 56.0, 2.0, level))
    assert len(text) <= 50 and text.startswith("TRAFFIC")
    assert severity == {NONE: "INFO", LOW: "WARNING", HIGH: "CRITICAL"}[level]


@pytest.mark.parametrize(
    "key, value, named",
    [
        ("horizon_s", 0.0, "alerts.horizon_s"),
        ("rate_hz", -1.0, "alerts.rate_hz"),
        ("drone_nmac_extra_m", 5.0, "drone_nmac_extra_m"),
        ("manned_nmac_h_m", 1000.0, "NMAC cylinder"),
        ("step_s", 40.0, "alerts.step_s"),
    ],
)
def test_bad_alert_settings_are_named(key, value, named):
    with pytest.raises(ConfigError, match=named):
        AlertSettings(**{key: value})


# ---------------------------------------------------------------------------- traffic kinds
def test_adsb_reports_of_manned_aircraft_are_manned_traffic():
    assert emitter_traffic(mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT) == "manned"
    assert emitter_traffic(mavlink.ADSB_EMITTER_TYPE_NO_INFO) == "manned"
    assert emitter_traffic(mavlink.ADSB_EMITTER_TYPE_UAV) == "drone"
    fields = {
        "ICAO_address": 0xA00001,
        "lat": 473977420,
        "lon": 85455940,
        "altitude": 600000,
        "heading": 9000,
        "hor_velocity": 5000,
        "ver_velocity": 0,
        "emitter_type": mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT,
        "tslc": 1,
        "flags": 0x1F,
    }
    assert threat_from_adsb(fields, AdsbSettings(), 10.0).traffic == "manned"


def test_the_traffic_kind_crosses_zenoh_and_the_snapshot():
    manned = Threat(
        "adsb-a00001", "moving", "local_ned", (1.0, 2.0, -50.0), (50.0, 0.0, 0.0), 25.0, 5.0, traffic="manned"
    )
    assert codec.decode(codec.encode(manned), received_t_s=0.0).traffic == "manned"
    assert "traffic" not in codec.to_dict(dataclasses.replace(manned, traffic="drone"))
    back = snapshot_from_dict(snapshot_to_dict(ThreatSnapshot(1, 0.0, 0.0, None, (manned,))))
    assert back.threats[0].traffic == "manned"
    bad = codec.encode(manned).replace(b'"manned"', b'"bird"')
    with pytest.raises(Exception, match="^traffic"):
        codec.decode(bad, received_t_s=0.0)


# ---------------------------------------------------------------------------- the owner
class Hover:
    """The vehicle holds at (0, 0, -20)."""

    duration_s = 1.0

    def sample(self, t):
        t = np.atleast_1d(t)
        pos = np.tile([0.0, 0.0, -20.0], (len(t), 1))
        return pos, np.zeros_like(pos), np.zeros_like(pos)


@dataclasses.dataclass
class Ref:
    trajectory: object
    t0_s: float = 0.0


class Sink:
    def __init__(self):
        self.alerts = []

    def alert(self, alert):
        self.alerts.append(alert)


@dataclasses.dataclass(frozen=True)
class Told:
    kind: str
    label: str
    conflict: object


@dataclasses.dataclass(frozen=True)
class Conflict:
    threat_id: str


def _board(threats: dict, clock: list):
    sink = Sink()
    board = TrafficAlerts(
        S,
        threats=lambda t: tuple(threats.values()),
        reference=lambda: Ref(Hover()),
        own_down_m=lambda: -20.0,
        now_s=lambda: clock[0],
        sink=sink,
    )
    return board, sink


def test_an_alert_is_told_once_repeated_at_its_rate_then_cleared_for_five_seconds():
    clock = [0.0]
    mover = Threat("m1", "moving", "local_ned", (40.0, 0.0, -20.0), (-2.0, 0.0, 0.0), 3.0, None, 0.0)
    threats = {"m1": mover}
    board, sink = _board(threats, clock)
    board.check()
    first = sink.alerts[-1]
    assert first.statustext[1] == "CRITICAL" and first.action == mavlink.MAV_COLLISION_ACTION_REPORT
    assert first.collision["threat_level"] == HIGH and first.collision["time_to_minimum_delta"] == pytest.approx(20.0)
    clock[0] = 0.4
    board.check()
    assert len(sink.alerts) == 1, "repeated faster than alerts.rate_hz"
    clock[0] = 1.0
    board.check()
    assert len(sink.alerts) == 2 and sink.alerts[-1].statustext is None
    board.decided(Told("evade", "evade left", Conflict("m1")))
    assert sink.alerts[-1].action == mavlink.MAV_COLLISION_ACTION_MOVE_PERPENDICULAR
    threats["m1"] = dataclasses.replace(mover, velocity_ned_m_s=(2.0, 0.0, 0.0))  # it turns away
    clock[0] = 2.0
    board.check()
    cleared = sink.alerts[-1]
    assert cleared.statustext == ("TRAFFIC m1 clear", "INFO") and cleared.collision["threat_level"] == NONE
    assert cleared.action == mavlink.MAV_COLLISION_ACTION_MOVE_PERPENDICULAR
    for t in (3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0):
        clock[0] = t
        board.check()
    nones = [a for a in sink.alerts if a.t_s > 2.0]
    assert len(nones) == 5 and all(a.collision["threat_level"] == NONE for a in nones)
    assert "m1" not in board.told


def test_a_threat_that_disappears_is_cleared_and_a_raised_level_is_told_again():
    clock = [0.0]
    far = Threat("m2", "moving", "local_ned", (60.0, 4.5, -20.0), (-2.0, 0.0, 0.0), 3.0, None, 0.0)
    threats = {"m2": far}
    board, sink = _board(threats, clock)
    board.check()
    assert sink.alerts[-1].statustext[1] == "WARNING"  # passes 4.5 m from the centre: LoWC only
    threats["m2"] = dataclasses.replace(far, position=(60.0, 0.0, -20.0))
    clock[0] = 0.1
    board.check()
    assert sink.alerts[-1].statustext[1] == "CRITICAL", "a raised level is told at once"
    threats.clear()
    clock[0] = 0.2
    board.check()
    assert sink.alerts[-1].statustext == ("TRAFFIC m2 clear", "INFO")


def test_a_decision_on_a_threat_not_yet_alerted_alerts_it_at_low():
    clock = [0.0]
    near = Threat("p1", "popup", "local_ned", (0.0, 8.0, -20.0), (0.0, 0.0, 0.0), 3.0, None, 0.0)
    board, sink = _board({"p1": near}, clock)
    board.check()
    assert sink.alerts == []  # 5 m beyond its radius: well clear
    board.decided(Told("hold", "hold (brake to a hover)", Conflict("p1")))
    assert sink.alerts[-1].collision["threat_level"] == LOW
    assert sink.alerts[-1].action == mavlink.MAV_COLLISION_ACTION_HOVER and sink.alerts[-1].statustext
    board.decided(Told("replan", "replan", Conflict("static")))
    assert len(sink.alerts) == 1, "the static world is not traffic"
