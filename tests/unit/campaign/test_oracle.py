"""The threat benchmark's oracle (``companion/campaign/oracle.py``): labels and witnesses.

The oracle decides which encounters can be avoided at all; the policy's success is reported on
those. It must say "avoidable" only with a manoeuvre that really stays clear (checked here at a
4x finer step than its own, without its sampling slack), and "unavoidable" where physics says
so (a head-on threat that reaches the vehicle before any acceleration within the limits can move
it out of the sphere).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.threats.model import Threat
from companion.world import Box, Cylinder, World

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from companion.campaign.oracle import TRACKING_ALLOWANCE_M, OracleLimits, flight_margins, label_encounter, manoeuvres  # noqa: E402

LIMITS = OracleLimits()
DOWN_M = -20.0
OPEN = World([], [-200.0, -200.0, -40.0], [300.0, 300.0, -5.0])
#: Largest norm of an acceleration within the limits (m/s^2): every manoeuvre's deviation from
#: the straight, unaccelerated flight after t seconds is at most A_MAX t^2 / 2.
A_MAX = math.hypot(LIMITS.accel_horizontal_m_s2, LIMITS.accel_vertical_m_s2)


def threat(pos, vel=(0.0, 0.0, 0.0), radius_m=3.0, tid="t0", t_s=0.0) -> Threat:
    return Threat(
        tid,
        "moving" if any(vel) else "popup",
        "local_ned",
        tuple(float(x) for x in pos),
        tuple(float(x) for x in vel),
        float(radius_m),
        None,
        float(t_s),
    )


def assert_witness_clear(result, threats, world) -> None:
    """The witness stays clear at 0.005 s without slack, and within the limits."""
    assert result.witness is not None
    threat_m, world_m = flight_margins(result.witness, threats, world, step_s=0.005)
    assert threat_m >= 0.0, f"witness {result.witness.manoeuvre.name} meets a threat ({threat_m:.3f} m)"
    assert world_m >= 0.0, f"witness {result.witness.manoeuvre.name} meets the world ({world_m:.3f} m)"
    acc = result.witness.acc_ned_m_s2
    assert np.all(np.hypot(acc[:, 0], acc[:, 1]) <= LIMITS.accel_horizontal_m_s2 + 1e-9)
    assert np.all(np.abs(acc[:, 2]) <= LIMITS.accel_vertical_m_s2 + 1e-9)
    speed0 = float(np.linalg.norm(result.witness.vel_ned_m_s[0]))
    assert np.all(np.linalg.norm(result.witness.vel_ned_m_s, axis=1) <= max(LIMITS.speed_max_m_s, speed0) + 1e-9)


def test_a_static_threat_far_off_the_path_is_avoidable():
    pos0 = np.array([0.0, 0.0, DOWN_M])
    vel0 = np.array([6.0, 0.0, 0.0])
    far = [threat((40.0, 30.0, DOWN_M), radius_m=5.0)]
    res = label_encounter(pos0, vel0, far, 0.0, OPEN)
    assert res.avoidable
    assert res.witness.manoeuvre.name == "keep going"  # the first manoeuvre tried is enough
    assert res.tried < 100
    assert_witness_clear(res, far, OPEN)


def test_a_threat_that_already_contains_the_vehicle_is_unavoidable():
    pos0 = np.array([10.0, 5.0, DOWN_M])
    inside = [threat((11.0, 5.5, DOWN_M - 0.5), vel=(1.0, 0.0, 0.0), radius_m=3.0)]
    res = label_encounter(pos0, np.array([6.0, 0.0, 0.0]), inside, 0.0, OPEN)
    assert not res.avoidable
    assert res.witness is None
    assert res.best_margin_m < 0.0
    # just outside the sphere + allowance, the same threat moving away is avoidable
    away = [threat((10.0 + 3.0 + TRACKING_ALLOWANCE_M + 2.0, 5.0, DOWN_M), vel=(8.0, 0.0, 0.0), radius_m=3.0)]
    assert label_encounter(pos0, np.array([6.0, 0.0, 0.0]), away, 0.0, OPEN).avoidable


@settings(max_examples=8, deadline=None)
@given(
    v0=st.floats(3.0, 7.2),
    vt=st.floats(0.0, 9.0),
    radius=st.floats(2.0, 6.0),
    fraction=st.floats(0.3, 0.95),
    heading=st.floats(-math.pi, math.pi),
)
def test_a_head_on_threat_inside_the_reachable_bound_is_unavoidable(v0, vt, radius, fraction, heading):
    # The threat comes straight at the vehicle; unaccelerated, the two centres meet at t_c.
    # Any manoeuvre within the limits is at most A_MAX t_c^2 / 2 away from that point then; with
    # t_c chosen so that this is `fraction` of the radius + allowance, the vehicle is inside.
    limit = radius + TRACKING_ALLOWANCE_M
    t_c = math.sqrt(2.0 * fraction * limit / A_MAX)
    gap = t_c * (v0 + vt)
    u = np.array([math.cos(heading), math.sin(heading), 0.0])
    pos0 = np.array([50.0, 50.0, DOWN_M])
    threats = [threat(pos0 + gap * u, vel=-vt * u, radius_m=radius)]
    res = label_encounter(pos0, v0 * u, threats, 0.0, OPEN)
    assert not res.avoidable
    # the same geometry with the threat starting three times farther away can be escaped
    if gap > limit:
        far = [threat(pos0 + 3.0 * gap * u, vel=-vt * u, radius_m=radius)]
        assert 0.5 * A_MAX * (3.0 * t_c) ** 2 > limit  # not excluded by the bound
        res_far = label_encounter(pos0, v0 * u, far, 0.0, OPEN)
        if res_far.avoidable:
            assert_witness_clear(res_far, far, OPEN)


def test_brake_and_reverse_cannot_escape_a_close_head_on_threat():
    # 6 m/s against a 6 m/s threat 15 m ahead (radius 5 + 1 allowance): they meet in 1.25 s,
    # when any manoeuvre has moved at most 0.5 * 2.92 * 1.25^2 = 2.3 m < 6 m from the meeting point.
    pos0 = np.array([0.0, 0.0, DOWN_M])
    threats = [threat((15.0, 0.0, DOWN_M), vel=(-6.0, 0.0, 0.0), radius_m=5.0)]
    res = label_encounter(pos0, np.array([6.0, 0.0, 0.0]), threats, 0.0, OPEN)
    assert not res.avoidable
    assert res.tried == len(manoeuvres(np.array([6.0, 0.0, 0.0])))  # every one was flown
    # 60 m ahead: a sidestep gets out of the way
    threats = [threat((60.0, 0.0, DOWN_M), vel=(-6.0, 0.0, 0.0), radius_m=5.0)]
    res = label_encounter(pos0, np.array([6.0, 0.0, 0.0]), threats, 0.0, OPEN)
    assert res.avoidable
    assert_witness_clear(res, threats, OPEN)


def test_in_a_corridor_the_witness_keeps_off_the_walls():
    # walls 3 m left and right, a static threat (radius 2 + 1 m allowance) 9 m ahead at 6 m/s:
    # too close to stop in front of it, no room to pass it sideways; braking while climbing works
    walls = World(
        [Box((-50.0, 3.0, -40.0), (100.0, 10.0, -5.0)), Box((-50.0, -10.0, -40.0), (100.0, -3.0, -5.0))],
        [-50.0, -20.0, -40.0],
        [100.0, 20.0, -5.0],
    )
    pos0 = np.array([0.0, 0.0, DOWN_M])
    vel0 = np.array([6.0, 0.0, 0.0])
    threats = [threat((9.0, 0.0, DOWN_M), radius_m=2.0)]
    res = label_encounter(pos0, vel0, threats, 0.0, walls)
    assert res.avoidable
    assert_witness_clear(res, threats, walls)
    assert res.witness.pos_ned_m[:, 2].min() < DOWN_M - 1.0  # it climbed
    # without the walls, an earlier manoeuvre of the grid (through a wall) would have done
    in_open = label_encounter(pos0, vel0, threats, 0.0, World([], [-50.0, -20.0, -40.0], [100.0, 20.0, -5.0]))
    assert in_open.avoidable and in_open.tried <= res.tried
    # with the threat 1 m closer, nothing within the limits gets by
    closer = [threat((8.0, 0.0, DOWN_M), radius_m=2.0)]
    assert not label_encounter(pos0, vel0, closer, 0.0, walls).avoidable


def test_the_witness_at_the_edge_of_avoidability_is_still_clear():
    # Bisect the distance of a head-on threat at which the label flips: there the witness only
    # just gets by, so its clearance between the 0.02 s samples is what the sampling slack covers.
    pos0 = np.array([0.0, 0.0, DOWN_M])
    vel0 = np.array([6.0, 0.0, 0.0])

    def label(gap_m: float):
        threats = [threat((gap_m, 0.0, DOWN_M), vel=(-6.0, 0.0, 0.0), radius_m=3.0)]
        return label_encounter(pos0, vel0, threats, 0.0, OPEN), threats

    lo, hi = 8.0, 60.0
    assert not label(lo)[0].avoidable and label(hi)[0].avoidable
    for _ in range(9):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if label(mid)[0].avoidable else (mid, hi)
    res, threats = label(hi)
    assert res.avoidable
    assert_witness_clear(res, threats, OPEN)
    threat_m, _ = flight_margins(res.witness, threats, OPEN, step_s=0.005)
    assert threat_m < 0.5  # it is a tight one


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_threats=st.integers(1, 3), cluttered=st.booleans())
def test_an_avoidable_label_comes_with_a_witness_that_really_stays_clear(seed, n_threats, cluttered):
    rng = np.random.default_rng(seed)
    speed = rng.uniform(0.0, 7.0)
    heading = rng.uniform(-math.pi, math.pi)
    u = np.array([math.cos(heading), math.sin(heading), 0.0])
    pos0 = np.array([0.0, 0.0, DOWN_M])
    threats = []
    for j in range(n_threats):
        t_ca = rng.uniform(1.0, 6.0)
        aim = pos0 + speed * t_ca * u + rng.normal(size=3) * 2.0
        vel = rng.normal(size=3) * rng.uniform(0.0, 5.0)
        vel[2] *= 0.2
        radius = rng.uniform(2.0, 6.0)
        start = aim - vel * t_ca
        if np.linalg.norm(start - pos0) < radius + TRACKING_ALLOWANCE_M + 1.0:
            start = pos0 + (radius + TRACKING_ALLOWANCE_M + 1.0 + 2.0) * rng.normal(size=3) / math.sqrt(3)
        threats.append(threat(start, vel=vel, radius_m=radius, tid=f"t{j}", t_s=5.0))
    world = OPEN
    if cluttered:
        cyl = []
        for _ in range(8):
            c = rng.uniform(-40.0, 40.0, size=2)
            r = rng.uniform(2.0, 6.0)
            if np.linalg.norm(c) > r + 3.0:
                cyl.append(Cylinder(tuple(c), r, -40.0, -5.0))
        world = World(cyl, [-60.0, -60.0, -40.0], [60.0, 60.0, -5.0])
    res = label_encounter(pos0, speed * u, threats, 5.0, world)
    if res.avoidable:
        assert res.best_margin_m >= 0.0
        assert_witness_clear(res, threats, world)
    else:
        assert res.witness is None and res.best_margin_m < 0.0
