"""The one trajectory pipeline: each stage alone, the settings honoured by every input (a
mission leg, a join, a replan, an alternative, an escape), and the static clearance of what it
produces."""

import math
import pickle

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from companion.flight.checker import TrajectoryChecker
from companion.flight.pipeline import PipelineError, PlanBudget, PlanningProblem, TrajectoryPipeline, TrajectoryStatus
from companion.flight.plan import FlightPlanSettings, plan_leg
from companion.flight.stages import (
    G1Smoother,
    G2Smoother,
    GartPlanner,
    MgartPlanner,
    PolylineSmoother,
    SpeedProfileTimer,
)
from companion.mission.model import LocalWaypoint
from companion.planning import GartSettings, MgartSettings
from companion.smoothing import FeasibilitySettings, SmoothingSettings, TrajectoryLimits
from companion.threats.decision import candidates as gen
from companion.threats.decision.alternatives import plan_alternatives
from companion.threats.decision.choice import ReferenceState
from companion.threats.decision.join import join_trajectory
from companion.threats.settings import ThreatSettings
from companion.world import Disc, World

LIMITS = TrajectoryLimits(speed_m_s=6.0)
CORNER = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 40.0]])
OPEN = World([], [-100.0, -100.0], [200.0, 200.0])


def pipeline(method="g2", limits=LIMITS, **kw):
    return TrajectoryPipeline.from_settings(SmoothingSettings(method=method, limits=limits), **kw)


def degrees(trajectory) -> set:
    """Bezier degrees of the pieces of a trajectory's curve (1: straight)."""
    return {p.shape[0] - 1 for p in trajectory.curve.pieces}


# ---------------------------------------------------------------------------- each stage alone
def test_gart_planner_finds_a_path_in_the_problem_world():
    world = World([Disc((20.0, 0.0), 5.0)], [-10.0, -30.0], [50.0, 30.0], 1.0)
    result = GartPlanner(GartSettings(kappa_max_1_m=0.1)).plan(
        PlanningProblem(world, [0.0, 0.0], [40.0, 0.0]),
        PlanBudget(0.5, first_path_s=60.0),  # a cold numba
        rng=np.random.default_rng(0),
    )  # cache compiles in the first search
    assert result.status == "exact" and world.path_free(result.path)


def test_gart_planner_reports_an_invalid_goal_as_a_status():
    world = World([Disc((40.0, 0.0), 5.0)], [-10.0, -30.0], [50.0, 30.0])
    result = GartPlanner().plan(
        PlanningProblem(world, [0.0, 0.0], [40.0, 0.0]), PlanBudget(0.2, attempts=3), rng=np.random.default_rng(0)
    )
    assert result.status == "invalid_goal" and result.path is None


def test_mgart_planner_gives_several_paths():
    world = World([Disc((20.0, 0.0), 5.0)], [-10.0, -30.0], [50.0, 30.0], 1.0)
    results = MgartPlanner(MgartSettings()).plan(
        PlanningProblem(world, [0.0, 0.0], [40.0, 0.0]), PlanBudget(1.0), 2, rng=np.random.default_rng(0)
    )
    assert 1 <= len(results) <= 2 and all(r.status == "exact" for r in results)


@pytest.mark.parametrize(
    "smoother, expected", [(G2Smoother(0.1), {1, 3}), (G1Smoother(0.1), {1, 4}), (PolylineSmoother(), None)]
)
def test_smoothers_give_their_kind_of_curve(smoother, expected):
    curve = smoother.smooth(CORNER, OPEN)
    if expected is None:
        np.testing.assert_array_equal(curve, CORNER)
        assert smoother.turn_kappa_1_m == math.inf
    else:
        assert {p.shape[0] - 1 for p in curve.pieces} == expected


def test_timer_honours_the_limits_and_the_start_speed():
    traj = SpeedProfileTimer().time(G2Smoother(0.1).smooth(CORNER), LIMITS, start_speed_m_s=3.0)
    t = np.linspace(0.0, traj.duration_s, 400)
    speed = np.linalg.norm(traj.sample(t)[1], axis=1)
    assert speed[0] == pytest.approx(3.0, abs=1e-6)
    assert speed.max() <= LIMITS.speed_m_s * (1 + 1e-6) and speed[-1] < 1e-6


