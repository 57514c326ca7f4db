"""A replan's rounds share one budget (``replan_budget_s``): the 250 ms goal of a decision that replans."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.pipeline import PlanBudget, PlanningProblem, TrajectoryPipeline
from companion.threats.decision.candidates import MIN_ROUND_S, round_budget
from companion.threats.settings import ThreatSettings
from companion.world import Disc, World

seconds = st.floats(0.001, 1.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(seconds, seconds, seconds)
def test_a_round_never_takes_more_than_is_left(left_s, gart_s, first_s):
    budget = round_budget(ThreatSettings(gart_budget_s=gart_s, gart_first_budget_s=first_s), left_s)
    if left_s < MIN_ROUND_S:
        assert budget is None
        return
    assert budget.max_time_s <= gart_s and budget.total_s <= left_s + 1e-12
    assert budget.first_path_s is None or budget.first_path_s <= first_s


def test_a_plan_reports_the_time_of_all_its_searches():
    """A search that times out, then the first-path search: the result counts both (the rounds'
    shared budget is charged for both)."""
    walled = World([Disc((50.0, y), 4.0) for y in np.arange(-48.0, 49.0, 6.0)], [0.0, -50.0], [100.0, 50.0])
    pipeline = TrajectoryPipeline.for_limits().with_iteration_budgets(3000.0)
    budget = PlanBudget(0.01, first_path_s=0.02)
    result = pipeline.plan(
        PlanningProblem(walled, np.array([5.0, 0.0]), np.array([95.0, 0.0])), budget, rng=np.random.default_rng(0)
    )
    assert result.status == "timeout"
    assert result.iterations == 30 + 60
    assert abs(pipeline.search_time_s(result) - 0.03) < 1e-12
