"""GART and M-GART: valid paths, statuses instead of exceptions, determinism, distinct sorted paths."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.errors import PlanningError
from companion.planning import (
    CostWeights,
    GartSettings,
    MgartSettings,
    gart,
    hausdorff_m,
    mgart,
    path_cost,
    path_length_m,
    shortcut_path,
)
from companion.planning.simplify import CornerRule
from companion.world import Box, Cylinder, Disc, Prism, Sphere, World

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from benchmarks.worlds import make_world  # noqa: E402

LENGTH = GartSettings(cost=CostWeights.length_only())


def exact_path_free(world: World, path: np.ndarray) -> bool:
    """Independent exact check: every segment against every obstacle, no index."""
    if not world.contains(path).all():
        return False
    for a, b in zip(path[:-1], path[1:]):
        for ob in world.obstacles:
            if ob.segment_distance(tuple(a), tuple(b)) <= world.margin_m:
                return False
    return True


def heading_changes(path: np.ndarray) -> np.ndarray:
    d = np.diff(path, axis=0)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.arccos(np.clip(np.sum(u[:-1] * u[1:], axis=1), -1, 1))


@pytest.mark.parametrize("name, seed", [("2d", 0), ("2d", 3), ("3d_dense", 1), ("3d_dense", 7)])
def test_gart_paths_are_collision_free_and_end_at_start_and_goal(name, seed):
    b = make_world(name, seed)
    r = gart(b.world, b.start, b.goal, rng=np.random.default_rng(seed), max_iterations=600, settings=LENGTH)
    assert r.status == "exact"
    assert np.allclose(r.path[0], b.start) and np.allclose(r.path[-1], b.goal)
    assert exact_path_free(b.world, r.path)
    assert r.length_m == pytest.approx(path_length_m(r.path))
    assert r.cost == pytest.approx(r.length_m)  # length-only weights
    assert r.length_m >= np.linalg.norm(b.goal - b.start)
    assert r.tree.nodes.shape[1] == b.world.dim and r.tree.parents[0] == -1
    assert r.time_to_first_s is not None and r.time_to_first_s <= r.elapsed_s
    costs = [c for _, c in r.cost_history]
    assert costs == sorted(costs, reverse=True)


def test_anytime_improvement_does_not_make_the_path_worse():
    b = make_world("2d", 2)
    first = gart(b.world, b.start, b.goal, rng=np.random.default_rng(5), stop_at_first=True, settings=LENGTH)
    later = gart(b.world, b.start, b.goal, rng=np.random.default_rng(5), max_iterations=1500, settings=LENGTH)
    assert later.cost <= first.cost_history[0][1] + 1e-9
    assert later.iterations == 1500 and first.iterations < 1500


def test_fixed_seed_gives_the_same_path():
    b = make_world("3d_dense", 4)
    runs = [gart(b.world, b.start, b.goal, rng=np.random.default_rng(42), max_iterations=400) for _ in range(2)]
    assert np.array_equal(runs[0].path, runs[1].path)
    assert np.array_equal(runs[0].tree.nodes, runs[1].tree.nodes)
    other = gart(b.world, b.start, b.goal, rng=np.random.default_rng(43), max_iterations=400)
    assert not np.array_equal(other.tree.nodes, runs[0].tree.nodes)


def test_mixed_obstacles_with_margin_and_default_cost():
    world = World(
        [
            Box((20, 0, -40), (30, 60, 0)),
            Cylinder((60, 40), 8, -50, 0),
            Prism([(40, 70), (80, 70), (60, 95)], -45, -5),
            Sphere((80, 20, -20), 10),
        ],
        (0, 0, -50),
        (100, 100, -2),
        margin_m=1.5,
    )
    start, goal = (5, 5, -10), (95, 95, -20)
    r = gart(world, start, goal, rng=np.random.default_rng(0), max_time_s=2.0, max_iterations=1500)
    assert r.solved and exact_path_free(world, r.path)
    assert r.cost == pytest.approx(path_cost(world, r.path, GartSettings().cost))
    assert r.cost >= r.length_m - 1e-9  # the climb penalty only adds


def test_heading_limit_from_kappa_max_holds_at_every_corner():
    b = make_world("2d", 1)
    settings = GartSettings(kappa_max_1_m=0.2, cost=CostWeights.length_only())
    r = gart(b.world, b.start, b.goal, rng=np.random.default_rng(1), max_iterations=1500, settings=settings)
    assert r.solved and exact_path_free(b.world, r.path)
    rule = CornerRule(settings)
    d = np.diff(r.path, axis=0)
    lengths = np.linalg.norm(d, axis=1)
    u = d / lengths[:, None]
    for k in range(len(u) - 1):
        assert rule.ok(tuple(u[k]), lengths[k], tuple(u[k + 1]), lengths[k + 1])
    # the G2 corner length of every corner fits into half the shorter edge
    beta = heading_changes(r.path) / 2
    need = 1.1228 * np.sin(beta) / (0.2 * np.cos(beta) ** 2)
    assert np.all(need <= 0.5 * np.minimum(lengths[:-1], lengths[1:]) + 1e-9)


def test_max_heading_change_for_matches_the_g2_corner_formula():
    s = GartSettings(kappa_max_1_m=0.1, max_heading_change_rad=math.pi)
    gamma = s.max_heading_change_for(20.0)
    beta = gamma / 2
    assert 1.1228 * math.sin(beta) / (0.1 * math.cos(beta) ** 2) == pytest.approx(0.5 * 20.0)


def test_start_or_goal_in_collision_is_a_status_not_an_exception():
    world = World([Disc((50, 50), 10)], (0, 0), (100, 100), margin_m=1)
    rng = np.random.default_rng(0)
    assert gart(world, (50, 55), (90, 90), rng=rng).status == "invalid_start"
    assert gart(world, (5, 5), (59.5, 50), rng=rng).status == "invalid_goal"
    res = mgart(world, (5, 5), (50, 50), 3, rng=rng)
    assert len(res) == 1 and res[0].status == "invalid_goal" and res[0].path is None


def test_unreachable_goal_times_out_with_a_tree():
    world = World([Box((40, 0), (45, 100))], (0, 0), (100, 100))
    r = gart(world, (5, 5), (90, 90), rng=np.random.default_rng(0), max_iterations=300)
    assert r.status == "timeout" and r.path is None and math.isinf(r.cost)
    assert r.iterations == 300 and r.tree.size > 1
    assert np.all(r.tree.nodes[:, 0] < 40)


def test_straight_line_when_nothing_is_in_the_way():
    world = World([Disc((50, 10), 3)], (0, 0), (100, 100))
    r = gart(world, (0, 50), (100, 60), rng=np.random.default_rng(0), stop_at_first=True)
    assert r.solved and r.path.shape == (2, 2)
    assert r.length_m == pytest.approx(math.hypot(100, 10))


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(start=(0, math.nan)), "start"),
        (dict(goal=(0, math.inf)), "goal"),
        (dict(goal=(101, 50)), "goal"),
        (dict(start=(-1, 0)), "start"),
        (dict(start=(0, 0, 0)), "start"),
        (dict(goal=[[1, 2]]), "goal"),
        (dict(rng=np.random.RandomState(0)), "rng"),
        (dict(max_time_s=0), "max_time_s"),
        (dict(max_iterations=-5), "max_iterations"),
        (dict(world="paper_2d.toml"), "world"),
        (dict(settings=MgartSettings()), "settings"),
    ],
)
def test_bad_arguments_raise_planning_error_naming_them(kwargs, key):
    args = dict(world=World([], (0, 0), (100, 100)), start=(0, 0), goal=(99, 99), rng=np.random.default_rng(0))
    args.update(kwargs)
    world, start, goal = args.pop("world"), args.pop("start"), args.pop("goal")
    with pytest.raises(PlanningError, match=key):
        gart(world, start, goal, **args)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(step_m=0), "step_m"),
        (dict(step_m=-3), "step_m"),
        (dict(goal_bias=1.5), "goal_bias"),
        (dict(kappa_max_1_m=0.0), "kappa_max_1_m"),
        (dict(max_rewire_radius_m=-1), "max_rewire_radius_m"),
        (dict(max_heading_change_rad=4.0), "max_heading_change_rad"),
    ],
)
def test_bad_settings_raise_planning_error_naming_the_field(kwargs, key):
    with pytest.raises(PlanningError, match=key):
        GartSettings(**kwargs)
    with pytest.raises(PlanningError, match="energy"):
        CostWeights(energy=0)
    with pytest.raises(PlanningError, match="min_separation_m"):
        MgartSettings(min_separation_m=0)


@pytest.mark.parametrize("name, seed", [("2d", 0), ("3d_dense", 2)])
def test_mgart_paths_are_free_distinct_and_sorted(name, seed):
    b = make_world(name, seed)
    settings = MgartSettings(gart=LENGTH)
    res = mgart(b.world, b.start, b.goal, 5, rng=np.random.default_rng(seed), max_time_s=10.0, settings=settings)
    assert len(res) == 5 and all(r.status == "exact" for r in res)
    costs = [r.cost for r in res]
    assert costs == sorted(costs)
    for r in res:
        assert exact_path_free(b.world, r.path)
        assert np.allclose(r.path[0], b.start) and np.allclose(r.path[-1], b.goal)
    for i in range(len(res)):
        for j in range(i + 1, len(res)):
            assert hausdorff_m(res[i].path, res[j].path, 1.0) >= settings.min_separation_m
    assert res[0].tree.forbidden.any()


def test_mgart_rejects_bad_k():
    world = World([], (0, 0), (10, 10))
    for k in (0, -1, 2.5, True):
        with pytest.raises(PlanningError, match="k"):
            mgart(world, (0, 0), (9, 9), k, rng=np.random.default_rng(0))


def test_shortcut_never_costs_more_and_stays_free():
    b = make_world("2d", 6)
    raw_settings = GartSettings(
        cost=CostWeights.length_only(), simplify=GartSettings().simplify.__class__(enabled=False)
    )
    r = gart(b.world, b.start, b.goal, rng=np.random.default_rng(6), stop_at_first=True, settings=raw_settings)
    short = shortcut_path(b.world, r.path, LENGTH)
    assert exact_path_free(b.world, short)
    assert path_length_m(short) <= r.length_m + 1e-9
    assert np.array_equal(short[0], r.path[0]) and np.array_equal(short[-1], r.path[-1])


def test_hausdorff_of_offset_lines():
    a = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert hausdorff_m(a, a + [0.0, 3.0]) == pytest.approx(3.0)
    assert hausdorff_m(a, a) == 0.0


@pytest.mark.parametrize("seed", [0, 4])
def test_g2_smoother_honours_kappa_max_on_paths_planned_with_it(seed):
    smoothing = pytest.importorskip("companion.smoothing")
    world = World(
        [Disc(c, r) for c, r in [((30, 30), 8), ((60, 55), 10), ((35, 75), 7), ((75, 20), 6)]],
        (0, 0),
        (100, 100),
        margin_m=1.0,
    )
    settings = GartSettings(kappa_max_1_m=0.15)
    r = gart(world, (2, 2), (98, 98), rng=np.random.default_rng(seed), max_iterations=800, settings=settings)
    assert r.solved
    curve = smoothing.smooth_g2(r.path, 0.15, world=world)
    assert curve.kappa_ok and curve.max_curvature_1_m <= 0.15 * 1.001
    s = np.linspace(0, curve.length_m, 2000)
    assert world.is_free(curve.evaluate(s)).all()


@pytest.mark.parametrize("n_extra", [0, 200])  # 200: guidance looks obstacles up per grid cell
def test_attract_repels_from_inside_attracts_outside_and_pulls_to_goal(n_extra):
    from companion.planning.gart import GartSearch

    rs = np.random.RandomState(0)
    extra = [Disc(c, 0.3) for c in rs.uniform(0, 20, (n_extra, 2))]  # far corner, out of reach
    world = World([Disc((50, 50), 10)] + extra, (0, 0), (100, 100), margin_m=1.0)
    s = GartSettings(goal_gain_m=0.0, repel_offset_m=0.5, obstacle_gain_m2=4.0, influence_m=6.0, max_guidance_m=20.0)
    search = GartSearch(world, (90.0, 90.0), (95.0, 95.0), s, np.random.default_rng(0))
    inside = search.attract((50.0, 55.0))  # 5 m from the centre: clearance -6 m
    assert inside == pytest.approx((50.0, 50.0 + 11.5))
    near = search.attract((50.0, 65.0))  # clearance 4 m: moves 4/4 = 1 m towards it
    assert near == pytest.approx((50.0, 64.0))
    close = search.attract((50.0, 62.0))  # clearance 1 m: k/c = 4 capped at c/2
    assert close == pytest.approx((50.0, 61.5))
    far = search.attract((80.0, 50.0))  # beyond the influence distance
    assert far == pytest.approx((80.0, 50.0))
    s_goal = GartSettings(goal_gain_m=2.0)
    pulled = GartSearch(world, (90.0, 90.0), (80.0, 90.0), s_goal, np.random.default_rng(0)).attract((80.0, 80.0))
    assert pulled == pytest.approx((80.0, 82.0))


def test_many_obstacles_are_planned_through():
    rs = np.random.RandomState(1)
    centers = rs.uniform(5, 95, (400, 2))
    keep = [c for c in centers if np.linalg.norm(c) > 5 and np.linalg.norm(c - 99) > 5]
    world = World([Disc(c, 1.0) for c in keep], (0, 0), (100, 100), margin_m=0.5)
    r = gart(world, (0, 0), (99, 99), rng=np.random.default_rng(0), max_iterations=1500, settings=LENGTH)
    assert r.solved and exact_path_free(world, r.path)


def test_start_equal_to_goal_gives_a_two_point_path():
    world = World([Disc((50, 50), 5)], (0, 0), (100, 100))
    r = gart(world, (10, 10), (10, 10), rng=np.random.default_rng(0), stop_at_first=True)
    assert r.solved and r.path.shape == (2, 2) and r.length_m == 0.0
