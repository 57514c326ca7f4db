"""The real-time driver of the flight's schedule (companion.link.periodic) and the record's
lines written right after a setpoint (the daemon's ``record_write`` row)."""

import asyncio
import time

import pytest

from companion.flight.schedule import Scheduler, Task
from companion.link.periodic import PeriodicDriver
from companion.link.setpoints import SetpointStreamer, hold_position
from companion.view.sinks import RecordSinks


def test_ticks_come_on_absolute_deadlines_and_until_returns_after_the_tick_that_makes_it_true():
    async def main():
        ticks = []
        driver = PeriodicDriver(100.0, ticks.append)
        driver.start()
        assert await driver.until(lambda: len(ticks) >= 20)
        assert len(ticks) == 20  # woken by the tick that made it true
        periods = [b - a for a, b in zip(ticks, ticks[1:])]
        assert sum(periods) / len(periods) == pytest.approx(0.01, abs=0.002)
        await driver.stop()
        assert not driver.running

    asyncio.run(main())


def test_stop_wakes_the_waiters_and_a_failing_tick_does_not_stop_the_driver():
    async def main():
        calls = []

        def tick(now):
            calls.append(now)
            if len(calls) == 2:
                raise RuntimeError("boom")

        driver = PeriodicDriver(100.0, tick)
        driver.start()
        waiting = asyncio.get_running_loop().create_task(driver.until(lambda: False))
        await asyncio.sleep(0.08)
        assert driver.failures == 1 and len(calls) >= 5
        await driver.stop()
        assert await asyncio.wait_for(waiting, 1.0) is False
        assert await driver.until(lambda: False) is False  # not running: at once

    asyncio.run(main())


def test_a_late_tick_skips_the_deadlines_it_missed():
    async def main():
        calls = []

        def tick(now):
            calls.append(now)
            if len(calls) == 3:
                time.sleep(0.055)  # five periods late

        driver = PeriodicDriver(100.0, tick)
        driver.start()
        await driver.until(lambda: len(calls) >= 6)
        await driver.stop()
        assert driver.missed >= 4
        assert all(b - a < 0.07 for a, b in zip(calls, calls[1:]))  # no burst after the late one

    asyncio.run(main())


@pytest.mark.parametrize("rate_hz,spin_s", [(0.0, 0.0), (2000.0, 0.0), (50.0, 0.05)])
def test_bad_rates_are_named(rate_hz, spin_s):
    with pytest.raises(ValueError, match="rate_hz|spin_s"):
        PeriodicDriver(rate_hz, lambda now: None, spin_s=spin_s)


class Sink:
    def __init__(self, sent: list) -> None:
        self.sent, self.lines = sent, []

    def write(self, line_type, **fields) -> None:
        self.lines.append((line_type, len(self.sent)))

    def close(self) -> None:
        pass


def test_paced_record_lines_are_written_right_after_a_setpoint_and_flushed_at_close():
    async def main():
        sent = []
        streamer = SetpointStreamer(lambda **kw: sent.append(time.monotonic()), hold_position([0, 0, -10], 0.0))
        sink = Sink(sent)
        sinks = RecordSinks([sink])
        schedule = Scheduler(
            [Task("setpoints", 50.0, streamer.tick, 2.0), Task("record_write", 10.0, lambda now: sinks.flush(), 3.0)],
            slack_s=0.01,
        )
        driver = PeriodicDriver(50.0, schedule.tick)
        sinks.write("header")  # not paced: at once
        driver.start()
        sinks.pace(True)
        await asyncio.sleep(0.005)
        before = len(sent)
        sinks.write("sample")
        sinks.write("event")
        assert [line for line, _ in sink.lines] == ["header"]  # waiting for the schedule's row
        await asyncio.sleep(0.15)
        assert [line for line, _ in sink.lines] == ["header", "sample", "event"]
        assert before + 1 <= sink.lines[1][1] <= before + 6  # right after a send, within 0.1 s
        sinks.write("summary")
        await driver.stop()
        sinks.close()
        assert sink.lines[-1][0] == "summary"
        assert streamer.stats().count >= 3

    asyncio.run(main())