def test_checker_reports_a_blocked_curve_and_a_valid_one():
    traj = SpeedProfileTimer().time(CORNER, LIMITS)
    blocked = World([Disc((20.0, 0.0), 2.0)], [-100.0, -100.0], [200.0, 200.0])
    assert TrajectoryChecker().check(traj, OPEN).status is TrajectoryStatus.VALID
    out = TrajectoryChecker().check(traj, blocked)
    assert out.status is TrajectoryStatus.BLOCKED and "static obstacle" in out.reason
    with pytest.raises(PipelineError, match="trajectory"):
        TrajectoryChecker().check(CORNER, OPEN)


class _Stretching:
    """A closed-loop stand-in: stretches a trajectory twice (``check_and_stretch``) or says it is
    infeasible (``check``)."""

    def check_and_stretch(self, trajectory):
        return _Report(True, trajectory.time_scaled(2.0), 2.0)

    def check(self, trajectory):
        return _Report(False, trajectory, 1.0)


class _Report:
    def __init__(self, feasible, trajectory, stretch):
        self.feasible, self.trajectory, self.stretch = feasible, trajectory, stretch
        self.reason = "" if feasible else "max |delta| too large"
        self.initial_max_abs_delta = self.initial_max_tracking_error_m = 0.0


def test_checker_stretches_at_rest_and_only_reports_a_moving_start():
    checker = TrajectoryChecker(_Stretching())
    at_rest = SpeedProfileTimer().time(CORNER, LIMITS)
    out = checker.check(at_rest, OPEN, stretch=True)
    assert out.status is TrajectoryStatus.STRETCHED
    assert out.trajectory.duration_s == pytest.approx(2.0 * at_rest.duration_s)
    assert checker.check(at_rest, OPEN, stretch=False).status is TrajectoryStatus.INFEASIBLE


def test_closed_loop_only_when_the_feasibility_settings_enable_it():
    on = pipeline(feasibility=FeasibilitySettings(), closed_loop=_Stretching())
    off = pipeline(feasibility=FeasibilitySettings(enabled=False), closed_loop=_Stretching())
    assert on.trajectory(CORNER, OPEN).status is TrajectoryStatus.STRETCHED
    assert off.trajectory(CORNER, OPEN).status is TrajectoryStatus.VALID


def test_from_settings_picks_the_smoother_and_pickles():
    for method, cls in (("g2", G2Smoother), ("g1", G1Smoother), ("none", PolylineSmoother)):
        p = pipeline(method)
        assert isinstance(p.smoother, cls)
        assert pickle.loads(pickle.dumps(p)) == p
    assert pipeline("g2").planner.settings.kappa_max_1_m == 0.1  # corners fit G2
    assert pipeline("g1").planner.settings.kappa_max_1_m is None
    with pytest.raises(PipelineError, match="smoothing"):
        TrajectoryPipeline.from_settings(LIMITS)
    with pytest.raises(PipelineError, match="max_time_s"):
        PlanBudget(0.0)
    with pytest.raises(PipelineError, match="goal"):
        PlanningProblem(OPEN, [0.0, 0.0], [1.0, 2.0, 3.0])


# ---------------------------------------------------------------------------- settings everywhere
def situation(pipe, world=OPEN, speed=4.0, goal=(150.0, 0.0)):
    ref = ReferenceState(0.0, np.zeros(2), np.array([speed, 0.0]), np.zeros(2), 0.0)
    return gen.Situation(ref, [], world, world, np.array(goal), ThreatSettings(), pipe)


@pytest.mark.parametrize("method, kinds", [("g2", {1, 3}), ("g1", {1, 4}), ("none", {1})])
def test_a_join_is_smoothed_by_the_configured_method(method, kinds):
    nodes = np.array([[40.0, 30.0], [80.0, 30.0], [120.0, 0.0]])
    traj, poly = join_trajectory(np.zeros(2), np.array([4.0, 0.0]), nodes, world=OPEN, pipeline=pipeline(method))
    assert traj is not None, poly
    assert degrees(traj) == kinds
    assert np.linalg.norm(traj.sample(np.array([0.0]))[1][0] - [4.0, 0.0]) < 0.1  # no setpoint jump


@pytest.mark.parametrize("method, kinds", [("g2", {1, 3}), ("g1", {1, 4}), ("none", {1})])
def test_a_replan_is_smoothed_by_the_configured_method(method, kinds):
    world = World([Disc((75.0, 0.0), 10.0)], [-50.0, -80.0], [200.0, 80.0], 1.0)
    cands = gen.replan_candidates(situation(pipeline(method), world), rng=np.random.default_rng(2), path_id="r")
    assert cands and cands[0].trajectory is not None
    assert degrees(cands[0].trajectory) == kinds


