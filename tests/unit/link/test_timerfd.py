"""The kernel periodic timer of the setpoint stream, and the work placed right after a send."""

import asyncio
import select
import time

import pytest

from companion.link.setpoints import SetpointStreamer, hold_position
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
    async def main():
        sent = []
        streamer = SetpointStreamer(lambda **kw: sent.append(time.monotonic()), hold_position([0, 0, -10], 0.0))
        sink = Sink(sent)
        sinks = RecordSinks([sink])
        sinks.write("header")                                       # not paced: at once
        streamer.start()
        sinks.pace(streamer.after_next_tick)
        await asyncio.sleep(0.005)
        before = len(sent)
        sinks.write("sample")
        sinks.write("event")
        assert [line for line, _ in sink.lines] == ["header"]       # waiting for the next send
        await asyncio.sleep(0.05)
        assert [line for line, _ in sink.lines] == ["header", "sample", "event"]
        assert sink.lines[1][1] == before + 1                       # right after the next send
        sinks.write("summary")
        await streamer.stop()
        sinks.close()
        assert sink.lines[-1][0] == "summary"
        assert streamer.stats().count >= 3

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
