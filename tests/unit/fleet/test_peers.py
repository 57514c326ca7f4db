"""Other vehicles as threats: their frame, their clock, priorities, staleness."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.fleet.message import SampledPath, TrajectoryMessage
from companion.fleet.peers import PeerTable
from companion.fleet.settings import FleetSettings
from companion.geo import LocalFrame
from companion.threats.decision.prediction import predict_tubes

HOME = (47.397742, 8.545594, 488.0)
S = FleetSettings()


def east_of_home(east_m: float) -> tuple:
    lat, lon, alt = LocalFrame(*HOME).to_lla(0.0, east_m, 0.0)
    return float(lat), float(lon), float(alt)


def msg(
    sysid=2,
    seq=1,
    *,
    origin=HOME,
    mission_s=100.0,
    unix_s=5000.0,
    scale=1.0,
    ned=None,
    pending=None,
    echo=None,
    sent_unix_s=None,
) -> TrajectoryMessage:
    ned = np.array([[0.0, 0.0, -15.0], [0.0, 4.0, -15.0], [0.0, 8.0, -15.0]]) if ned is None else ned
    return TrajectoryMessage(
        sysid,
        seq,
        1.6,
        origin,
        mission_s,
        unix_s,
        scale,
        unix_s if sent_unix_s is None else sent_unix_s,
        SampledPath("leg0", mission_s, 0.5, ned),
        pending,
        echo or {},
    )


def test_another_origin_is_shifted_into_our_frame():
    table = PeerTable(1, S, HOME)
    table.receive(msg(origin=east_of_home(100.0)), 5000.0)
    (th,) = table.threats(20.0, 5000.0, 1.0)
    assert th.ned_m[0] == pytest.approx([0.0, 100.0, -15.0], abs=0.05)


def test_their_mission_time_is_mapped_to_ours_through_the_wall_clock():
    table = PeerTable(1, S, HOME)
    table.receive(msg(mission_s=100.0, unix_s=5000.0), 5000.01)
    # our mission clock reads 20 s at wall 5002: their 100 s (wall 5000) is our 18 s
    (th,) = table.threats(20.0, 5002.0, 1.0)
    assert th.times_s == pytest.approx([18.0, 18.5, 19.0])
    assert th.position_at(18.25) == pytest.approx([0.0, 2.0, -15.0])
    # at time scale 4 (both clocks run 4 vehicle s per wall s), the same instant is our 12 s
    (th,) = table.threats(20.0, 5002.0, 4.0)
    assert th.times_s[0] == pytest.approx(12.0)


def test_a_higher_id_is_seen_only_yield_s_ahead_and_its_pending_path_is_its_own_business():
    pending = SampledPath("replan", 100.0, 0.5, np.zeros((2, 3)))
    table = PeerTable(2, S, HOME)
    table.receive(msg(sysid=1, pending=pending), 5000.0)
    table.receive(msg(sysid=3, pending=pending), 5000.0)
    got = {th.id: th for th in table.threats(20.0, 5000.0, 1.0)}
    assert set(got) == {"uav1", "uav1-pending", "uav3"}
    assert math.isinf(got["uav1"].expires_t_s) and got["uav3"].expires_t_s == pytest.approx(20.0 + S.yield_s)


def test_our_own_messages_and_late_ones_are_ignored():
    table = PeerTable(1, S, HOME)
    table.receive(msg(sysid=1), 5000.0)
    assert len(table) == 0
    table.receive(msg(seq=5, ned=np.zeros((1, 3))), 5000.0)
    table.receive(msg(seq=4), 5000.1)
    (th,) = table.threats(0.0, 5000.2, 1.0)
    assert len(th.ned_m) == 1 and table.counts["out_of_order"] == 1


def test_a_silent_vehicle_grows_then_is_forgotten():
    table = PeerTable(1, S, HOME)
    table.receive(msg(mission_s=100.0, unix_s=5000.0), 5000.0)
    fresh = predict_tubes(table.threats(20.0, 5000.0, 1.0), inflation_m=2.0)[0]
    stale = predict_tubes(
        table.threats(20.0 + 2 * S.stale_after_s, 5000.0 + 2 * S.stale_after_s, 1.0), inflation_m=2.0
    )[0]
    t = np.array([30.0])
    assert stale.radius_at(t)[0] == pytest.approx(fresh.radius_at(t)[0] - S.growth_max_m + S.stale_max_m)
    assert table.threats(0.0, 5000.0 + S.forget_after_s + 1.0, 1.0) == [] and len(table) == 0


def test_delays_and_clock_offsets_are_measured_from_the_echoes():
    table = PeerTable(1, S, HOME)
    # we sent at 100.0; they (clock 0.5 s ahead) got it at 100.55, echo it in a message sent at
    # their 101.0 that reaches us at 100.55 (0.05 s each way); the message's trajectory was
    # committed at their 100.85 (our 100.35): 0.2 s before it arrived
    table.receive(msg(unix_s=100.85, sent_unix_s=101.0, echo={1: (100.0, 100.55)}), 100.55)
    (peer,) = table.summary(100.55)
    assert peer["offset_s"] == pytest.approx(0.5) and peer["offset_bound_s"] == pytest.approx(0.05)
    assert table.max_delay_s() == pytest.approx(0.2)
    assert table.echo() == {2: (101.0, 100.55)}
