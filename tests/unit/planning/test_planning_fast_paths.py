"""Fast paths give the scalar answers: numpy node queries, batched segment tests, goal portals."""

from __future__ import annotations

import importlib
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.planning import CostWeights, GartSettings, MgartSettings, gart, hausdorff_m, mgart
from companion.planning.nearest import NodeGrid
from companion.planning.sampling import RandomStream
from companion.world import Box, Cylinder, Disc, Sphere, World
from companion.world.segments import segments_free_from

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from benchmarks.worlds import make_world  # noqa: E402

LENGTH = GartSettings(cost=CostWeights.length_only())


@pytest.mark.parametrize("dim", [2, 3])
def test_node_arrays_answer_as_the_bucket_grid_in_the_same_order(dim):
    rs = np.random.RandomState(dim)
    pts = [tuple(p) for p in rs.uniform(0, 100, (600, dim)).tolist()]
    grid = NodeGrid((0.0,) * dim, (100.0,) * dim, 40.0, pts)
    for i in range(len(pts)):
        grid.add(i)
        assert grid.arrays.keys[i] == grid._flat(grid._index(pts[i]))  # compiled bucket key
    for i in range(0, 600, 7):
        grid.remove(i)
    queries = [tuple(q) for q in rs.uniform(-5, 105, (60, dim)).tolist()]
    n = grid.arrays.sync(grid.where)
    for q in queries:
        for r in (3.0, 17.5, 40.0):
            scalar = _scalar_within(grid, q, r)
            assert grid.arrays.within(q, r, n) == scalar
        best = min(grid.active, key=lambda i: math.dist(pts[i], q))
        assert grid.arrays.nearest(q, n) == best == grid.nearest(q)


def _scalar_within(grid: NodeGrid, q: tuple, r: float) -> list:
    """The bucket walk of NodeGrid.within, whatever the tree size."""
    import companion.planning.nearest as nearest_module

    saved = nearest_module._VECTOR_FROM
    nearest_module._VECTOR_FROM = 10**9
    try:
        return grid.within(q, r)
    finally:
        nearest_module._VECTOR_FROM = saved


@pytest.mark.parametrize("dim", [2, 3])
def test_batched_segment_test_equals_the_scalar_one(dim):
    rs = np.random.RandomState(10 + dim)
    balls = [(Disc if dim == 2 else Sphere)(c, r) for c, r in zip(rs.uniform(0, 100, (40, dim)), rs.uniform(2, 9, 40))]
    others = [Box((40.0,) * dim, (55.0,) * dim)] + ([Cylinder((70.0, 20.0), 6.0)] if dim == 2 else [])
    for world in (
        World(balls, (0,) * dim, (100,) * dim, margin_m=0.7),
        World(balls + others, (0,) * dim, (100,) * dim, margin_m=0.7),
    ):
        for _ in range(40):
            a = tuple(rs.uniform(-2, 102, dim).tolist())
            ends = [tuple(b) for b in rs.uniform(-2, 102, (25, dim)).tolist()] + [a]
            assert segments_free_from(world, a, ends) == [world.segment_free(a, b) for b in ends]


def test_random_stream_gives_the_generator_sequence_whatever_the_batches():
    stream = RandomStream(np.random.default_rng(3))
    drawn = [stream() for _ in range(20000)]
    assert drawn == np.random.default_rng(3).random(20000).tolist()


def test_mgart_reaches_a_goal_in_a_pocket_eight_times_quickly():
    """3d_dense seed 8: the goal sits behind two spheres (about a quarter of its 20 m ball in view)."""
    b = make_world("3d_dense", 8)
    ms = MgartSettings(gart=LENGTH)
    res = mgart(b.world, b.start, b.goal, 8, rng=np.random.default_rng(8), max_time_s=60.0, settings=ms)
    assert len(res) == 8 and res[0].iterations < 1500
    assert all(b.world.path_free(r.path) for r in res)
    assert all(hausdorff_m(p.path, q.path) >= ms.min_separation_m for i, p in enumerate(res) for q in res[i + 1 :])
    assert [r.cost for r in res] == sorted(r.cost for r in res)


