"""What the companion hears of the intruders (``companion.campaign.delivery``): drone-scale zenoh
payloads and manned traffic's ADSB_VEHICLE, against the true tracks.

Everything random has a fixed seed; the statistical checks allow 5 standard errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.campaign.delivery import (
    DEFAULT_DELIVERY,
    MANNED_UPDATE_HZ,
    TTL_MIN_S,
    TTL_PERIODS,
    adsb_fields,
    feed_updates,
    report_times,
)
from companion.campaign.tracks import IntruderTrack, straight_track
from companion.threats.model import Threat, ThreatTable
from companion.threats.transport.adsb import AdsbSettings, emitter_radius_m
from heli_common.frames import LocalFrame

HOME = LocalFrame(-35.363261, 149.165230, 584.0)
ADSB = AdsbSettings()
ICAO = 0xA0002A
ROTORCRAFT = mavlink.ADSB_EMITTER_TYPE_ROTOCRAFT


def delivery(**changes) -> dict:
    out = dict(DEFAULT_DELIVERY)
    out.update(changes)
    return out


def crossing(tid: str = "t0", start_s: float = 3.0, end_s: float = 23.0, *, popup: bool = False) -> IntruderTrack:
    v = (0.0, 0.0, 0.0) if popup else (1.5, -4.0, 0.5)
    return straight_track(tid, start_s, end_s, (40.0, 30.0, -22.0), v, 3.5, popup=popup)


def turning(tid: str = "t1") -> IntruderTrack:
    return straight_track(
        tid, 1.0, 21.0, (10.0, -20.0, -20.0), (0.0, 5.0, 0.0), 4.0, turn_t_s=6.3, v_after_ned_m_s=(3.0, 4.0, -1.0)
    )


def manned_track(
    p0=(800.0, -600.0, -150.0), v=(-35.0, 20.0, 1.2), start_s: float = 10.0, end_s: float = 80.0
) -> IntruderTrack:
    base = straight_track("x", start_s, end_s, p0, v, 25.0)
    return IntruderTrack(
        f"adsb-{ICAO:06x}",
        base.t_s,
        base.pos_ned_m,
        emitter_radius_m(ROTORCRAFT, ADSB),
        start_s,
        end_s,
        icao_address=ICAO,
        emitter_type=int(ROTORCRAFT),
    )


def feed(tracks, traffic="drone", seed=0, **changes):
    return feed_updates(
        tracks, traffic, delivery(**changes), np.random.default_rng(seed), home=HOME, adsb_settings=ADSB
    )


# ---------------------------------------------------------------------------------------------
# drone scale
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("popup", [False, True])
def test_drone_updates_decode_to_the_true_threat(popup):
    track = crossing(popup=popup)
    updates = feed([track])
    times = report_times(track, DEFAULT_DELIVERY["update_hz"])
    assert [u[0] for u in updates] == pytest.approx(times.tolist(), abs=0)
    for received, threat, tid in updates:
        assert isinstance(threat, Threat)
        assert tid == threat.id == track.id
        assert threat.kind == ("popup" if popup else "moving")
        assert threat.frame == "local_ned"
        assert threat.received_t_s == received
        assert threat.radius_m == track.radius_m
        np.testing.assert_array_equal(threat.position, track.position_at(received)[0])
        expected_v = np.zeros(3) if popup else track.velocity_at(received)[0]
        np.testing.assert_array_equal(threat.velocity_ned_m_s, expected_v)


def test_drone_velocity_follows_the_segment_of_a_turning_track():
    track = turning()
    for received, threat, _ in feed([track]):
        np.testing.assert_array_equal(threat.velocity_ned_m_s, track.velocity_at(received)[0])
        np.testing.assert_allclose(threat.position, track.position_at(received)[0], atol=0)


@pytest.mark.parametrize("update_hz", [0.2, 0.7, 2.0, 5.0])
def test_report_spacing_and_count(update_hz):
    track = crossing(start_s=2.0, end_s=32.0)
    updates = feed([track], update_hz=update_hz)
    t = np.array([u[0] for u in updates])
    assert t[0] == track.first_report_t_s
    np.testing.assert_allclose(np.diff(t), 1.0 / update_hz, rtol=1e-9)
    assert t.size == math.floor(30.0 * update_hz + 1e-9) + 1
    assert t[-1] <= track.last_report_t_s + 1e-9
    assert t[-1] + 1.0 / update_hz > track.last_report_t_s
    assert all(th.ttl_s == max(TTL_PERIODS / update_hz, TTL_MIN_S) for _, th, _ in updates)


@pytest.mark.parametrize("latency_s", [0.05, 0.3, 0.5])
def test_latency_shifts_the_receive_times_not_the_positions(latency_s):
    track = crossing()
    on_time = feed([track])
    late = feed([track], latency_s=latency_s)
    assert len(late) == len(on_time)
    for (t0, th0, _), (t1, th1, _) in zip(on_time, late):
        assert t1 == pytest.approx(t0 + latency_s, abs=1e-12)
        assert th1.received_t_s == t1
        assert th1.position == th0.position  # measured when sent: that much old on receipt
        np.testing.assert_allclose(th1.position, track.position_at(t1 - latency_s)[0], atol=1e-9)


def test_several_intruders_in_time_order_with_their_ids():
    tracks = [crossing("a", start_s=3.0), turning("b"), crossing("c", start_s=4.2, popup=True)]
    updates = feed(tracks, update_hz=2.0)
    times = [u[0] for u in updates]
    assert times == sorted(times)
    by_id = {tr.id: tr for tr in tracks}
    assert {u[2] for u in updates} == set(by_id)
    for received, threat, tid in updates:
        track = by_id[tid]
        np.testing.assert_allclose(threat.position, track.position_at(received)[0], atol=1e-12)
        assert threat.kind == ("popup" if track.popup else "moving")
    for tr in tracks:
        assert sum(u[2] == tr.id for u in updates) == report_times(tr, 2.0).size


def test_noise_statistics():
    """Position and velocity errors: mean 0 and the standard deviation asked, per axis,
    independent of each other (correlation); a popup's velocity stays zero."""
    sigma_p, sigma_v = 2.5, 0.4
    track = straight_track("n", 0.0, 600.0, (0.0, 50.0, -20.0), (1.0, -2.0, 0.3), 3.0)
    updates = feed([track], seed=3, update_hz=5.0, noise_pos_m=sigma_p, noise_vel_m_s=sigma_v)
    t = np.array([u[0] for u in updates])
    err_p = np.array([u[1].position for u in updates]) - track.position_at(t)
    err_v = np.array([u[1].velocity_ned_m_s for u in updates]) - track.velocity_at(t)
    n = t.size
    assert n == 3001
    for err, sigma in ((err_p, sigma_p), (err_v, sigma_v)):
        assert np.all(np.abs(err.mean(axis=0)) < 5 * sigma / math.sqrt(n))
        assert np.all(np.abs(err.std(axis=0) / sigma - 1.0) < 5 / math.sqrt(2 * n))
        corr = np.corrcoef(err.T)[np.triu_indices(3, 1)]
        assert np.all(np.abs(corr) < 5 / math.sqrt(n))
    popup = crossing(popup=True, end_s=200.0)
    noisy = feed([popup], seed=4, noise_pos_m=sigma_p, noise_vel_m_s=sigma_v)
    assert all(th.velocity_ned_m_s == (0.0, 0.0, 0.0) and th.kind == "popup" for _, th, _ in noisy)
    err = np.array([th.position for _, th, _ in noisy]) - popup.pos_ned_m[0]
    assert np.all(np.abs(err.std(axis=0) / sigma_p - 1.0) < 5 / math.sqrt(2 * err.shape[0]))


