"""companion.workers: planning in worker processes, state and generators adopted back."""

from __future__ import annotations

import asyncio
import pickle

import numpy as np

from companion.flight.reference import ReferenceTable
from companion.workers import AlternativesGate, PlanningWorkers, adopt_changes, call_method
from companion.world import World


class Counter:
    """A stateful object whose method changes one attribute and reads another."""

    def __init__(self) -> None:
        self.count = 0
        self.label = "a"
        self.world = World([], np.zeros(2), np.full(2, 10.0))

    def bump(self, by: int) -> str:
        self.count += by
        return f"{self.label}{self.count}"


def draw(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.random(n)


def test_call_method_returns_only_the_attributes_it_changed():
    result, changed = call_method(Counter(), "bump", (2,), {})
    assert result == "a2" and changed == {"count": 2}


def test_adopt_changes_keeps_what_the_caller_replaced_meanwhile():
    obj = Counter()
    sent = dict(vars(obj))
    obj.label = "b"                               # the caller replaced it while the call ran
    adopted = adopt_changes(obj, sent, {"count": 5, "label": "worker's"})
    assert adopted == ["count"] and obj.count == 5 and obj.label == "b"


def test_a_world_pickles_and_answers_the_same():
    world = World([], np.zeros(2), np.full(2, 10.0), margin_m=0.5)
    copy = pickle.loads(pickle.dumps(world))
    assert copy.dim == world.dim and copy.point_free((5.0, 5.0)) and not copy.point_free((20.0, 5.0))


def test_process_workers_adopt_state_and_advance_generators_like_threads():
    async def fly(kind: str):
        workers = PlanningWorkers(kind, workers=1)
        try:
            await workers.start()
            obj, rng = Counter(), np.random.default_rng(3)
            first = await workers.run(obj.bump, 3)
            drawn = await workers.run(draw, rng, 2)
            return first, obj.count, drawn, rng.random()
        finally:
            workers.shutdown()

    threads, processes = asyncio.run(fly("thread")), asyncio.run(fly("process"))
    assert threads[:2] == processes[:2] == ("a3", 3)
    np.testing.assert_array_equal(threads[2], processes[2])
    assert threads[3] == processes[3]


class Manager:
    """What the gate looks at: world, goal, active path id, compute_alternatives."""

    def __init__(self) -> None:
        self.world = World([], np.zeros(2), np.full(2, 10.0))
        self.goal_ned_m = np.array([9.0, 9.0])
        self.active_path_id = "leg0"
        self.calls = 0

    def compute_alternatives(self, threats, t_s, k):
        self.calls += 1
        return [f"alt{self.calls}"]


def test_the_gate_skips_a_refresh_that_cannot_change_anything():
    async def run(fn, *args, **kwargs):
        return fn(*args, **kwargs)

    async def refreshes():
        gate, manager = AlternativesGate(run), Manager()
        out = [await gate(manager.compute_alternatives, [], 1.0, 4),
               await gate(manager.compute_alternatives, [], 2.0, 4)]      # nothing changed
        manager.active_path_id = "replan-1"
        out.append(await gate(manager.compute_alternatives, [], 3.0, 4))  # a new reference
        out.append(await gate(manager.compute_alternatives, ["threat"], 4.0, 4))
        out.append(await gate(manager.compute_alternatives, ["threat"], 5.0, 4))  # threats held
        return out, gate.skipped

    out, skipped = asyncio.run(refreshes())
    assert out == [["alt1"], [], ["alt2"], ["alt3"], ["alt4"]] and skipped == 1


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
