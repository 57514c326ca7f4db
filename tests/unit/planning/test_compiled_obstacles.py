"""The compiled tests and iteration among cylinders and prisms give the Python answers exactly.

Worlds of vertical cylinders (finite and infinite *down* limits), prisms (the same) and balls,
2D and 3D: the compiled point and segment tests equal ``World.point_free`` / ``segment_free``
(and each obstacle's distance equals its own method to the bit); the compiled guidance equals
``Guidance.attract``'s Python scan; GART and M-GART through the compiled iteration give the tree,
paths, costs and iteration counts of the Python iteration for the same seed, with and without
guidance, K_max and climb penalty.
"""

from __future__ import annotations

import contextlib
import importlib
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.planning import CostWeights, GartSettings, MgartSettings, gart, mgart
from companion.planning.compiled_search import compiled_case
from companion.planning.guidance import Guidance
from companion.world import Box, Cylinder, Disc, Prism, Sphere, World
from companion.world import obstacle_kernels as okern
from companion.world.segments import compiled_for, segment_test, segments_free_from

SETTINGS = settings(deadline=None, max_examples=25)
LENGTH = CostWeights.length_only()


def random_world(
    dim: int, seed: int, n_cyl: int = 5, n_prism: int = 3, n_ball: int = 4, size_m: float = 100.0
) -> World:
    """Cylinders and prisms (half of them finite in *down*) and balls, shuffled, in a cube."""
    rs = np.random.default_rng(seed)
    obs = []
    for _ in range(n_cyl):
        c, r = tuple(rs.uniform(0.1, 0.9, 2) * size_m), float(rs.uniform(0.02, 0.08) * size_m)
        top = float(rs.uniform(0.0, 0.6) * size_m)
        obs.append(
            Cylinder(c, r, top, top + float(rs.uniform(0.05, 0.4) * size_m)) if rs.random() < 0.5 else Cylinder(c, r)
        )
    for _ in range(n_prism):
        centre, n = rs.uniform(0.15, 0.85, 2) * size_m, int(rs.integers(3, 7))
        angles, radii = np.sort(rs.uniform(0.0, 2.0 * math.pi, n)), rs.uniform(0.04, 0.12, n) * size_m
        verts = [
            (float(centre[0] + q * math.cos(a)), float(centre[1] + q * math.sin(a))) for a, q in zip(angles, radii)
        ]
        top = float(rs.uniform(0.0, 0.6) * size_m)
        obs.append(
            Prism(verts, top, top + float(rs.uniform(0.05, 0.4) * size_m)) if rs.random() < 0.5 else Prism(verts)
        )
    for _ in range(n_ball):
        obs.append(
            (Disc if dim == 2 else Sphere)(tuple(rs.uniform(0.0, size_m, dim)), float(rs.uniform(0.02, 0.07) * size_m))
        )
    rs.shuffle(obs)
    return World(obs, (0.0,) * dim, (size_m,) * dim, margin_m=1.0)


@contextlib.contextmanager
def python_only():
    """GART, M-GART, guidance and the segment tests all through their Python code."""
    patches = [
        ("companion.planning.gart", "compiled_case"),
        ("companion.planning.gart", "shortcut_case"),
        ("companion.planning.mgart", "compiled_case"),
        ("companion.planning.search", "compiled_for"),
        ("companion.planning.guidance", "compiled_for"),
        ("companion.world.segments", "compiled_for"),
    ]
    saved = []
    try:
        for module_name, name in patches:
            module = importlib.import_module(module_name)
            saved.append((module, name, getattr(module, name)))
            setattr(module, name, lambda *args: False)
        yield
    finally:
        for module, name, value in reversed(saved):
            setattr(module, name, value)