def test_no_noise_draws_no_noise():
    track = crossing()
    a = feed([track], seed=1)
    b = feed([track], seed=2)
    assert [(u[0], u[1]) for u in a] == [(u[0], u[1]) for u in b]


@pytest.mark.parametrize("dropout", [0.1, 0.4, 0.6])
def test_dropout_fraction_and_the_first_report_kept(dropout):
    """Over 300 intruders of 20 reports each: every first report arrives; the others are lost
    with probability ``dropout`` (binomial, 5 sigma)."""
    tracks = [crossing(f"d{j}", start_s=1.0 + 0.01 * j, end_s=10.5 + 0.01 * j) for j in range(300)]
    updates = feed(tracks, seed=11, update_hz=2.0, dropout=dropout)
    sent_per_track = report_times(tracks[0], 2.0).size
    assert sent_per_track == 20
    received = {tr.id: [] for tr in tracks}
    for t, _, tid in updates:
        received[tid].append(t)
    for tr in tracks:
        assert received[tr.id][0] == tr.first_report_t_s
    later = sum(len(v) - 1 for v in received.values())
    sent_later = len(tracks) * (sent_per_track - 1)
    expected = sent_later * (1 - dropout)
    sigma = math.sqrt(sent_later * dropout * (1 - dropout))
    assert abs(later - expected) < 5 * sigma, (later, expected)