def test_mgart_without_portals_is_the_papers_rule_and_still_finds_distinct_paths():
    b = make_world("2d", 3)
    ms = MgartSettings(gart=LENGTH, portal_zone_m=0.0)
    res = mgart(b.world, b.start, b.goal, 4, rng=np.random.default_rng(3), max_time_s=30.0, settings=ms)
    assert len(res) == 4 and all(b.world.path_free(r.path) for r in res)


def test_large_tree_runs_are_deterministic():
    b = make_world("3d_dense", 2)
    runs = [
        gart(b.world, b.start, b.goal, rng=np.random.default_rng(1), max_iterations=900, settings=LENGTH)
        for _ in range(2)
    ]
    assert runs[0].tree.nodes.shape[0] > 300  # the numpy queries were used
    assert np.array_equal(runs[0].path, runs[1].path) and np.array_equal(runs[0].tree.nodes, runs[1].tree.nodes)


# ---------------------------------------------------------------------- the compiled iteration
def test_python_dist_is_math_dist_to_the_bit():
    from companion.planning.exact_dist import python_dist

    rs = np.random.default_rng(5)
    for dim in (2, 3):
        for scale in (1e-12, 1e-3, 1.0, 40.0, 1e6):
            a = rs.uniform(-scale, scale, (3000, dim))
            b = a + rs.normal(0.0, scale, (3000, dim)) * rs.uniform(0.0, 1.0, (3000, 1))
            b[:10] = a[:10]  # equal points
            for p, q in zip(a.tolist(), b.tolist()):
                assert python_dist(np.array(p), np.array(q)) == math.dist(p, q)


def _python_gart(monkeypatch, *args, **kwargs):
    """gart() through GartSearch's Python iteration and the Python shortcut."""
    gart_module = importlib.import_module("companion.planning.gart")  # (the package exports the function)
    with monkeypatch.context() as m:
        m.setattr(gart_module, "compiled_case", lambda world, settings: False)
        m.setattr(gart_module, "shortcut_case", lambda world, settings: False)
        return gart(*args, **kwargs)


def _same_result(a, b):
    assert a.status == b.status and a.iterations == b.iterations
    assert np.array_equal(a.path, b.path) and a.cost == b.cost and a.length_m == b.length_m
    assert [c for _, c in a.cost_history] == [c for _, c in b.cost_history]
    assert np.array_equal(a.tree.nodes, b.tree.nodes) and np.array_equal(a.tree.parents, b.tree.parents)


@pytest.mark.parametrize("world,seed", [("2d", 0), ("2d", 7), ("3d_dense", 2), ("3d_dense", 8)])
@pytest.mark.parametrize("guidance", [True, False])
def test_compiled_iteration_gives_the_python_iteration_result(monkeypatch, world, seed, guidance):
    from companion.planning.compiled_search import compiled_case

    b = make_world(world, seed)
    settings = GartSettings(cost=CostWeights.length_only(), guidance=guidance)
    assert compiled_case(b.world, settings)
    for budget in ({"stop_at_first": True, "max_time_s": 60.0}, {"max_iterations": 700}):
        rng_c, rng_p = np.random.default_rng(seed), np.random.default_rng(seed)
        compiled = gart(b.world, b.start, b.goal, rng=rng_c, settings=settings, **budget)
        python = _python_gart(monkeypatch, b.world, b.start, b.goal, rng=rng_p, settings=settings, **budget)
        _same_result(compiled, python)
        assert rng_c.random() == rng_p.random()  # the generator is left in the same state
    assert compiled.tree.nodes.shape[0] > 256  # the tree arrays were grown


def test_compiled_iteration_handles_a_straight_line_and_other_settings(monkeypatch):
    world = World([Disc((50.0, 80.0), 5.0)], (0, 0), (100, 100), margin_m=0.5)
    settings = GartSettings(cost=CostWeights.length_only(), informed=False, step_m=7.0, goal_bias=0.3)
    for goal in ((90.0, 10.0), (50.0, 95.0)):  # free straight line; behind the disc
        runs = [
            f(world, (10.0, 10.0), goal, rng=np.random.default_rng(4), max_iterations=300, settings=settings)
            for f in (gart, lambda *a, **k: _python_gart(monkeypatch, *a, **k))
        ]
        _same_result(*runs)


