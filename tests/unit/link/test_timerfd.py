"""The kernel periodic timer of the setpoint stream, and the work placed right after a send."""

import asyncio
import select
import time

import pytest

from companion.link.setpoints import SLEEP_BACKSTOP_S, SetpointStreamer, hold_position
from companion.link.timerfd import PeriodicTimer
from companion.view.sinks import RecordSinks


def test_the_timer_expires_on_its_absolute_deadlines():
    start = time.monotonic()
    timer = PeriodicTimer.open(start + 0.2, 0.01)
    if timer is None:
        pytest.skip("no timerfd on this platform")
    try:
        assert select.select([timer], [], [], 0.0)[0] == []          # not before its first deadline
        assert select.select([timer], [], [], 1.0)[0] == [timer]
        assert time.monotonic() - start >= 0.1995
        time.sleep(0.035)
        assert timer.expirations() >= 3                             # the first one and those missed
        assert timer.expirations() == 0                             # read: nothing pending
    finally:
        timer.close()


class Sink:
    def __init__(self, sent: list) -> None:
        self.sent, self.lines = sent, []

    def write(self, line_type, **fields) -> None:
        self.lines.append((line_type, len(self.sent)))

    def close(self) -> None:
        pass


def test_paced_record_lines_are_written_right_after_a_send_and_flushed_at_close():
    """In the stream's next housekeeping: right after one of the next sends."""
    async def main():
        sent = []
        streamer = SetpointStreamer(lambda **kw: sent.append(time.monotonic()), hold_position([0, 0, -10], 0.0))
        sink = Sink(sent)
        sinks = RecordSinks([sink])
        sinks.write("header")                                       # not paced: at once
        streamer.start()
        sinks.pace(streamer.call_after_next_tick)
        await asyncio.sleep(0.005)
        before = len(sent)
        sinks.write("sample")
        sinks.write("event")
        assert [line for line, _ in sink.lines] == ["header"]       # waiting for the housekeeping
        await asyncio.sleep(streamer.housekeeping_period_s + 0.05)
        assert [line for line, _ in sink.lines] == ["header", "sample", "event"]
        ticks = round(streamer.housekeeping_period_s / streamer.period_s)
        assert before + 1 <= sink.lines[1][1] <= before + ticks + 1  # right after a send, within one housekeeping period
        sinks.write("summary")
        await streamer.stop()
        sinks.close()
        assert sink.lines[-1][0] == "summary"
        assert streamer.stats().count >= 3

    asyncio.run(main())


def test_sleep_wakes_right_after_a_send_once_the_delay_has_passed():
    async def main():
        sent = []
        streamer = SetpointStreamer(lambda **kw: sent.append(time.monotonic()), hold_position([0, 0, -10], 0.0))
        t0 = time.monotonic()
        await streamer.sleep(0.01)                        # not streaming: a plain sleep
        assert time.monotonic() - t0 >= 0.0095 and not sent
        streamer.start()
        await asyncio.sleep(0.03)
        for delay in (0.005, 0.05, 0.1):
            start = time.monotonic()
            await streamer.sleep(delay)
            woke = time.monotonic()
            house_s = streamer.housekeeping_period_s
            assert woke - start >= delay - 0.5 * house_s   # not before its time (half a housekeeping period early at most)
            assert woke - start <= delay + house_s + 2 * streamer.period_s + 0.05
            assert 0.0 <= woke - sent[-1] < 0.005                # in the wake-up of a send, right after it
        waiting = asyncio.get_running_loop().create_task(streamer.sleep(10.0))
        await asyncio.sleep(0.03)
        await streamer.stop()                                   # stopping wakes every sleeper
        await asyncio.wait_for(waiting, 1.0)
        streamer.start()
        await asyncio.sleep(0.03)
        streamer.set_source(None)                               # nothing sent: no tick wakes it...
        streamer._after_tick = lambda: None                     # ...nor anything after a tick
        start = time.monotonic()
        await streamer.sleep(0.05)                              # the loop's timer does, late
        assert 0.05 + SLEEP_BACKSTOP_S - 0.1 <= time.monotonic() - start <= 0.05 + SLEEP_BACKSTOP_S + 0.5
        await streamer.stop()

    asyncio.run(main())


def test_after_tick_callbacks_run_in_the_sends_wake_up_and_at_stop():
    async def main():
        sent, called = [], []
        streamer = SetpointStreamer(lambda **kw: sent.append(time.monotonic()), hold_position([0, 0, -10], 0.0))
        streamer.call_after_next_tick(lambda: called.append(("idle", len(sent))))
        await asyncio.sleep(0)
        assert called == [("idle", 0)]                           # not streaming: soon
        streamer.start()
        await asyncio.sleep(0.03)
        streamer.call_after_next_tick(lambda: called.append(("next", len(sent))))
        streamer.call_after_next_tick(lambda: 1 / 0)             # a failing callback is logged, no more
        before = len(sent)
        await asyncio.sleep(streamer.housekeeping_period_s + 0.05)
        ticks = round(streamer.housekeeping_period_s / streamer.period_s)
        assert called[1][0] == "next" and before + 1 <= called[1][1] <= before + ticks + 1   # right after a send
        streamer.call_after_next_tick(lambda: called.append(("stop", None)))
        await streamer.stop()
        assert called[-1] == ("stop", None)

    asyncio.run(main())


def test_threads_started_under_normal_priority_do_not_inherit_the_streams_fifo():
    import os
    import threading

    from companion.link.setpoints import normal_priority, raise_stream_priority

    seen = {}

    def stream_thread() -> None:
        if raise_stream_priority() != "fifo":
            seen["skip"] = True
            return
        child = threading.Thread(target=lambda: seen.setdefault("child", os.sched_getscheduler(0)))
        with normal_priority():
            child.start()
            child.join()
        seen["after"] = os.sched_getscheduler(0)

    thread = threading.Thread(target=stream_thread)
    thread.start()
    thread.join()
    if seen.get("skip"):
        pytest.skip("SCHED_FIFO is not allowed here")
    assert (seen["child"], seen["after"]) == (os.SCHED_OTHER, os.SCHED_FIFO)
