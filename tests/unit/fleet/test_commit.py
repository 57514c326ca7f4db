"""Another vehicle's tube in the space-time check, and the delay check's rule (RMADER)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.fleet.commit import fleet_check, refuses
from companion.fleet.peers import VehicleThreat
from companion.threats.decision.spacetime import BatchCheck, check_candidates

coord = st.floats(-30.0, 30.0, allow_nan=False)
step = st.floats(-4.0, 4.0, allow_nan=False)


def vehicle(times, ned, radius=3.1, expires=math.inf) -> VehicleThreat:
    return VehicleThreat(
        "uav2", 2, np.asarray(times, float), np.asarray(ned, float), radius, float(times[0]), 0.0, 0.0, expires
    )


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(coord, coord, coord),
    st.tuples(step, step, step),
    st.tuples(coord, coord, coord),
    st.lists(st.tuples(step, step, step), min_size=1, max_size=12),
    st.sampled_from([0.05, 0.2, 0.5]),
)
def test_never_clear_where_the_exact_closest_approach_to_its_polyline_intrudes(p0, v, c0, moves, check_step_s):
    """The peer's samples every 0.5 s (a polyline); the candidate a straight line: the check at
    any step no longer than the samples' never says clear where a dense scan finds an intrusion."""
    ned = np.cumsum(np.vstack([c0, np.asarray(moves)]), axis=0)
    times = 0.5 * np.arange(len(ned))
    th = vehicle(times, ned)
    tube = th.tube(2.0)
    t = np.arange(0.0, times[-1] + 2.0 + 1e-9, check_step_s)
    pos = np.asarray(p0) + t[:, None] * np.asarray(v)
    res = check_candidates(t, pos[None], [tube], accel_bound_m_s2=0.0)
    dense = np.linspace(t[0], t[-1], 4001)
    gap = np.linalg.norm(np.asarray(p0) + dense[:, None] * np.asarray(v) - th.position_at(dense), axis=1)
    if gap.min() < th.radius_m + 2.0 - 1e-6:
        assert not res.clear[0], (gap.min(), tube.radius_m)


def test_a_head_on_trajectory_conflicts_and_an_offset_one_is_clear():
    class Line:  # a trajectory: north at 4 m/s from the origin
        duration_s = 20.0

        def __init__(self, east):
            self.east = east

        def sample(self, tau):
            tau = np.minimum(np.asarray(tau, float), self.duration_s)
            return (np.stack([4.0 * tau, np.full_like(tau, self.east), np.full_like(tau, -15.0)], axis=1),)

    times = np.arange(0.0, 20.5, 0.5)
    other = vehicle(times, np.stack([80.0 - 4.0 * times, 0 * times, 0 * times - 15.0], axis=1))
    kwargs = dict(horizon_s=15.0, step_s=0.2, inflation_m=2.0)
    head_on = fleet_check(Line(0.0), 0.0, 0.0, [other], **kwargs)
    assert not head_on.clear[0] and head_on.conflicts[0].threat_id == "fleet/uav2"
    assert 7.0 < head_on.conflicts[0].t_s < 10.0  # they meet at 10 s, 5.1 m earlier
    assert fleet_check(Line(8.0), 0.0, 0.0, [other], **kwargs).clear[0]
    # a higher id seen only 4 s ahead: the meeting at 10 s is not ours to avoid yet
    assert fleet_check(Line(0.0), 0.0, 0.0, [vehicle(other.times_s, other.ned_m, expires=4.0)], **kwargs).clear[0]


def _result(clear: bool, clearance: float) -> BatchCheck:
    return BatchCheck(np.array([clear]), np.array([clearance]), np.zeros(1), [None], np.full(1, np.inf))


def test_the_delay_check_refuses_only_what_got_worse_during_the_wait():
    assert not refuses(_result(True, 5.0), _result(True, 3.0))
    assert refuses(_result(True, 5.0), _result(False, -0.1))  # a new conflict appeared
    assert not refuses(_result(False, -1.0), _result(False, -1.2))  # an accepted intrusion, no worse
    assert refuses(_result(False, -1.0), _result(False, -2.0))


def test_a_corner_between_two_check_times_is_not_missed():
    """The peer turns 90 degrees at 0.5 s; the check looks at 0.25 and 0.75 s only. A hovering
    vehicle 0.2 m inside the tube at the corner is outside it on the chord: the corner
    allowance (``bend_m``) must catch it."""
    th = vehicle([0.0, 0.5, 1.0], [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 4.0, 0.0]])
    radius = th.radius_m + 2.0
    here = np.array([4.0, 0.0, 0.0]) + (radius - 0.2) * np.array([1.0, -1.0, 0.0]) / math.sqrt(2.0)
    t = np.array([0.25, 0.75])
    res = check_candidates(t, np.stack([here, here])[None], [th.tube(2.0)], accel_bound_m_s2=0.0)
    assert not res.clear[0]
