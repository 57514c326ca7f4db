"""The kernel periodic timer of the setpoint stream, and the stream thread's priority."""

import select
import time

import pytest

from companion.link.timerfd import PeriodicTimer


def test_the_timer_expires_on_its_absolute_deadlines():
    start = time.monotonic()
    timer = PeriodicTimer.open(start + 0.2, 0.01)
    if timer is None:
        pytest.skip("no timerfd on this platform")
    try:
        assert select.select([timer], [], [], 0.0)[0] == []  # not before its first deadline
        assert select.select([timer], [], [], 1.0)[0] == [timer]
        assert time.monotonic() - start >= 0.1995
        time.sleep(0.035)
        assert timer.expirations() >= 3  # the first one and those missed
        assert timer.expirations() == 0  # read: nothing pending
    finally:
        timer.close()


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
