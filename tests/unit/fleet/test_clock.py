"""The clock offset between two companions (NTP's exchange over their trajectory messages)."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from companion.fleet.clock_sync import ClockOffset, exchange

delay = st.floats(0.0, 0.5)


@settings(max_examples=300, deadline=None)
@given(st.floats(-100.0, 100.0), delay, delay, st.floats(0.0, 1.0), st.floats(0.0, 1e6))
def test_the_true_offset_lies_within_half_the_round_trip(offset, there, back, hold, t1):
    t2 = t1 + there + offset  # their clock = ours + offset
    t3 = t2 + hold
    t4 = t3 - offset + back
    est, rtt = exchange(t1, t2, t3, t4)
    assert math.isclose(rtt, there + back, abs_tol=1e-6)
    assert abs(est - offset) <= rtt / 2.0 + 1e-6


@settings(max_examples=100, deadline=None)
@given(st.floats(-10.0, 10.0), st.lists(st.tuples(delay, delay), min_size=1, max_size=20))
def test_the_exchange_with_the_shortest_round_trip_is_kept(offset, delays):
    clock = ClockOffset(window_s=1e9)
    for k, (there, back) in enumerate(delays):
        t1 = 10.0 * k
        clock.observe(t1, t1 + there + offset, t1 + there + offset + 0.2, t1 + there + 0.2 + back)
    assert math.isclose(clock.bound_s, min(a + b for a, b in delays) / 2.0, abs_tol=1e-6)
    assert abs(clock.offset_s - offset) <= clock.bound_s + 1e-6


def test_before_any_exchange_the_offset_is_zero_and_unbounded():
    clock = ClockOffset()
    assert clock.offset_s == 0.0 and math.isinf(clock.bound_s)


def test_contradictory_stamps_and_old_exchanges_are_dropped():
    clock = ClockOffset(window_s=30.0)
    clock.observe(0.0, 5.0, 5.0, -1.0)  # a negative round trip: ignored
    assert math.isinf(clock.bound_s)
    clock.observe(0.0, 1.0, 1.1, 0.2)  # rtt 0.1
    clock.observe(100.0, 101.0, 101.1, 100.6)  # rtt 0.5, 100 s later: the first is forgotten
    assert math.isclose(clock.bound_s, 0.25)