def test_dropout_keeps_the_first_report_even_when_almost_all_are_lost():
    tracks = [crossing(f"e{j}") for j in range(50)]
    updates = feed(tracks, seed=12, dropout=0.99)
    assert {u[2] for u in updates} == {tr.id for tr in tracks}
    assert len(updates) < 50 + 50 * 41 * 0.05


# ---------------------------------------------------------------------------------------------
# manned traffic: ADSB_VEHICLE
# ---------------------------------------------------------------------------------------------


def _to_local(threat: Threat) -> Threat:
    table = ThreatTable(HOME)
    table.put(threat)
    return table.get(threat.id)


def test_manned_updates_are_adsb_threats_at_one_hertz():
    track = manned_track()
    updates = feed([track], "rotorcraft", update_hz=5.0)  # manned traffic is 1 Hz whatever asked
    t = np.array([u[0] for u in updates])
    np.testing.assert_allclose(np.diff(t), 1.0 / MANNED_UPDATE_HZ)
    assert t[0] == track.first_report_t_s and t.size == 71
    for received, threat, tid in updates:
        assert tid == threat.id == f"adsb-{ICAO:06x}"
        assert threat.frame == "global" and threat.kind == "moving"
        assert threat.radius_m == ADSB.radius_rotorcraft_m
        assert threat.ttl_s == ADSB.ttl_s and threat.received_t_s == received
        local = _to_local(threat)
        truth = track.position_at(received)[0]
        assert np.linalg.norm(np.asarray(local.position) - truth) < 0.1
        assert np.hypot(*(np.asarray(local.position) - truth)[:2]) < 0.02
        assert abs(local.position[2] - truth[2]) < 1e-3


def _fields(pos, vel, *, icao=ICAO, emitter=ROTORCRAFT) -> dict:
    track = IntruderTrack(
        f"adsb-{icao:06x}",
        np.array([0.0, 1.0]),
        np.zeros((2, 3)),
        25.0,
        0.0,
        1.0,
        icao_address=icao,
        emitter_type=int(emitter),
    )
    return adsb_fields(
        track,
        np.asarray(pos, dtype=float),
        np.asarray(vel, dtype=float),
        HOME,
        mavlink.MAVLink(None, srcSystem=1, srcComponent=1),
    )


position_m = st.tuples(st.floats(-3000.0, 3000.0), st.floats(-3000.0, 3000.0), st.floats(-2000.0, -10.0))  # in range
velocity_m_s = st.tuples(st.floats(-80.0, 80.0), st.floats(-80.0, 80.0), st.floats(-20.0, 20.0))


