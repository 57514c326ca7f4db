"""Cost of paper eq. 3: energy with climb penalty, threat through clearance, tracking."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.planning import CostWeights, GartSettings, gart, path_cost, path_length_m
from companion.world import Disc, Sphere, World


def test_length_only_cost_is_the_length():
    world = World([Disc((50, 50), 5)], (0, 0), (100, 100))
    path = np.array([[0, 0], [30, 40], [30, 90]])
    assert path_cost(world, path, CostWeights.length_only()) == pytest.approx(50 + 50)
    assert path_length_m(path) == pytest.approx(100)


def test_climb_penalty_counts_only_climbing():
    world = World([], (0, 0, -100), (100, 100, 0))
    up = np.array([[0, 0, -10], [0, 0, -30]])  # climbs 20 m (down decreases)
    down = up[::-1]
    w = CostWeights(climb_penalty=2.0)
    assert path_cost(world, up, w) == pytest.approx(20 + 2 * 20)
    assert path_cost(world, down, w) == pytest.approx(20)


def test_tracking_term_sums_heading_changes():
    world = World([], (0, 0), (100, 100))
    path = np.array([[0, 0], [10, 0], [10, 10], [20, 10]])
    w = CostWeights(energy=1.0, tracking_m_per_rad=3.0)
    assert path_cost(world, path, w) == pytest.approx(30 + 3.0 * math.pi)


def test_threat_term_grows_with_proximity_and_vanishes_beyond_range():
    world = World([Sphere((50, 50, -20), 5)], (0, 0, -50), (100, 100, 0))
    w = CostWeights(threat=10.0, threat_range_m=5.0, climb_penalty=0.0)
    far = np.array([[0, 60.5, -20], [100, 60.5, -20]])  # clearance 5.5 m > range
    near = np.array([[0, 57, -20], [100, 57, -20]])  # clearance 2 m at the closest point
    nearer = np.array([[0, 55.5, -20], [100, 55.5, -20]])  # clearance 0.5 m
    assert path_cost(world, far, w) == pytest.approx(100)
    assert 100 < path_cost(world, near, w) < path_cost(world, nearer, w)


def test_planner_reports_the_cost_of_its_path_with_every_term_on():
    world = World([Disc((40, 40), 10), Disc((70, 65), 8)], (0, 0), (100, 100), margin_m=1)
    weights = CostWeights(threat=2.0, threat_range_m=6.0, tracking_m_per_rad=4.0)
    r = gart(
        world, (5, 5), (95, 95), rng=np.random.default_rng(2), max_iterations=500, settings=GartSettings(cost=weights)
    )
    assert r.solved
    assert r.cost == pytest.approx(path_cost(world, r.path, weights))
    assert r.cost > r.length_m
