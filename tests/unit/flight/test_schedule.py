"""The flight's schedule (companion.flight.schedule): tasks at their declared rates, in table
order, at most once per tick, late ticks skipped not burst, failures and overruns counted."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.schedule import ScheduleError, Scheduler, Task


def counting(name, rate_hz, log, budget_ms=1.0):
    return Task(name, rate_hz, lambda now: log.append((name, now)), budget_ms)


def run(scheduler, t_end_s, dt_s):
    k = 0
    while k * dt_s <= t_end_s + 1e-9:
        scheduler.tick(k * dt_s)
        k += 1


def test_tasks_run_at_their_rates_in_table_order():
    log = []
    s = Scheduler([counting("fast", 50.0, log), counting("phase", 10.0, log), counting("slow", 2.0, log)])
    run(s, 1.0 - 1e-6, 0.02)
    counts = {name: sum(1 for n, _ in log if n == name) for name in ("fast", "phase", "slow")}
    assert counts == {"fast": 50, "phase": 10, "slow": 2}
    assert [n for n, t in log if t == 0.0] == ["fast", "phase", "slow"]  # table order


def test_a_late_tick_runs_a_task_once_and_skips_the_missed_times():
    log = []
    s = Scheduler([counting("phase", 10.0, log)])
    s.tick(0.0)
    s.tick(0.55)  # five periods late: once, not five times
    s.tick(0.56)
    s.tick(0.65)
    assert [t for _, t in log] == [0.0, 0.55, 0.65]  # its times stay 0.1 s apart from 0


def test_slack_lets_a_jittering_driver_keep_the_rate():
    log = []
    s = Scheduler([counting("phase", 10.0, log)], slack_s=0.01)
    for k in range(51):  # ticks 0.5 ms early every time
        s.tick(max(k * 0.02 - 0.0005, 0.0))
    assert len(log) == 11


def test_failures_and_overruns_are_counted_and_the_others_still_run():
    log = []
    clock = iter(range(1000))
    s = Scheduler(
        [Task("bad", 10.0, lambda now: 1 / 0, 1.0), counting("good", 10.0, log, budget_ms=0.5)],
        timer=lambda: next(clock) * 1e-3,
    )  # every task "takes" 1 ms
    s.tick(0.0)
    s.tick(0.1)
    report = {row["task"]: row for row in s.report()}
    assert report["bad"]["failures"] == 2 and report["bad"]["runs"] == 2
    assert report["good"]["runs"] == 2 and report["good"]["overruns"] == 2
    assert report["good"]["max_ms"] == pytest.approx(1.0)
    assert len(log) == 2


@pytest.mark.parametrize("field,value", [("rate_hz", 0.0), ("rate_hz", math.nan), ("budget_ms", -1.0)])
def test_a_bad_row_is_named(field, value):
    row = dict(name="monitor", rate_hz=10.0, run=lambda now: None, budget_ms=1.0)
    row[field] = value
    with pytest.raises(ScheduleError, match=f"task 'monitor': {field}"):
        Scheduler([Task(**row)])


def test_names_are_unique_and_rows_can_be_added_and_removed():
    s = Scheduler([counting("a", 1.0, [])])
    with pytest.raises(ScheduleError, match="'a'"):
        s.add(counting("a", 2.0, []))
    s.add(counting("b", 2.0, []))
    s.remove("a")
    assert s.names == ("b",)


@settings(max_examples=60, deadline=None)
@given(rate_hz=st.floats(0.1, 50.0), dt_s=st.sampled_from([0.005, 0.01, 0.02]), t_end_s=st.floats(1.0, 30.0))
def test_a_task_keeps_its_rate_within_a_tick(rate_hz, dt_s, t_end_s):
    log = []
    s = Scheduler([counting("task", rate_hz, log)])
    run(s, t_end_s, dt_s)
    times = [t for _, t in log]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert all(g >= 1.0 / rate_hz - dt_s - 1e-6 for g in gaps)  # on average exactly the rate
    assert len(times) == pytest.approx(t_end_s * rate_hz, abs=1.0)
    assert all(g <= 1.0 / rate_hz + dt_s + 1e-6 for g in gaps)
