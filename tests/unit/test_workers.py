"""companion.workers: planning in worker processes (values in, values out)."""

from __future__ import annotations

import asyncio
import pickle

import numpy as np

from companion.flight.reference import ReferenceTable
from companion.workers import PlanningWorkers
from companion.world import World


def draw(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.random(n)


def test_a_world_pickles_and_answers_the_same():
    world = World([], np.zeros(2), np.full(2, 10.0), margin_m=0.5)
    copy = pickle.loads(pickle.dumps(world))
    assert copy.dim == world.dim and copy.point_free((5.0, 5.0)) and not copy.point_free((20.0, 5.0))


def test_process_workers_return_what_threads_return():
    """Values in, values out: the same function on the same arguments gives the same result."""

    async def fly(kind: str):
        workers = PlanningWorkers(kind, workers=1)
        try:
            await workers.start()
            return await workers.run(draw, np.random.default_rng(3), 2)
        finally:
            workers.shutdown()

    np.testing.assert_array_equal(asyncio.run(fly("thread")), asyncio.run(fly("process")))


class Line:
    """A straight trajectory at constant acceleration along north, yaw turning at 0.5 rad/s."""

    duration_s = 3.0

    def sample(self, t):
        t = np.asarray(t, dtype=float)
        pos = np.stack([0.5 * t**2, 0 * t, 0 * t], axis=1)
        return pos, np.stack([t, 0 * t, 0 * t], axis=1), np.stack([1 + 0 * t, 0 * t, 0 * t], axis=1)

    def yaw_rad(self, t):
        return 3.0 + 0.5 * np.asarray(t, dtype=float)

    def yaw_rate_rad_s(self, t):
        return 0.5 + 0 * np.asarray(t, dtype=float)


def test_the_reference_table_interpolates_a_quadratic_exactly_and_clamps():
    table = ReferenceTable(Line(), step_s=0.02, chunk_knots=10)
    for tau in (0.0, 0.013, 0.5, 1.2345, 2.999, 3.0, 7.0):
        t = min(tau, 3.0)
        pos, vel, acc, yaw, rate = table.state(tau)
        np.testing.assert_allclose(pos, [0.5 * t * t, 0, 0], atol=1e-12)
        np.testing.assert_allclose(vel, [t, 0, 0], atol=1e-12)
        np.testing.assert_allclose(acc, [1, 0, 0], atol=1e-12)
        assert abs(np.angle(np.exp(1j * (yaw - 3.0 - 0.5 * t)))) < 1e-9 and -np.pi <= yaw < np.pi
        assert abs(rate - 0.5) < 1e-12
