"""Reproducible fast time (issue 23): searches budgeted in iterations, modelled job durations, and
a flight joined in the air from an earlier flight's state."""

from __future__ import annotations

import numpy as np
import pytest

from companion.config import Settings
from companion.flight.fast_time import FastTimeFlight, InlineJobs, JobLatency, VirtualClock
from companion.flight.pipeline import PlanBudget, PlanningProblem, TrajectoryPipeline
from companion.flight.stages import iteration_budget
from companion.planning.mgart import mgart
from companion.threats.decision.kinds import Trigger
from companion.threats.decision.values import Observation
from companion.world import Cylinder, World


def cluttered() -> World:
    rng = np.random.default_rng(4)
    obstacles = [Cylinder((float(x), float(y)), 3.0, -40.0, 0.0) for x, y in rng.uniform(15, 85, size=(12, 2))]
    return World(obstacles, [-5, -5, -40], [105, 105, 0], margin_m=1.0)


def test_iteration_budget_turns_seconds_into_iterations():
    assert iteration_budget(0.5, None) == {"max_time_s": 0.5}
    assert iteration_budget(0.5, 3000.0) == {"max_iterations": 1500}
    assert iteration_budget(1e-6, 3000.0) == {"max_iterations": 1}


def test_mgart_meets_an_iteration_budget_exactly_and_repeats():
    world = cluttered()
    start, goal = np.array([0.0, 0.0, -20.0]), np.array([99.0, 99.0, -20.0])
    runs = [mgart(world, start, goal, 8, rng=np.random.default_rng(1), max_iterations=700) for _ in range(2)]
    assert runs[0][0].iterations <= 700
    assert [r.cost for r in runs[0]] == [r.cost for r in runs[1]]
    assert all(np.array_equal(a.path, b.path) for a, b in zip(*runs))


def test_a_reproducible_pipeline_plans_the_same_paths():
    pipeline = TrajectoryPipeline.for_limits().with_iteration_budgets(2000.0)
    assert pipeline.reproducible and not TrajectoryPipeline.for_limits().reproducible
    problem = PlanningProblem(cluttered(), [0.0, 0.0, -20.0], [99.0, 99.0, -20.0])
    a, b = (pipeline.plan(problem, PlanBudget(0.2), rng=np.random.default_rng(3)) for _ in range(2))
    assert a.status == b.status and np.array_equal(a.path, b.path)


def test_job_latency_by_kind():
    latency = JobLatency(decision_s=0.05, replan_s=0.25, alternatives_s=0.5)
    threat = (None, Observation(1.0, trigger=Trigger.THREAT))
    resume = (None, Observation(1.0, trigger=Trigger.RESUME))
    assert latency.of("alternatives", (), None) == 0.5
    assert latency.of("decision", threat, None) == 0.05
    assert latency.of("decision", resume, None) == 0.25
    assert latency.of("replan", (), None) == 0.25
    with pytest.raises(ValueError, match="decision_s"):
        JobLatency(decision_s=-1.0)


def test_modelled_jobs_are_delivered_at_their_modelled_time():
    clock = VirtualClock(2.0)
    jobs = InlineJobs(clock, latency=JobLatency(alternatives_s=0.3))
    got = []
    jobs.submit("alternatives", lambda: "done", (), got.append, got.append)
    jobs.deliver(2.28)
    assert got == []
    jobs.deliver(2.30)
    assert got == ["done"]


def test_a_job_that_raises_is_handed_to_failed_with_its_exception_when_done():
    clock = VirtualClock(0.0)
    jobs = InlineJobs(clock, latency=JobLatency(replan_s=0.25))
    done, failed = [], []

    def boom():
        raise ValueError("no clear candidate")

    jobs.submit("leg_replan", boom, (), done.append, failed.append)
    jobs.deliver(0.25)
    assert done == [] and len(failed) == 1
    assert isinstance(failed[0], ValueError) and str(failed[0]) == "no clear candidate"


def test_a_flight_joined_in_the_air_flies_on_as_the_whole_flight():
    from companion.flight.plan import plan_leg
    from companion.mission.model import LocalWaypoint

    settings = Settings()
    world = World([], [-20, -20, -40], [120, 60, -5])
    pipeline = TrajectoryPipeline.from_settings(settings.smoothing, settings.planning, iterations_per_s=3000.0)
    leg = plan_leg(
        0,
        LocalWaypoint(1, "waypoint", np.array([80.0, 0.0, -20.0]), 3.0, 0.0, None),
        np.array([0.0, 0.0, -20.0]),
        world,
        pipeline=pipeline,
        settings=settings.flight,
        rng=np.random.default_rng(0),
    )
    whole = FastTimeFlight([leg], settings, world=world, job_latency=JobLatency()).run(max_s=40.0)
    k = int(np.searchsorted(whole.t_s, 6.0))
    joined = FastTimeFlight([leg], settings, world=world, job_latency=JobLatency()).run(
        max_s=40.0, from_s=float(whole.t_s[k]), from_state=whole.states[k]
    )
    assert joined.t_s[0] == pytest.approx(whole.t_s[k])
    n = min(len(joined.t_s), len(whole.t_s) - k)
    error = np.linalg.norm(joined.pos_ned_m[:n] - whole.pos_ned_m[k : k + n], axis=1)
    assert float(error.max()) < 0.05
    assert joined.outcome == whole.outcome
