"""Fast paths give the scalar answers: numpy node queries, batched segment tests, goal portals."""

from __future__ import annotations

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
        assert grid.arrays.keys[i] == grid._flat(grid._index(pts[i]))   # compiled bucket key
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
    nearest_module._VECTOR_FROM = 10 ** 9
    try:
        return grid.within(q, r)
    finally:
        nearest_module._VECTOR_FROM = saved


@pytest.mark.parametrize("dim", [2, 3])
def test_batched_segment_test_equals_the_scalar_one(dim):
    rs = np.random.RandomState(10 + dim)
    balls = [(Disc if dim == 2 else Sphere)(c, r) for c, r in zip(rs.uniform(0, 100, (40, dim)), rs.uniform(2, 9, 40))]
    others = [Box((40.0,) * dim, (55.0,) * dim)] + ([Cylinder((70.0, 20.0), 6.0)] if dim == 2 else [])
    for world in (World(balls, (0,) * dim, (100,) * dim, margin_m=0.7),
                  World(balls + others, (0,) * dim, (100,) * dim, margin_m=0.7)):
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
    assert all(hausdorff_m(p.path, q.path) >= ms.min_separation_m for i, p in enumerate(res) for q in res[i + 1:])
    assert [r.cost for r in res] == sorted(r.cost for r in res)


def test_mgart_without_portals_is_the_papers_rule_and_still_finds_distinct_paths():
    b = make_world("2d", 3)
    ms = MgartSettings(gart=LENGTH, portal_zone_m=0.0)
    res = mgart(b.world, b.start, b.goal, 4, rng=np.random.default_rng(3), max_time_s=30.0, settings=ms)
    assert len(res) == 4 and all(b.world.path_free(r.path) for r in res)


def test_large_tree_runs_are_deterministic():
    b = make_world("3d_dense", 2)
    runs = [gart(b.world, b.start, b.goal, rng=np.random.default_rng(1), max_iterations=900, settings=LENGTH)
            for _ in range(2)]
    assert runs[0].tree.nodes.shape[0] > 300  # the numpy queries were used
    assert np.array_equal(runs[0].path, runs[1].path) and np.array_equal(runs[0].tree.nodes, runs[1].tree.nodes)
