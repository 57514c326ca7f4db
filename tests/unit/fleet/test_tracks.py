"""companion.fleet.tracks: common wall-clock grid, pairwise separation, path length (synthetic
tracks), and a track read back from a tlog written with pymavlink."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ConfigError
from companion.fleet.tracks import (
    Track,
    common_grid,
    fleet_separation,
    path_length_m,
    read_tlog_track,
    resample,
    separation,
    tracks_in_frame,
)


def line(t, start, velocity):
    return np.asarray(start, float) + np.outer(np.asarray(t, float) - t[0], velocity)


def test_two_vehicles_crossing_at_right_angles_with_a_time_offset():
    # A flies north through the origin at t = 10, B flies east through it at t = 10 + dt:
    # the closest approach is v * dt / sqrt(2)
    v, dt = 7.0, 1.0
    t = np.arange(0.0, 20.0, 0.2)
    a = line(t, [-70.0, 0.0, -15.0], [v, 0.0, 0.0])
    b = line(t, [0.0, -70.0 - v * dt, -15.0], [0.0, v, 0.0])
    sep = separation([t, t], [a, b], step_s=0.01)
    assert sep.min_m == pytest.approx(v * dt / math.sqrt(2.0), abs=0.01)
    assert sep.pair == (0, 1)
    assert sep.t_s == pytest.approx(10.5, abs=0.05)
    assert sep.losses(4.2) == 0 and sep.losses(5.0) == 1


def test_head_on_tracks_sampled_at_different_times_meet_between_samples():
    ta = np.arange(0.0, 10.0, 0.5)
    tb = np.arange(0.25, 10.0, 0.5)  # never sampled at A's times
    a = line(ta, [0.0, -35.0, -15.0], [0.0, 7.0, 0.0])
    b = line(tb, [0.0, 35.0 - 1.75, -15.0], [0.0, -7.0, 0.0])
    sep = separation([ta, tb], [a, b])
    assert sep.min_m < 0.5  # they pass through each other at t = 5
    assert sep.common_s == pytest.approx(min(ta[-1], tb[-1]) - max(ta[0], tb[0]), abs=1e-9)


def test_tracks_that_do_not_overlap_in_time_have_no_common_time():
    t1, t2 = np.arange(0.0, 5.0, 0.1), np.arange(6.0, 9.0, 0.1)
    sep = separation([t1, t2], [np.zeros((len(t1), 3)), np.zeros((len(t2), 3))])
    assert math.isinf(sep.min_m) and sep.pair is None and sep.common_s == 0.0
    assert len(common_grid([t1, t2])) == 0


def test_three_tracks_report_the_closest_pair_and_every_pair():
    t = np.linspace(0.0, 10.0, 101)
    tracks = [
        np.column_stack([t * 0, t * 0, -15 + t * 0]),
        np.column_stack([t * 0 + 10.0, t * 0, -15 + t * 0]),
        np.column_stack([t * 0 + 3.0, t * 0, -15 + t * 0]),
    ]
    sep = separation([t, t, t], tracks)
    assert sep.pair == (0, 2) and sep.min_m == pytest.approx(3.0)
    assert sep.pair_min_m == {(0, 1): pytest.approx(10.0), (0, 2): pytest.approx(3.0), (1, 2): pytest.approx(7.0)}
    assert sep.losses(4.2) == 1


def test_path_length_and_resample():
    assert path_length_m([[0, 0, 0], [3, 4, 0], [3, 4, 12]]) == pytest.approx(17.0)
    assert path_length_m(np.zeros((1, 3))) == 0.0
    got = resample([0.0, 2.0], [[0.0, 0.0, 0.0], [2.0, 4.0, -2.0]], [0.0, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(got, [[0, 0, 0], [1, 2, -1], [2, 4, -2], [2, 4, -2]])


def test_mismatched_inputs_are_errors():
    with pytest.raises(ConfigError, match="separation"):
        separation([np.zeros(2)], [np.zeros((2, 3)), np.zeros((2, 3))])
    with pytest.raises(ConfigError, match="step_s"):
        common_grid([np.zeros(2)], step_s=0.0)


tracks_strategy = st.integers(min_value=2, max_value=4).flatmap(
    lambda n: st.tuples(st.just(n), st.integers(min_value=0, max_value=2**32 - 1))
)


def random_tracks(n: int, seed: int):
    rng = np.random.default_rng(seed)
    times, pos = [], []
    for _ in range(n):
        k = int(rng.integers(2, 30))
        t = np.sort(rng.uniform(0.0, 10.0, k))
        t = np.unique(np.round(t, 3))
        if len(t) < 2:
            t = np.array([0.0, 10.0])
        times.append(t)
        pos.append(rng.normal(0.0, 20.0, (len(t), 3)))
    return times, pos


@settings(max_examples=60, deadline=None)
@given(tracks_strategy)
def test_separation_is_symmetric_and_never_above_the_distance_at_a_common_sample(case):
    n, seed = case
    times, pos = random_tracks(n, seed)
    sep = separation(times, pos)
    rev = separation(times[::-1], pos[::-1])
    if math.isinf(sep.min_m):
        assert math.isinf(rev.min_m)
        return
    assert rev.min_m == pytest.approx(sep.min_m, abs=1e-9)
    assert sep.min_m == pytest.approx(min(sep.pair_min_m.values()), abs=1e-12)
    start, end = max(t[0] for t in times), min(t[-1] for t in times)
    for i in range(n):
        for j in range(i + 1, n):
            both = np.intersect1d(times[i], times[j])
            both = both[(both >= start) & (both <= end)]
            for t in both:
                d = np.linalg.norm(pos[i][times[i] == t][0] - pos[j][times[j] == t][0])
                assert sep.pair_min_m[(i, j)] <= d + 1e-9
                assert sep.min_m <= d + 1e-9


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_separation_at_a_shared_sample_time_is_exact(seed):
    # two tracks on one clock: the minimum is the smallest distance of the samples or less
    rng = np.random.default_rng(seed)
    t = np.sort(np.unique(np.round(rng.uniform(0, 10, 12), 3)))
    a, b = rng.normal(0, 10, (len(t), 3)), rng.normal(0, 10, (len(t), 3))
    sep = separation([t, t], [a, b])
    assert sep.min_m <= np.min(np.linalg.norm(a - b, axis=1)) + 1e-9
    assert sep.min_m >= 0.0


def write_tlog(path, rows, *, sysid=1, other=None):
    """A tlog of GLOBAL_POSITION_INT rows (wall s, lat, lon, alt) from ``sysid`` (and the same
    positions shifted from ``other``), written as sim-vehicle writes it (8-byte stamp + frame)."""
    import struct

    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    with open(path, "wb") as fh:
        for sender, shift in [(sysid, 0.0)] + ([(other, 0.001)] if other else []):
            mav = mavlink2.MAVLink(None, srcSystem=sender, srcComponent=1)
            for t, lat, lon, alt in rows:
                msg = mav.global_position_int_encode(
                    int(t * 1000) % 2**32,
                    int(round((lat + shift) * 1e7)),
                    int(round(lon * 1e7)),
                    int(round(alt * 1000)),
                    15000,
                    0,
                    0,
                    0,
                    0,
                )
                fh.write(struct.pack(">Q", int(t * 1e6)) + msg.pack(mav))


def test_a_track_is_read_back_from_a_tlog_with_its_wall_clock_stamps(tmp_path):
    rows = [(1796120000.0 + 0.2 * k, 47.397742 + 1e-5 * k, 8.545594, 503.0) for k in range(20)]
    write_tlog(tmp_path / "a.tlog", rows, sysid=2, other=7)
    track = read_tlog_track(tmp_path / "a.tlog", 2)
    assert isinstance(track, Track) and track.sysid == 2 and len(track) == 20
    np.testing.assert_allclose(track.t_s, [r[0] for r in rows], atol=1e-6)
    np.testing.assert_allclose(track.lla[:, 0], [r[1] for r in rows], atol=1e-7)
    np.testing.assert_allclose(track.lla[:, 2], 503.0)
    assert read_tlog_track(tmp_path / "a.tlog").sysid == 2  # the first system heard
    with pytest.raises(ConfigError, match="no GLOBAL_POSITION_INT from system 3"):
        read_tlog_track(tmp_path / "a.tlog", 3)
    with pytest.raises(ConfigError, match="does not exist"):
        read_tlog_track(tmp_path / "missing.tlog", 1)


def test_fleet_separation_of_two_tlogs(tmp_path):
    from heli_common.frames import LocalFrame

    frame = LocalFrame(47.397742, 8.545594, 488.0)
    t = 1796120000.0 + 0.1 * np.arange(101)
    for sysid, sign in ((1, 1.0), (2, -1.0)):  # head-on along east, 2 m apart north
        east = sign * (35.0 - 7.0 * (t - t[0]))
        lat, lon, alt = frame.to_lla(np.full_like(t, sysid * 2.0), east, np.full_like(t, -15.0))
        write_tlog(tmp_path / f"sim{sysid - 1}.tlog", list(zip(t, lat, lon, alt)), sysid=sysid)
    out = fleet_separation([tmp_path / "sim0.tlog", tmp_path / "sim1.tlog"], [1, 2])
    assert out["min_separation_m"] == pytest.approx(2.0, abs=0.05)
    assert out["closest_pair"] == [1, 2]
    assert out["path_length_m"][1] == pytest.approx(70.0, abs=0.2)
    times, ned, frame2 = tracks_in_frame([read_tlog_track(tmp_path / "sim0.tlog", 1)])
    assert ned[0][0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)  # the first sample's point