def test_limits_change_every_trajectory():
    slow, fast = TrajectoryLimits(speed_m_s=3.0), TrajectoryLimits(speed_m_s=7.0)
    nodes = np.array([[40.0, 30.0], [120.0, 30.0]])

    def top_speed(traj):
        t = np.linspace(0.0, traj.duration_s, 300)
        return float(np.max(np.linalg.norm(np.atleast_2d(traj.sample(t)[1]), axis=1)))

    for limits in (slow, fast):
        pipe = pipeline(limits=limits)
        join, _ = join_trajectory(np.zeros(2), np.array([2.0, 0.0]), nodes, world=OPEN, pipeline=pipe)
        replan = gen.replan_candidates(situation(pipe, speed=2.0), rng=np.random.default_rng(0), path_id="r")[0]
        assert top_speed(join) == pytest.approx(limits.speed_m_s, rel=0.02)
        assert top_speed(replan.trajectory) == pytest.approx(limits.speed_m_s, rel=0.02)
        assert situation(pipe).escape_speed_m_s() == pytest.approx(
            min(ThreatSettings().evade_speed_m_s, 1.2 * limits.speed_m_s)
        )
    leg_world = World([], [-50.0, -50.0, -60.0], [150.0, 150.0, 0.0])
    goal = LocalWaypoint(seq=1, kind="waypoint", pos_ned_m=np.array([100.0, 20.0, -20.0]), acceptance_radius_m=2.0)
    legs = [
        plan_leg(
            0,
            goal,
            [0.0, 0.0, -20.0],
            leg_world,
            pipeline=pipeline(limits=lim),
            settings=FlightPlanSettings(),
            rng=np.random.default_rng(0),
        )
        for lim in (slow, fast)
    ]
    assert legs[0].trajectory.duration_s > 1.5 * legs[1].trajectory.duration_s


def test_a_mission_leg_honours_the_method():
    leg_world = World([], [-50.0, -50.0, -60.0], [150.0, 150.0, 0.0])
    goal = LocalWaypoint(seq=1, kind="waypoint", pos_ned_m=np.array([100.0, 20.0, -20.0]), acceptance_radius_m=2.0)
    leg = plan_leg(
        0,
        goal,
        [0.0, 0.0, -20.0],
        leg_world,
        pipeline=pipeline("none"),
        settings=FlightPlanSettings(),
        rng=np.random.default_rng(0),
    )
    assert all(degrees(piece) == {1} for piece in leg.trajectory.pieces)


def test_alternatives_come_from_the_pipelines_planner():
    world = World([Disc((60.0, 0.0), 10.0)], [-20.0, -60.0], [140.0, 60.0], 1.0)
    alts = plan_alternatives(
        world,
        [0.0, 0.0],
        [120.0, 0.0],
        2,
        pipeline=pipeline(),
        rng=np.random.default_rng(0),
        max_time_s=1.0,
        spacing_m=2.0,
    )
    assert alts and all(world.path_free(a.path_ned_m) for a in alts)


# ---------------------------------------------------------------------------- geometry
@st.composite
def worlds_and_paths(draw):
    """A random disc world and a random polyline that is collision-free in it."""
    margin = draw(st.floats(0.0, 2.0))
    discs = [
        Disc((draw(st.floats(-60.0, 60.0)), draw(st.floats(-60.0, 60.0))), draw(st.floats(1.0, 8.0)))
        for _ in range(draw(st.integers(1, 6)))
    ]
    world = World(discs, [-100.0, -100.0], [100.0, 100.0], margin)
    nodes = np.array(
        [[draw(st.floats(-90.0, 90.0)), draw(st.floats(-90.0, 90.0))] for _ in range(draw(st.integers(2, 6)))]
    )
    seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    assume(np.all(seg >= 2.0) and world.path_free(nodes))
    return world, nodes


@settings(deadline=None, max_examples=40)
@given(worlds_and_paths(), st.sampled_from(["g2", "g1", "none"]))
def test_a_pipeline_trajectory_keeps_clear_of_the_obstacles(case, method):
    world, path = case
    out = pipeline(method).trajectory(path, world)
    assert out.status is TrajectoryStatus.VALID, out.reason
    traj = out.trajectory
    pos = np.atleast_2d(traj.sample(np.linspace(0.0, traj.duration_s, 500))[0])
    for disc in world.obstacles:
        dist = np.linalg.norm(pos - np.asarray(disc.center_m), axis=1)
        assert np.all(dist >= disc.radius_m + world.margin_m - 1e-6)