# ---------------------------------------------------------------------------- segment and point tests
@SETTINGS
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10**6), spread=st.sampled_from([3.0, 25.0, 80.0]))
def test_compiled_segment_test_is_world_segment_free(dim, seed, spread):
    world = random_world(dim, seed)
    assert compiled_for(world)
    free = segment_test(world)
    rs = np.random.default_rng(seed + 1)
    a = rs.uniform(-2.0, 102.0, (200, dim))
    b = a + rs.normal(0.0, spread, (200, dim))
    b[:5] = a[:5]  # zero-length segments
    expected = [world.segment_free(tuple(p), tuple(q)) for p, q in zip(a.tolist(), b.tolist())]
    assert [free(tuple(p), tuple(q)) for p, q in zip(a.tolist(), b.tolist())] == expected
    assert segments_free_from(world, tuple(a[0].tolist()), [tuple(q) for q in b.tolist()]) == [
        world.segment_free(tuple(a[0].tolist()), tuple(q)) for q in b.tolist()
    ]
    space = okern.space_of(world)
    assert [okern.point_clear(p, space) for p in a] == [world.point_free(tuple(p)) for p in a.tolist()]


@SETTINGS
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10**6))
def test_each_obstacle_distance_is_its_own_method_to_the_bit(dim, seed):
    world = random_world(dim, seed, n_ball=0)
    space = okern.space_of(world)
    rs = np.random.default_rng(seed + 2)
    a = rs.uniform(-10.0, 110.0, (40, dim))
    b = a + rs.normal(0.0, 30.0, (40, dim))
    for j, ob in enumerate(world.non_ball_obstacles):
        for p, q in zip(a, b):
            assert okern._other_segment_distance(j, p, q, space) == ob.segment_distance(tuple(p), tuple(q))
            assert okern.other_sdf(j, p, space) == ob.sdf(tuple(p))


def test_segments_leaving_a_finite_cylinder_are_measured_by_the_same_search():
    cyl = Cylinder((50.0, 50.0), 5.0, 20.0, 40.0)
    world = World([cyl], (0.0,) * 3, (100.0,) * 3, margin_m=0.5)
    space = okern.space_of(world)
    rs = np.random.default_rng(3)
    for _ in range(300):  # from above or below the cylinder to across it: golden-section pieces
        a = np.array([*rs.uniform(40.0, 60.0, 2), rs.uniform(0.0, 20.0)])
        b = np.array([*rs.uniform(40.0, 60.0, 2), rs.uniform(10.0, 60.0)])
        assert okern._other_segment_distance(0, a, b, space) == cyl.segment_distance(tuple(a), tuple(b))


def test_boxes_keep_the_python_tests():
    world = World([Box((10.0, 10.0), (20.0, 20.0)), Cylinder((50.0, 50.0), 4.0)], (0.0, 0.0), (100.0, 100.0))
    assert not compiled_for(world) and not okern.supported(world)
    assert segment_test(world) == world.segment_free
    with pytest.raises(ValueError, match="Box"):
        okern.space_of(world)


# ---------------------------------------------------------------------------- guidance
@SETTINGS
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10**6))
def test_compiled_guidance_is_the_python_scan(dim, seed):
    world = random_world(dim, seed)
    gs = GartSettings(influence_m=8.0, max_guidance_m=9.0, goal_gain_m=1.5)
    goal = (95.0,) * dim
    compiled = Guidance(world, goal, gs)
    assert compiled.compiled
    with python_only():
        python = Guidance(world, goal, gs)
    assert not python.compiled
    rs = np.random.default_rng(seed + 3)
    for p in rs.uniform(0.0, 100.0, (100, dim)).tolist():
        assert compiled.attract(tuple(p)) == python.attract(tuple(p))


# ---------------------------------------------------------------------------- GART and M-GART
def _same(a, b) -> None:
    assert a.status == b.status and a.iterations == b.iterations
    assert (a.path is None and b.path is None) or (np.array_equal(a.path, b.path) and a.cost == b.cost)
    assert [c for _, c in a.cost_history] == [c for _, c in b.cost_history]
    assert np.array_equal(a.tree.nodes, b.tree.nodes) and np.array_equal(a.tree.parents, b.tree.parents)


CASES = [  # dim, guidance, K_max, climb penalty
    (2, True, None, 0.0),
    (2, False, 0.15, 0.0),
    (3, True, None, 1.0),
    (3, False, None, 0.0),
    (3, True, 0.1, 1.0),
]


def blocked_world(dim: int, seed: int) -> World:
    """:func:`random_world` with an unbounded cylinder on the diagonal and a finite one beside it."""
    extra = [Cylinder((50.0, 50.0), 8.0), Cylinder((70.0, 80.0), 6.0, 30.0, 90.0)]
    return random_world(dim, seed, n_cyl=5, n_prism=2, n_ball=3).with_threats(extra)