@given(position_m, velocity_m_s)
@settings(max_examples=200, deadline=None)
def test_adsb_round_trip_quantisation(pos, vel):
    """After the message's quantisation and the companion's conversion: position within 2 cm
    horizontally and 1 mm in altitude, speeds within 0.5 cm/s, course within 0.005 deg."""
    from companion.threats.transport.adsb import threat_from_adsb

    fields = _fields(pos, vel)
    threat = threat_from_adsb(fields, ADSB, 0.0, HOME)
    assert threat is not None
    local = np.asarray(_to_local(threat).position)
    err = local - np.asarray(pos)
    assert math.hypot(err[0], err[1]) < 0.02
    assert abs(err[2]) < 1e-3
    v_true, v_got = np.asarray(vel), np.asarray(threat.velocity_ned_m_s)
    speed_true = math.hypot(v_true[0], v_true[1])
    assert abs(math.hypot(v_got[0], v_got[1]) - speed_true) <= 0.005 + 1e-9
    assert abs(v_got[2] - v_true[2]) <= 0.005 + 1e-9
    course_err = 0.005 * math.pi / 180.0 * speed_true
    assert np.linalg.norm(v_got[:2] - v_true[:2]) <= 0.005 + course_err + 1e-6


def test_adsb_fields_are_a_real_mavlink_message():
    pos, vel = (350.0, -120.0, -95.0), (12.0, -30.0, 2.0)
    fields = _fields(pos, vel)
    assert fields["mavpackettype"] == "ADSB_VEHICLE"
    assert set(fields) - {"mavpackettype"} == set(mavlink.MAVLink_adsb_vehicle_message.fieldnames)
    # pack those fields again on another link and parse the bytes as a receiver would
    msg = mavlink.MAVLink_adsb_vehicle_message(
        *[fields[k] if k != "callsign" else fields[k].encode() for k in mavlink.MAVLink_adsb_vehicle_message.fieldnames]
    )
    sender = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    receiver = mavlink.MAVLink(None)
    parsed = receiver.parse_buffer(bytearray(msg.pack(sender)))
    assert len(parsed) == 1 and parsed[0].to_dict() == fields
    lat, lon, alt = HOME.to_lla(*pos)
    assert fields["lat"] == round(float(lat) * 1e7) and fields["lon"] == round(float(lon) * 1e7)
    assert fields["altitude"] == round(float(alt) * 1000.0)
    assert fields["ICAO_address"] == ICAO and fields["emitter_type"] == ROTORCRAFT
    assert fields["hor_velocity"] == round(math.hypot(12.0, -30.0) * 100)
    assert fields["ver_velocity"] == -200  # positive up: climbing at 2 m/s
    assert fields["heading"] == round(math.degrees(math.atan2(-30.0, 12.0)) * 100) % 36000
    assert fields["altitude_type"] == mavlink.ADSB_ALTITUDE_TYPE_GEOMETRIC
    needed = (
        mavlink.ADSB_FLAGS_VALID_COORDS
        | mavlink.ADSB_FLAGS_VALID_ALTITUDE
        | mavlink.ADSB_FLAGS_VALID_HEADING
        | mavlink.ADSB_FLAGS_VALID_VELOCITY
        | mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
    )
    assert fields["flags"] & needed == needed
    assert fields["tslc"] == 0 and fields["callsign"].startswith("N")


def test_manned_out_of_range_reports_are_not_heard():
    """Reports beyond the ADS-B range (5 km from home) are dropped; the approaching aircraft is
    heard from the first report within it."""
    track = manned_track(p0=(6000.0, 0.0, -300.0), v=(-50.0, 0.0, 0.0), start_s=0.0, end_s=60.0)
    updates = feed([track], "fixedwing")
    t = np.array([u[0] for u in updates])
    ranges = np.linalg.norm(track.position_at(t), axis=1)
    assert np.all(ranges <= ADSB.max_range_m + 0.1)
    sent = report_times(track, 1.0)
    heard_from = sent[np.linalg.norm(track.position_at(sent), axis=1) <= ADSB.max_range_m][0]
    assert t[0] == heard_from and 0 < t[0]


def test_manned_with_latency_stamped_late():
    track = manned_track()
    on_time = feed([track], "rotorcraft")
    late = feed([track], "rotorcraft", latency_s=0.4)
    for (t0, th0, _), (t1, th1, _) in zip(on_time, late):
        assert t1 == pytest.approx(t0 + 0.4) and th1.received_t_s == t1
        assert th1.position == th0.position