def test_compiled_shortcut_gives_the_python_shortcut_and_cost():
    from companion.planning.cost import path_cost
    from companion.planning.shortcut_kernel import shortcut_and_cost
    from companion.planning.simplify import shortcut_path

    rs = np.random.default_rng(9)
    for dim in (2, 3):
        ball = Disc if dim == 2 else Sphere
        balls = [ball(c, r) for c, r in zip(rs.uniform(0, 100, (25, dim)), rs.uniform(2, 8, 25))]
        world = World(balls, (0,) * dim, (100,) * dim, margin_m=0.5)
        settings = GartSettings(cost=CostWeights.length_only(), max_heading_change_rad=0.6 * math.pi)
        free = [tuple(p) for p in rs.uniform(0, 100, (400, dim)).tolist() if world.point_free(tuple(p))]
        for k in range(60):
            path = np.array(free[k : k + 3 + k % 9])
            if k % 5 == 0:
                path = np.vstack([path[:2], path[1:2], path[2:]])  # a repeated waypoint
            out, cost = shortcut_and_cost(world, path, settings)
            expected = shortcut_path(world, path, settings)
            assert np.array_equal(out, expected) and cost == path_cost(world, expected, settings.cost)


@pytest.mark.parametrize("world,seed", [("2d", 3), ("3d_dense", 8)])
def test_compiled_mgart_gives_the_python_mgart_result(monkeypatch, world, seed):
    b = make_world(world, seed)
    ms = MgartSettings(gart=LENGTH)
    rng_c, rng_p = np.random.default_rng(seed), np.random.default_rng(seed)
    compiled = mgart(b.world, b.start, b.goal, 8, rng=rng_c, max_time_s=60.0, settings=ms)
    with monkeypatch.context() as m:
        m.setattr(importlib.import_module("companion.planning.mgart"), "compiled_case", lambda world, settings: False)
        m.setattr(importlib.import_module("companion.planning.gart"), "shortcut_case", lambda world, settings: False)
        python = mgart(b.world, b.start, b.goal, 8, rng=rng_p, max_time_s=60.0, settings=ms)
    assert len(compiled) == len(python) == 8
    for a, p in zip(compiled, python):
        assert np.array_equal(a.path, p.path) and a.cost == p.cost and a.iterations == p.iterations
    tree_c, tree_p = compiled[0].tree, python[0].tree
    assert np.array_equal(tree_c.nodes, tree_p.nodes) and np.array_equal(tree_c.parents, tree_p.parents)
    assert np.array_equal(tree_c.forbidden, tree_p.forbidden) and tree_c.forbidden.any()
    assert rng_c.random() == rng_p.random()


def _numpy_resample(path: np.ndarray, step_m: float) -> np.ndarray:
    """resample_path as numpy computes it (the reference of the compiled one)."""
    pts = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step_m)))
        pts.extend(a + (np.arange(1, n + 1)[:, None] / n) * (b - a))
    return np.asarray(pts)


def test_compiled_resampling_and_separation_test_answer_as_numpy():
    from companion.planning.hausdorff_kernel import UNSURE, separated_kernel
    from companion.planning.mgart import resample_path, separated

    rs = np.random.default_rng(12)
    unsure = 0
    for dim in (2, 3):
        for k in range(150):
            steps = rs.normal(0.0, 1.0, (3 + k % 6, dim))
            steps *= (20.0 if k % 2 else rs.uniform(1, 30)) / np.linalg.norm(steps, axis=1)[:, None]  # 20 m edges
            a = np.cumsum(steps, axis=0)
            b = a + rs.normal(0.0, 1.0 + k % 7, a.shape)
            ra, rb = resample_path(a, 1.0), resample_path(b, 1.0)
            assert np.array_equal(ra, _numpy_resample(a, 1.0)) and np.array_equal(rb, _numpy_resample(b, 1.0))
            d = np.linalg.norm(ra[:, None, :] - rb[None, :, :], axis=2)
            h = max(d.min(axis=1).max(), d.min(axis=0).max())
            assert hausdorff_m(a, b, 1.0) == h
            for threshold in (h, np.nextafter(h, 0.0), np.nextafter(h, np.inf)):  # numpy decides these
                assert separated(ra, rb, threshold) == (h >= threshold)
            for threshold in (4.0, 0.5 * h, 2.0 * h):
                assert separated(ra, rb, threshold) == (h >= threshold)
                unsure += separated_kernel(ra, rb, threshold) == UNSURE
    assert unsure <= 0.02 * 2 * 150 * 3  # away from the threshold the compiled test decides
