"""How close each intruder came (``companion.campaign.judge``): miss distances, the spheres of the
drone scale and the cylinders of manned traffic at their boundaries, obstacle entries and the
length flown."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from companion.campaign.judge import FT_M, Volumes, entries, path_length_m, separation
from companion.campaign.tracks import IntruderTrack, straight_track
from companion.world import Cylinder

DT_S = 0.02
SPEED_M_S = 6.0
T_CPA_S = 10.0
VOLUMES = Volumes()
EPS_M = 1e-6


def own_line(t_end_s: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """A level straight own track north at 6 m/s, 50 Hz (sample 500 at T_CPA_S exactly)."""
    t = np.arange(0, int(round(t_end_s / DT_S)) + 1) * DT_S
    return t, np.column_stack([SPEED_M_S * t, np.zeros_like(t), np.full_like(t, -20.0)])


def own_at_cpa() -> np.ndarray:
    return np.array([SPEED_M_S * T_CPA_S, 0.0, -20.0])


def static_at(offset_ned_m, radius_m: float, tid: str = "s") -> IntruderTrack:
    """A static intruder at the own position at T_CPA_S plus an offset across the track (the
    closest approach is then at T_CPA_S, at the offset's distance)."""
    p = own_at_cpa() + np.asarray(offset_ned_m, dtype=float)
    return straight_track(tid, 0.0, 30.0, p, (0.0, 0.0, 0.0), radius_m, popup=True)


def judge_one(track: IntruderTrack, manned: bool = False, volumes: Volumes = VOLUMES):
    t, own = own_line()
    return separation(t, own, [track], manned, volumes)


# ---------------------------------------------------------------------------------------------
# miss distances
# ---------------------------------------------------------------------------------------------


@given(st.floats(-40.0, 40.0), st.floats(-30.0, 30.0), st.floats(-8.0, 8.0), st.floats(-8.0, 8.0), st.floats(1.0, 10.0))
@settings(max_examples=150, deadline=None)
def test_known_miss_vector(east_m, down_m, v_east, v_down, radius_m):
    """A moving intruder that passes the own position at T_CPA_S offset by a miss vector
    perpendicular to the relative velocity: hmd, vmd and the time are the miss's."""
    v_int = np.array([0.0, v_east, v_down])
    v_rel = np.array([SPEED_M_S, 0.0, 0.0]) - v_int
    miss = np.array([0.0, east_m, down_m])
    miss -= (miss @ v_rel) / (v_rel @ v_rel) * v_rel  # perpendicular to the relative motion
    p0 = own_at_cpa() + miss - v_int * T_CPA_S
    sep = judge_one(straight_track("m", 0.0, 30.0, p0, v_int, radius_m))
    assert sep.cpa_t_s[0] == pytest.approx(T_CPA_S, abs=1e-9)
    assert sep.hmd_m[0] == pytest.approx(math.hypot(miss[0], miss[1]), abs=1e-6)
    assert sep.vmd_m[0] == pytest.approx(abs(miss[2]), abs=1e-6)
    assert sep.min_sep_m == pytest.approx(np.linalg.norm(miss) - radius_m, abs=1e-6)


def test_static_intruder_across_the_track():
    sep = judge_one(static_at((0.0, 12.0, -5.0), 3.0))
    assert sep.hmd_m == pytest.approx((12.0,))
    assert sep.vmd_m == pytest.approx((5.0,))
    assert sep.cpa_t_s == pytest.approx((T_CPA_S,))
    assert sep.min_sep_m == pytest.approx(13.0 - 3.0)
    assert (sep.collision, sep.nmac, sep.lowc) == (False, False, False)


# ---------------------------------------------------------------------------------------------
# drone scale: spheres
# ---------------------------------------------------------------------------------------------

SPHERES = Volumes(collision_extra_m=0.5, nmac_extra_m=1.5, lowc_extra_m=4.0)
DIRECTIONS = [(0.0, 1.0, 0.0), (0.0, 0.0, -1.0), (0.0, 0.6, 0.8)]


@pytest.mark.parametrize("direction", DIRECTIONS)
@pytest.mark.parametrize("volumes", [VOLUMES, SPHERES])
def test_sphere_boundaries(direction, volumes):
    """Just inside / just outside each sphere (radius + extra), whatever the direction."""
    radius = 4.0
    expected_at = {"collision": volumes.collision_extra_m, "nmac": volumes.nmac_extra_m, "lowc": volumes.lowc_extra_m}
    for name, extra in expected_at.items():
        for delta, inside in ((-EPS_M, True), (EPS_M, False)):
            distance = radius + extra + delta
            sep = judge_one(static_at(distance * np.asarray(direction), radius), volumes=volumes)
            flags = {"collision": sep.collision, "nmac": sep.nmac, "lowc": sep.lowc}
            assert flags[name] is inside, (name, delta)
            for other, other_extra in expected_at.items():  # the nested volumes agree
                assert flags[other] is (distance < radius + other_extra)
            assert sep.min_sep_m == pytest.approx(distance - radius, abs=1e-9)


@pytest.mark.parametrize("volumes", [VOLUMES, SPHERES])
def test_on_a_sphere_is_outside(volumes):
    """The volumes are open: at exactly radius + extra (exact in floating point) no flag."""
    radius = 4.0
    for name, extra in (
        ("collision", volumes.collision_extra_m),
        ("nmac", volumes.nmac_extra_m),
        ("lowc", volumes.lowc_extra_m),
    ):
        sep = judge_one(static_at((0.0, 0.0, -(radius + extra)), radius), volumes=volumes)
        assert sep.min_sep_m == extra
        assert getattr(sep, name) is False, name


@given(st.floats(0.0, 20.0), st.floats(1.0, 8.0))
@settings(max_examples=100, deadline=None)
def test_sphere_flags_follow_the_distance(distance, radius):
    for extra in (VOLUMES.collision_extra_m, VOLUMES.nmac_extra_m, VOLUMES.lowc_extra_m):
        assume(abs(distance - radius - extra) > 1e-9)  # off the boundary by more than rounding
    sep = judge_one(static_at((0.0, 0.0, -distance), radius))
    assert sep.collision == (distance < radius + VOLUMES.collision_extra_m)
    assert sep.nmac == (distance < radius + VOLUMES.nmac_extra_m)
    assert sep.lowc == (distance < radius + VOLUMES.lowc_extra_m)
    assert sep.collision <= sep.nmac <= sep.lowc


# ---------------------------------------------------------------------------------------------
# manned traffic: cylinders
# ---------------------------------------------------------------------------------------------

NMAC_H, NMAC_V = VOLUMES.nmac_h_ft * FT_M, VOLUMES.nmac_v_ft * FT_M
WC_H, WC_V = VOLUMES.wc_h_ft * FT_M, VOLUMES.wc_v_ft * FT_M
MANNED_RADIUS_M = 25.0


@pytest.mark.parametrize(
    "h_m, v_m, nmac, lowc",
    [
        (NMAC_H - 0.01, NMAC_V - 0.01, True, True),
        (NMAC_H + 0.01, NMAC_V - 0.01, False, True),
        (NMAC_H - 0.01, NMAC_V + 0.01, False, True),
        (WC_H - 0.01, WC_V - 0.01, False, True),
        (WC_H + 0.01, 0.0, False, False),
        (0.0, WC_V + 0.01, False, False),
        (WC_H - 0.01, WC_V + 0.01, False, False),
        (100.0, 0.0, True, True),
    ],
)
def test_cylinder_boundaries(h_m, v_m, nmac, lowc):
    """The cylinders: horizontally within and vertically within at once (500 ft / 100 ft,
    2000 ft / 250 ft); collision inside the emitter's radius."""
    sep = judge_one(static_at((0.0, h_m, -v_m), MANNED_RADIUS_M), manned=True)
    assert (sep.nmac, sep.lowc) == (nmac, lowc)
    assert not sep.collision
    assert sep.hmd_m[0] == pytest.approx(h_m, abs=1e-6) and sep.vmd_m[0] == pytest.approx(v_m, abs=1e-6)


@pytest.mark.parametrize("delta, inside", [(-EPS_M, True), (EPS_M, False)])
def test_manned_collision_inside_the_radius(delta, inside):
    sep = judge_one(static_at(np.array([0.0, 0.6, 0.8]) * (MANNED_RADIUS_M + delta), MANNED_RADIUS_M), manned=True)
    assert sep.collision is inside
    assert sep.nmac and sep.lowc


def test_manned_nmac_needs_both_at_once():
    """Horizontally inside 500 ft at one time and vertically inside 100 ft at another, never
    both: no NMAC, yet a loss of well clear (inside both of its bounds at once)."""
    t = np.arange(0, 2001) * DT_S
    own = np.zeros((t.size, 3))
    own[:, 2] = -300.0
    # until 20 s: right below, 60 m lower (inside 500 ft, outside 100 ft); then level, 200 m away
    p = np.column_stack([np.where(t < 20.0, 0.0, 200.0), np.zeros_like(t), np.where(t < 20.0, -240.0, -300.0)])
    track = IntruderTrack("adsb-a00001", t, p, MANNED_RADIUS_M, 0.0, float(t[-1]))
    sep = separation(t, own, [track], True, VOLUMES)
    assert not sep.nmac
    assert sep.lowc  # below: 0 m < 2000 ft and 60 m < 250 ft at once
    sep_wide = separation(t, own, [track], True, Volumes(nmac_v_ft=250.0))
    assert sep_wide.nmac  # 60 m < 250 ft: the pass below is one


def test_manned_flags_from_any_time_not_only_the_closest_approach():
    """An NMAC is any sample inside the cylinder, even where the 3D distance is not the least."""
    t = np.arange(0, 1001) * DT_S
    own = np.column_stack([np.zeros_like(t), np.zeros_like(t), np.full_like(t, -300.0)])
    # 140 m horizontally and 25 m above first (NMAC), then 60 m right below (not NMAC: > 100 ft)
    p = np.column_stack([np.where(t < 10.0, 140.0, 0.0), np.zeros_like(t), np.where(t < 10.0, -325.0, -240.0)])
    track = IntruderTrack("adsb-a00002", t, p, MANNED_RADIUS_M, 0.0, float(t[-1]))
    sep = separation(t, own, [track], True, VOLUMES)
    assert sep.hmd_m[0] == pytest.approx(0.0) and sep.vmd_m[0] == pytest.approx(60.0)
    assert sep.nmac


# ---------------------------------------------------------------------------------------------
# several intruders
# ---------------------------------------------------------------------------------------------


def test_multiple_intruders():
    near = static_at((0.0, 0.0, -4.5), 4.0, "near")  # 0.5 m beyond its radius: NMAC, no collision
    far = straight_track("far", 0.0, 30.0, (0.0, 30.0, -20.0), (SPEED_M_S, 0.0, 0.0), 2.0)  # alongside, 30 m east
    t, own = own_line()
    sep = separation(t, own, [far, near], False, VOLUMES)
    assert len(sep.hmd_m) == len(sep.vmd_m) == len(sep.cpa_t_s) == 2
    assert sep.hmd_m[1] == pytest.approx(0.0) and sep.vmd_m[1] == pytest.approx(4.5)
    assert sep.cpa_t_s[1] == pytest.approx(T_CPA_S)
    assert sep.hmd_m[0] > 29.0
    assert sep.min_sep_m == pytest.approx(0.5)
    assert (sep.collision, sep.nmac, sep.lowc) == (False, True, True)
    hit = static_at((0.0, 1.0, 0.0), 3.0, "hit")
    both = separation(t, own, [far, near, hit], False, VOLUMES)
    assert both.collision and both.min_sep_m == pytest.approx(-2.0)
    none = separation(t, own, [far], False, VOLUMES)
    assert (none.collision, none.nmac, none.lowc) == (False, False, False)


# ---------------------------------------------------------------------------------------------
# entries and path length
# ---------------------------------------------------------------------------------------------

LO, HI = np.array([-50.0, -50.0, -60.0]), np.array([250.0, 50.0, -1.0])


def test_entries_counts_each_entry():
    t, own = own_line(30.0)  # 0 .. 180 m north
    one = (Cylinder((60.0, 0.0), 3.0),)
    two = (Cylinder((60.0, 0.0), 3.0), Cylinder((120.0, 0.0), 3.0))
    assert entries(own, (), LO, HI) == 0
    assert entries(own, one, LO, HI) == 1
    assert entries(own, two, LO, HI) == 2
    beside = (Cylinder((60.0, 10.0), 3.0),)
    assert entries(own, beside, LO, HI) == 0


def test_entries_into_one_obstacle_twice_and_from_inside():
    t = np.linspace(0.0, 1.0, 2001)
    north = 60.0 + 10.0 * np.sin(2 * np.pi * 2 * t)  # two periods about the obstacle's centre
    own = np.column_stack([north, np.zeros_like(t), np.full_like(t, -20.0)])
    obstacle = (Cylinder((60.0, 0.0), 3.0),)
    inside = np.abs(north - 60.0) < 3.0
    expected = int(inside[0]) + int(np.count_nonzero(inside[1:] & ~inside[:-1]))
    assert entries(own, obstacle, LO, HI) == expected == 5  # starts inside, then 4 crossings
    go_and_back = np.concatenate([np.linspace(0.0, 100.0, 501), np.linspace(100.0, 0.0, 501)])
    own2 = np.column_stack([go_and_back, np.zeros_like(go_and_back), np.full_like(go_and_back, -20.0)])
    assert entries(own2, obstacle, LO, HI) == 2


def test_entries_respect_the_cylinder_height():
    t, own = own_line(30.0)
    low = (Cylinder((60.0, 0.0), 3.0, -10.0, 0.0),)  # from 10 m down to the ground; we fly at 20 m
    assert entries(own, low, LO, HI) == 0
    tall = (Cylinder((60.0, 0.0), 3.0, -30.0, 0.0),)
    assert entries(own, tall, LO, HI) == 1


@given(st.lists(st.tuples(*[st.floats(-100.0, 100.0)] * 3), min_size=2, max_size=30))
@settings(max_examples=100, deadline=None)
def test_path_length_is_the_sum_of_the_segments(points):
    p = np.array(points)
    expected = sum(math.dist(a, b) for a, b in zip(points[:-1], points[1:]))
    assert path_length_m(p) == pytest.approx(expected, rel=1e-12, abs=1e-9)


@given(st.tuples(*[st.floats(-100.0, 100.0)] * 3), st.tuples(*[st.floats(-100.0, 100.0)] * 3), st.integers(2, 200))
@settings(max_examples=100, deadline=None)
def test_path_length_of_a_subdivided_line(a, b, n):
    p = np.linspace(a, b, n)
    assert path_length_m(p) == pytest.approx(math.dist(a, b), rel=1e-9, abs=1e-9)
    assert path_length_m(p[:1]) == 0.0


# ---------------------------------------------------------------------------------------------
# Volumes validation
# ---------------------------------------------------------------------------------------------

FIELDS = ("collision_extra_m", "nmac_extra_m", "lowc_extra_m", "nmac_h_ft", "nmac_v_ft", "wc_h_ft", "wc_v_ft")


@pytest.mark.parametrize("name", FIELDS)
@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "3"])
def test_volumes_bad_value_names_the_field(name, bad):
    with pytest.raises(ValueError, match=rf"volumes\.{name}"):
        Volumes(**{name: bad})


def test_volumes_order_named():
    with pytest.raises(ValueError, match="collision_extra_m <= nmac_extra_m <= lowc_extra_m"):
        Volumes(collision_extra_m=2.0, nmac_extra_m=1.0)
    with pytest.raises(ValueError, match="collision_extra_m <= nmac_extra_m <= lowc_extra_m"):
        Volumes(nmac_extra_m=5.0)
    with pytest.raises(ValueError, match="NMAC cylinder"):
        Volumes(nmac_h_ft=2500.0)
    with pytest.raises(ValueError, match="NMAC cylinder"):
        Volumes(nmac_v_ft=300.0)
    assert Volumes(collision_extra_m=1.0, nmac_extra_m=1.0, lowc_extra_m=1.0).lowc_extra_m == 1.0