def _settings(guidance: bool, kappa: float | None, climb: float) -> GartSettings:
    return GartSettings(
        step_m=12.0,
        guidance=guidance,
        kappa_max_1_m=kappa,
        cost=CostWeights(energy=1.0, climb_penalty=climb, threat=0.0, tracking_m_per_rad=0.0),
    )


@contextlib.contextmanager
def corner_tests_counted(counts: list):
    """The Python corner rule's segment tests, their refusals counted in ``counts``."""
    simplify = importlib.import_module("companion.planning.simplify")
    original = simplify.segment_test

    def counting(world):
        free = original(world)

        def test(a, b):
            ok = free(a, b)
            counts.append(ok)
            return ok

        return test

    simplify.segment_test = counting
    try:
        yield
    finally:
        simplify.segment_test = original


@pytest.mark.parametrize("dim,guidance,kappa,climb", CASES)
def test_compiled_gart_is_the_python_gart(dim, guidance, kappa, climb):
    world = blocked_world(dim, 40 + dim)
    start, goal = (2.0,) * dim, (97.0,) * dim
    gs = _settings(guidance, kappa, climb)
    assert compiled_case(world, gs) and world.point_free(start) and world.point_free(goal)
    assert not world.segment_free(start, goal)
    corner_tests: list = []
    for budget in ({"max_iterations": 900}, {"max_iterations": 3000, "stop_at_first": True}):
        rng_c, rng_p = np.random.default_rng(dim), np.random.default_rng(dim)
        compiled = gart(world, start, goal, rng=rng_c, settings=gs, **budget)
        with python_only(), corner_tests_counted(corner_tests):
            python = gart(world, start, goal, rng=rng_p, settings=gs, **budget)
        _same(compiled, python)
        assert compiled.status == "exact" and compiled.iterations > 0
        assert rng_c.random() == rng_p.random()
    if kappa is not None:  # K_max's corner clearance refused some corners
        assert not all(corner_tests)


@pytest.mark.parametrize("dim,guidance,kappa,climb", CASES[::2])
def test_compiled_mgart_is_the_python_mgart(dim, guidance, kappa, climb):
    world = blocked_world(dim, 50 + dim)
    start, goal = (2.0,) * dim, (97.0,) * dim
    gs = _settings(guidance, kappa, climb)
    ms = MgartSettings(gart=gs)
    assert compiled_case(world, gs)
    rng_c, rng_p = np.random.default_rng(5), np.random.default_rng(5)
    compiled = mgart(world, start, goal, 4, rng=rng_c, settings=ms, max_iterations=1500)
    with python_only():
        python = mgart(world, start, goal, 4, rng=rng_p, settings=ms, max_iterations=1500)
    assert len(compiled) == len(python) >= 2
    for a, p in zip(compiled, python):
        assert np.array_equal(a.path, p.path) and a.cost == p.cost and a.iterations == p.iterations
    tree_c, tree_p = compiled[0].tree, python[0].tree
    assert np.array_equal(tree_c.nodes, tree_p.nodes) and np.array_equal(tree_c.parents, tree_p.parents)
    assert np.array_equal(tree_c.forbidden, tree_p.forbidden)
    assert rng_c.random() == rng_p.random()


def test_a_free_straight_line_with_a_climb_costs_the_same():
    world = random_world(3, 7, n_cyl=0, n_prism=1, n_ball=0)
    gs = GartSettings(cost=CostWeights(energy=2.0, climb_penalty=1.5, threat=0.0, tracking_m_per_rad=0.0))
    start, goal = (1.0, 1.0, 90.0), (3.0, 2.0, 60.0)  # climbing 30 m
    assert world.segment_free(start, goal) and compiled_case(world, gs)
    compiled = gart(world, start, goal, rng=np.random.default_rng(0), settings=gs, max_iterations=50)
    with python_only():
        python = gart(world, start, goal, rng=np.random.default_rng(0), settings=gs, max_iterations=50)
    _same(compiled, python)
    assert compiled.cost_history[0][1] == pytest.approx(2.0 * (math.dist(start, goal) + 1.5 * 30.0))
