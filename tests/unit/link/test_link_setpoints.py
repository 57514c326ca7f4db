"""Setpoint encoding and the SetpointStreamer's schedule (no vehicle needed)."""

import asyncio
import math

import numpy as np
import pytest

from companion.errors import LinkError
from companion.link import (
    Setpoint,
    SetpointStreamer,
    check_url,
    hold_position,
    jitter_stats,
    setpoint_fields,
    setpoint_type_mask,
)
from companion.link.vehicle_commands import mode_number


def test_type_mask_bits():
    assert setpoint_type_mask([0, 0, 0], [0, 0, 0], [0, 0, 0], 0.0) == 2048  # yaw rate ignored
    assert setpoint_type_mask([0, 0, 0], None, None, None) == 0b111111000 | 1024 | 2048
    assert setpoint_type_mask(None, [0, 0, 0], None, 0.5, 0.1) == 0b111000111


def test_setpoint_fields_values():
    f = setpoint_fields(1234, 1, 1, [1, 2, -3], [0.5, 0, 0], [0, 0.1, 0], 0.7)
    assert (f["x"], f["y"], f["z"]) == (1.0, 2.0, -3.0)
    assert (f["vx"], f["afy"], f["yaw"]) == (0.5, 0.1, 0.7)
    assert f["coordinate_frame"] == 1 and f["type_mask"] == 2048 and f["time_boot_ms"] == 1234


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"pos_ned_m": [0, 0]}, "pos_ned_m"),
        ({"vel_ned_m_s": [0, math.nan, 0]}, "vel_ned_m_s"),
        ({"yaw_rad": math.inf}, "yaw_rad"),
    ],
)
def test_bad_setpoints_are_named(kwargs, name):
    with pytest.raises(LinkError, match=name):
        setpoint_fields(0, 1, 1, **kwargs)


@pytest.mark.parametrize(
    "url",
    ["udpin://0.0.0.0:14540", "udpout://127.0.0.1:14555", "tcpout://127.0.0.1:5760", "serial:///dev/ttyUSB0:57600"],
)
def test_good_urls(url):
    assert check_url(url) == url


@pytest.mark.parametrize("url", ["127.0.0.1:14550", "udpin:0.0.0.0:1", "http://x", ""])
def test_bad_urls(url):
    with pytest.raises(LinkError, match="not a MAVSDK URL"):
        check_url(url)


def test_mode_numbers():
    assert mode_number("guided") == 4 and mode_number("LAND") == 9 and mode_number(3) == 3
    with pytest.raises(LinkError, match="unknown flight mode 'HOVER'"):
        mode_number("HOVER")


def test_jitter_stats_of_a_perfect_and_a_late_stream():
    t = np.arange(100) * 0.02
    s = jitter_stats(t, 0.02)
    assert s.count == 100 and s.max_ms == pytest.approx(0.0, abs=1e-9)
    t[50] += 0.005
    s = jitter_stats(t, 0.02)
    assert s.max_ms == pytest.approx(5.0, abs=1e-6) and s.p50_ms == pytest.approx(0.0, abs=1e-6)
    assert math.isnan(jitter_stats([1.0], 0.02).p99_ms)


def run_streamer(streamer, duration_s):
    async def main():
        streamer.start()
        await asyncio.sleep(duration_s)
        await streamer.stop()

    asyncio.run(main())


def test_streamer_sends_at_the_rate_without_drift():
    sent = []
    streamer = SetpointStreamer(lambda **kw: sent.append(kw), hold_position([1, 2, -3], 0.5), rate_hz=50.0)
    run_streamer(streamer, 0.5)
    times = streamer.send_times_s
    assert 3 <= len(sent) <= 27  # never more than one send per period
    assert len(times) == len(sent) == streamer.sent
    # absolute deadlines: the k-th send is never early relative to t0 + k * period
    k = np.arange(len(times))
    assert np.all(times - times[0] >= k * 0.02 - 1e-4)
    assert np.allclose(sent[0]["pos_ned_m"], [1, 2, -3]) and sent[0]["yaw_rad"] == 0.5
    assert np.allclose(sent[0]["vel_ned_m_s"], 0.0)


def test_source_swap_and_failure_repeats_last():
    sent = []
    streamer = SetpointStreamer(lambda **kw: sent.append(kw), hold_position([0, 0, -5]))

    def broken(t):
        raise RuntimeError("boom")

    async def main():
        streamer.start()
        await asyncio.sleep(0.1)
        streamer.set_source(broken)
        await asyncio.sleep(0.1)
        streamer.set_source(lambda t: Setpoint(np.array([9.0, 0, -5]), None, None, None))
        await asyncio.sleep(0.1)
        await streamer.stop()

    asyncio.run(main())
    positions = [tuple(s["pos_ned_m"]) for s in sent]
    assert positions[0] == (0.0, 0.0, -5.0)
    assert positions[-1] == (9.0, 0.0, -5.0)
    assert not streamer.running


def test_no_source_sends_nothing_and_bad_rate_rejected():
    sent = []
    streamer = SetpointStreamer(lambda **kw: sent.append(kw))
    run_streamer(streamer, 0.1)
    assert sent == []
    with pytest.raises(ValueError, match="rate_hz"):
        SetpointStreamer(lambda **kw: None, rate_hz=0.0)


def test_send_errors_do_not_stop_the_stream():
    calls = []

    def flaky(**kw):
        calls.append(1)
        if len(calls) % 2:
            raise OSError("network down")

    streamer = SetpointStreamer(flaky, hold_position([0, 0, -1]))
    run_streamer(streamer, 0.2)
    assert len(calls) >= 6 and streamer.send_errors >= 3 and streamer.sent >= 3


def test_priority_helpers_report_what_they_got():
    import os
    import sys

    from companion.link import raise_stream_priority, restore_normal_priority
    from companion.link.setpoints import STREAM_SWITCH_INTERVAL_S

    interval = sys.getswitchinterval()
    got = raise_stream_priority()
    try:
        assert got in ("fifo", "nice", "normal")
        if got == "fifo":
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
        assert sys.getswitchinterval() == pytest.approx(STREAM_SWITCH_INTERVAL_S)  # GIL waits bounded
    finally:
        restore_normal_priority()
        sys.setswitchinterval(interval)
    if hasattr(os, "sched_getscheduler"):
        assert os.sched_getscheduler(0) == os.SCHED_OTHER


def test_send_now_goes_out_at_once_without_touching_the_jitter_statistics():
    import asyncio

    sent = []

    async def scenario():
        streamer = SetpointStreamer(lambda **kw: sent.append(kw), hold_position([1.0, 2.0, -3.0]), rate_hz=50.0)
        streamer.start()
        await asyncio.sleep(0.11)
        scheduled = len(streamer.send_times_s)
        streamer.send_now()
        after = len(streamer.send_times_s)
        await streamer.stop()
        return scheduled, after, streamer.sent

    scheduled, after, total = asyncio.run(scenario())
    assert scheduled >= 4 and after == scheduled
    assert total == scheduled + 1 and len(sent) == total
