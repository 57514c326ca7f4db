"""The executor's threat avoidance (companion.flight.avoidance) with the daemon's reactor
(companion.threats.reactor): decisions one at a time, monitor, resume, engaging, publishing
and STATUSTEXT. Scripted decisions stand for ``decide`` in real thread workers
(``WorkerJobs`` on ``PlanningWorkers("thread")``), the reactor's bus is in memory (no zenoh,
no vehicle) and a real ``PeriodicDriver`` runs the schedule's monitor and tell rows."""

from __future__ import annotations

import asyncio
import dataclasses
import threading
import time

import numpy as np
import pytest

from companion.config import Settings
from companion.errors import LinkError
from companion.flight.active import ReferenceOwner
from companion.flight.avoidance import AlternativesPlan, Avoidance, DecisionSteps
from companion.flight.schedule import Scheduler, Task
from companion.link.periodic import PeriodicDriver
from companion.service.jobs import WorkerJobs
from companion.threats.decision.alternatives import Alternative
from companion.threats.decision.kinds import DecisionKind, Trigger
from companion.threats.decision.step import DecisionPolicy, DecisionState, LegContext
from companion.threats.model import Threat, payload_error
from companion.threats.reactor import ThreatReactor
from companion.threats.statustext import STATUSTEXT_MAX_CHARS, statustext_for
from companion.threats.transport.update import ThreatUpdate
from companion.workers import PlanningWorkers
from companion.world import World

HOME = (47.397742, 8.545594, 488.0)


# ---------------------------------------------------------------------------- test doubles
class Line:
    """A straight 10 s trajectory at 1 m/s, heading north."""

    duration_s = 10.0
    length_m = 10.0
    end_pos_ned_m = np.array([10.0, 0.0, -10.0])

    def sample(self, t):
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration_s)
        pos = np.stack([t, np.zeros_like(t), np.full_like(t, -10.0)], axis=1)
        vel = np.zeros_like(pos)
        vel[:, 0] = 1.0
        return pos, vel, np.zeros_like(pos)

    def yaw_rad(self, t):
        return np.zeros(np.atleast_1d(t).shape)

    def yaw_rate_rad_s(self, t):
        return np.zeros(np.atleast_1d(t).shape)


class FixedClock:
    """Mission time stands at 5 s (the decisions' t0)."""

    scale = 1.0
    synced = True

    def now_s(self, monotonic_s=None):
        return 5.0


@dataclasses.dataclass(frozen=True)
class Conflict:
    threat_id: str
    time_to_conflict_s: float = 4.0


@dataclasses.dataclass(frozen=True)
class Decision:
    """The manager's Decision contract as the reactor uses it (``label`` optional)."""

    kind: DecisionKind
    reason: str = "test"
    trajectory: object = None
    start_t_s: float | None = None
    path_id: str | None = None
    path_ned_m: np.ndarray | None = None
    conflict: Conflict | None = None
    decide_ms: float = 1.0
    plan_ms: float = 0.0
    resume: bool = False
    label: str = ""

    def __post_init__(self):
        object.__setattr__(self, "kind", DecisionKind(self.kind))

    def as_event(self) -> dict:
        out = {"event": self.kind.value, "reason": self.reason, "path_id": self.path_id}
        if self.conflict is not None:
            out["threat_id"] = self.conflict.threat_id
        return out


@dataclasses.dataclass(frozen=True)
class LabelledDecision(Decision):
    label: str = ""


def trajectory_decision(kind, threat_id="p1", resume=False, label=None, t0=5.0):
    fields = dict(
        trajectory=Line(),
        start_t_s=t0,
        path_id=f"{kind}-1",
        path_ned_m=np.zeros((2, 3)),
        conflict=Conflict(threat_id) if threat_id else None,
        resume=resume,
    )
    if label is not None:
        return LabelledDecision(kind, label=label, **fields)
    return Decision(kind, **fields)


class ScriptedManager:
    """Stands for ``decide`` (and ``plan_alternatives_for``) in the worker: answers threat and
    monitor decisions from ``on_threats_script`` and resume decisions from ``resume_script``
    (default: ``none``); records every call and the active reference each one observed."""

    def __init__(self):
        self.calls: list[tuple[str, tuple[str, ...], float]] = []
        self.on_threats_script: list[Decision] = []
        self.resume_script: list[Decision] = []
        self.gate: threading.Event | None = None
        self.started = threading.Event()
        self.active = []
        self.alternatives = ()
        self.alternatives_planned = 0
        self._running = 0
        self.max_running = 0
        self._lock = threading.Lock()

    def _call(self, what, script, threats, t_s):
        with self._lock:
            self._running += 1
            self.max_running = max(self.max_running, self._running)
        self.started.set()
        try:
            if self.gate is not None:
                assert self.gate.wait(10.0)
            self.calls.append((what, tuple(th.id for th in threats), t_s))
            return script.pop(0) if script else Decision("none", "clear")
        finally:
            with self._lock:
                self._running -= 1

    def decide(self, state, obs, leg, policy):
        """``decide`` of the pure step: scripted."""
        self.active.append((obs.active.path_id, obs.active.ends_short))
        if obs.trigger is Trigger.RESUME:
            return self._call("resume", self.resume_script, obs.threats, obs.t_s), state
        return self._call("on_threats", self.on_threats_script, obs.threats, obs.t_s), state

    def plan_alternatives(self, state, obs, leg, policy, k, **kw):
        self.alternatives_planned += 1
        return (Alternative.from_path("alt0-1", [[0.0, 0.0, -10.0], [10.0, 0.0, -10.0]]),), state


class MemoryBus:
    """The part of ThreatBus the reactor uses, in memory (its session, and its inbound and
    outbound parts in one double)."""

    def __init__(self):
        self.events, self.paths, self.statuses = [], [], []
        self.republished = []
        self.handler = None
        self.inbound = self.outbound = self

    def key(self, leaf):
        return f"uav/1/{leaf}"

    def republish_threat(self, threat):
        self.republished.append(threat)
        return True

    def open(self):
        return self

    def close(self):
        pass

    def subscribe(self, handler, *, loop=None):
        self.handler = handler

    def serve_threats(self, snapshot):
        self.snapshot = snapshot

    def publish_event(self, event):
        self.events.append(event)

    def publish_path(self, path):
        self.paths.append(path)

    def publish_status(self, status):
        self.statuses.append(status)


class Sink:
    """The daemon's sink as it uses the reactor (``companion.service.sink.DaemonSink``)."""

    def __init__(self, harness):
        self.h = harness

    def record(self, line_type, /, **fields):
        self.h.records.append((line_type, fields))

    def event(self, name, **fields):
        self.h.records.append(("event", {"name": name, **fields}))

    def decision(self, decision, event):
        self.h.reactor.tell_decision(decision, event)

    def path(self, reference, alternatives, leg_index):
        self.h.reactor.publish_path(reference, alternatives, leg_index)


class Harness:
    """The avoidance with the reactor, the reference owner, thread jobs and a driver."""

    def __init__(self, *, alternatives_k=0, monitor_period_s=0.01, statustext_error=None):
        s = Settings()  # the fleet needs a zenoh session: not this bus in memory
        self.settings = dataclasses.replace(
            s,
            flight=dataclasses.replace(s.flight, alternatives_k=alternatives_k),
            fleet=dataclasses.replace(s.fleet, enabled=False),
        )
        self.manager = ScriptedManager()
        self.bus = MemoryBus()
        self.records: list[tuple[str, dict]] = []
        self.texts: list[tuple[str, str]] = []
        self.statustext_error = statustext_error
        self.monitor_period_s = monitor_period_s
        self.owner = ReferenceOwner(FixedClock(), turn_rate_rad_s=0.6, yaw_now_rad=lambda: 0.0)
        self.owner.engage(Line(), "leg0", t0_s=0.0)
        self.reactor = ThreatReactor(
            self.settings, clock_now_s=lambda: 5.0, record=Sink(self).record, statustext=self.statustext, bus=self.bus
        )
        self.leg = LegContext(1, World([], [-50.0, -50.0, -50.0], [50.0, 50.0, 0.0]), np.array([10.0, 0.0, -10.0]))
        self.workers = PlanningWorkers("thread")
        self.engaged: list[dict] = []
        self.sent_at: list[float] = []
        self.owner.listen(self._engaged)

    def _engaged(self, ref):
        if ref is not None and ref.path_id != "leg0":
            self.engaged.append({"path_id": ref.path_id, "t0_s": ref.t0_s, "resume": ref.resume})

    @property
    def reference(self):
        return self.owner.current

    def statustext(self, text, severity):
        if self.statustext_error is not None:
            raise self.statustext_error
        self.texts.append((text, severity))

    def decisions_recorded(self):
        return [f for kind, f in self.records if kind == "decision"]

    def send_now(self):
        self.owner.setpoint_at(time.monotonic())

    async def start(self, *, leg=True):
        loop = asyncio.get_running_loop()
        policy = DecisionPolicy.from_settings(self.settings)
        f = self.settings.flight
        self.avoidance = Avoidance(
            policy=policy,
            state=DecisionState.initial(policy, 1),
            owner=self.owner,
            threats=self.reactor,
            jobs=WorkerJobs(self.workers, loop),
            sink=Sink(self),
            now_s=lambda: 5.0,
            monotonic_s=time.monotonic,
            send_now=self.send_now,
            send_at=self.sent_at.append,
            position_ned_m=lambda: np.array([1.0, 2.0, -10.0]),
            alternatives=AlternativesPlan(f.alternatives_k, f.alternatives_budget_s, f.alternatives_lead_s),
            steps=DecisionSteps(decide=self.manager.decide, plan_alternatives=self.manager.plan_alternatives),
        )
        self.reactor.on_change = self.avoidance.on_threats_changed
        await self.reactor.start(HOME, reference=lambda: self.owner.current, position_ned_m=lambda: None)
        schedule = Scheduler(
            [
                Task("monitor", 1.0 / self.monitor_period_s, self.avoidance.monitor, 10.0),
                Task("tell", 200.0, self.avoidance.tell_engaged, 1.0),
            ]
        )
        self.driver = PeriodicDriver(200.0, schedule.tick)
        self.driver.start()
        if leg:
            self.avoidance.start_leg(self.leg)

    async def stop(self):
        await self.driver.stop()
        await self.reactor.stop()
        self.workers.shutdown()

    async def resume(self):
        """What the phase machine asks when a reference ended short: the answer, awaited."""
        answer = asyncio.get_running_loop().create_future()
        self.avoidance.request_resume(lambda d: answer.done() or answer.set_result(d))
        return await answer

    def put(self, tid, pos=(6.0, 0.0, -10.0), received_mono_s=None, traffic="drone"):
        """A pop-up on the reference (by default): the monitor's check finds a conflict."""
        threat = Threat(tid, "popup", "local_ned", pos, radius_m=3.0, received_t_s=5.0, traffic=traffic)
        self.bus.handler(
            ThreatUpdate(
                "put",
                tid,
                threat,
                None,
                f"uav/1/threats/{tid}",
                5.0,
                time.monotonic() if received_mono_s is None else received_mono_s,
                1,
            )
        )


async def until(predicate, what, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.005)


def run(coro_fn, harness):
    async def main():
        try:
            await coro_fn(harness)
        finally:
            await harness.stop()

    asyncio.run(main())


# ---------------------------------------------------------------------------- threat updates
def test_a_threat_decision_is_engaged_published_recorded_and_told():
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("replan")]

    async def main(h):
        await h.start()
        receipt = time.monotonic()
        h.put("p1", received_mono_s=receipt)
        await until(lambda: h.bus.events, "the event")
        event = h.bus.events[0]
        assert event["event"] == "replan" and event["trigger"] == "threat" and event["label"] == "replan"
        assert event["latency_ms"] >= 0.0 and event["leg"] == 1 and event["threat_id"] == "p1"
        parts = event["latency_parts_ms"]  # where the latency went, summing to it
        assert set(parts) == {"queued", "compute", "transport", "gate", "start"}
        assert all(v >= -0.01 for k, v in parts.items() if k != "transport") and parts["transport"] > -1.0
        assert sum(parts.values()) == pytest.approx(event["latency_ms"], abs=0.1)
        assert h.engaged == [{"path_id": "replan-1", "t0_s": 5.0, "resume": False}]
        assert h.reference.first_sent_monotonic_s >= receipt
        assert h.manager.calls[0][:2] == ("on_threats", ("p1",))
        assert h.manager.active == [("leg0", False)] and h.reference.path_id == "replan-1"
        assert h.decisions_recorded()[0]["kind"] == "replan"
        text, severity = h.texts[0]
        assert text.startswith("AVOID p1: replan, ") and text.endswith(" ms") and severity == "NOTICE"
        assert h.bus.paths[-1]["path_id"] == "replan-1"
        assert h.avoidance.decisions == 1 and len(h.avoidance.latencies_ms["replan"]) == 1

    run(main, h)


@pytest.mark.parametrize("t0, sent_at", [(5.0, []), (5.25, [5.25])])
def test_a_reference_that_starts_later_has_its_first_setpoint_sent_at_its_start(t0, sent_at):
    """A decision planned from its expected duration starts its reference then: the first
    setpoint of it goes out at that instant, not at the stream's next tick after it."""
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("evade", t0=t0)]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(lambda: h.engaged, "the engagement")
        assert h.engaged[0]["t0_s"] == t0 and h.sent_at == sent_at

    run(main, h)


def test_none_and_trajectoryless_decisions_publish_nothing():
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [Decision("none"), Decision("hold", resume=True)]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(lambda: len(h.manager.calls) == 1, "the first decision")
        h.put("p2")
        await until(lambda: len(h.manager.calls) == 2, "the second decision")
        await asyncio.sleep(0.05)
        assert h.bus.events == [] and h.texts == [] and h.decisions_recorded() == [] and h.engaged == []
        assert h.avoidance.decisions == 0

    run(main, h)


def test_updates_during_a_decision_are_folded_into_one_next_decision_with_the_newest_table():
    h = Harness(monitor_period_s=60.0)
    h.manager.gate = threading.Event()

    async def main(h):
        await h.start()
        h.put("a")
        await until(h.manager.started.is_set, "the first decision to start")
        for tid in ("b", "c", "d"):
            h.put(tid)
        h.manager.gate.set()
        await until(lambda: len(h.manager.calls) == 2, "the folded decision")
        await asyncio.sleep(0.05)
        assert len(h.manager.calls) == 2
        assert h.manager.calls[1][1] == ("a", "b", "c", "d")
        assert h.manager.max_running == 1

    run(main, h)


def test_no_decision_outside_a_leg_and_the_next_leg_checks_the_threats_held():
    h = Harness(monitor_period_s=0.01)

    async def main(h):
        await h.start(leg=False)
        h.put("p1")
        await asyncio.sleep(0.1)
        assert h.manager.calls == []
        h.avoidance.start_leg(h.leg)
        await until(lambda: h.manager.calls, "the check at the leg's start")
        h.avoidance.end_leg()
        await asyncio.sleep(0.05)
        n = len(h.manager.calls)
        await asyncio.sleep(0.1)
        assert len(h.manager.calls) == n

    run(main, h)


def test_a_decision_for_a_leg_that_ended_meanwhile_is_not_applied():
    h = Harness(monitor_period_s=60.0)
    h.manager.gate = threading.Event()
    h.manager.on_threats_script = [trajectory_decision("replan")]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(h.manager.started.is_set, "the decision to start")
        h.avoidance.end_leg()
        h.manager.gate.set()
        await until(lambda: h.manager.calls, "the decision")
        await asyncio.sleep(0.05)
        assert h.engaged == [] and h.bus.events == []

    run(main, h)


def test_a_decision_built_on_a_reference_the_daemon_replaced_meanwhile_is_dropped():
    """E.g. the link came back during the decision: the daemon holds, then replans the leg."""
    h = Harness(monitor_period_s=60.0)
    h.manager.gate = threading.Event()
    h.manager.on_threats_script = [trajectory_decision("replan")]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(h.manager.started.is_set, "the decision to start")
        h.owner.engage(Line(), "leg1-resume", t0_s=6.0)  # what a replan after a link loss does
        h.manager.gate.set()
        await until(lambda: h.manager.calls, "the decision")
        await asyncio.sleep(0.05)
        assert [e["path_id"] for e in h.engaged] == ["leg1-resume"] and h.bus.events == []
        assert h.reference.path_id == "leg1-resume", "decisions check the owner's reference"

    run(main, h)


def test_nothing_is_decided_while_the_daemon_holds_without_a_reference():
    h = Harness(monitor_period_s=0.01)

    async def main(h):
        await h.start()
        h.owner.hold([0.0, 0.0, -10.0])  # hold_here after a link loss
        h.put("p1")
        await asyncio.sleep(0.1)
        assert h.manager.calls == [] and await h.resume() is None

    run(main, h)


# ---------------------------------------------------------------------------- rejected
def test_a_rejected_sample_is_published_recorded_and_told_as_a_warning():
    h = Harness(monitor_period_s=60.0)

    async def main(h):
        await h.start()
        err = payload_error("radius_m", "must be > 0")
        h.bus.handler(ThreatUpdate("rejected", "broken", None, err, "uav/1/threats/broken", 5.0, time.monotonic(), 2))
        assert h.bus.events[0]["event"] == "rejected" and h.bus.events[0]["field"] == "radius_m"
        assert h.decisions_recorded()[0]["kind"] == "rejected"
        assert h.texts == [("THREAT broken rejected: radius_m", "WARNING")]
        assert h.manager.calls == []

    run(main, h)


# ---------------------------------------------------------------------------- monitor
def test_the_monitor_rechecks_while_a_threat_is_known_and_a_leg_is_flown():
    h = Harness(monitor_period_s=0.01)

    async def main(h):
        await h.start()
        await asyncio.sleep(0.1)
        assert h.manager.calls == [], "no threat known: nothing to check"
        h.put("m1")
        await until(lambda: len(h.manager.calls) >= 5, "monitor checks")
        assert all(c[0] == "on_threats" and c[1] == ("m1",) for c in h.manager.calls)
        assert h.manager.max_running == 1
        h.manager.on_threats_script = [trajectory_decision("evade", "m1", resume=True, label="evade left")]
        await until(lambda: h.bus.events, "the monitor's decision")
        event = h.bus.events[0]
        assert event["trigger"] == "monitor" and event["event"] == "evade" and event["label"] == "evade left"
        assert h.engaged[-1]["resume"] is True and (h.reference.path_id, h.reference.resume) == ("evade-1", True)
        text, severity = h.texts[0]
        assert text.startswith("AVOID m1: evade left, ") and severity == "WARNING"

    run(main, h)


def test_the_monitor_skips_ticks_while_a_decision_is_under_way():
    h = Harness(monitor_period_s=0.005)
    h.manager.gate = threading.Event()

    async def main(h):
        await h.start()
        h.put("m1")
        await until(h.manager.started.is_set, "a decision")
        await asyncio.sleep(0.1)  # about 20 ticks while the decision blocks
        h.manager.gate.set()
        await until(lambda: len(h.manager.calls) >= 3, "monitor checks after the decision")
        assert h.manager.max_running == 1

    run(main, h)


def test_a_manned_conflict_left_unanswered_is_decided_again_on_the_next_report_not_every_tick():
    """Nothing better than the reference against a manned aircraft: the monitor does not ask
    again on the same reports (its ticks run every 10 ms), the aircraft's next report does; a
    drone-scale conflict left unanswered is asked again at every tick."""
    h = Harness(monitor_period_s=0.01)
    unanswered = lambda tid: Decision("none", "no candidate better", conflict=Conflict(tid))  # noqa: E731

    async def main(h):
        await h.start()
        h.manager.on_threats_script = [unanswered("adsb-a00001")] * 50
        h.put("adsb-a00001", traffic="manned")
        await until(lambda: len(h.manager.calls) >= 1, "the report's decision")
        await asyncio.sleep(0.3)  # 30 ticks on the same report
        assert len(h.manager.calls) == 1
        h.put("adsb-a00001", pos=(7.0, 0.0, -10.0), traffic="manned")
        await until(lambda: len(h.manager.calls) >= 2, "the next report's decision")
        await asyncio.sleep(0.3)
        assert len(h.manager.calls) == 2
        h.manager.on_threats_script = [unanswered("p1")] * 50
        h.put("p1")
        await until(lambda: len(h.manager.calls) >= 10, "a drone-scale conflict asked at every tick")

    run(main, h)


# ---------------------------------------------------------------------------- resume
def test_resume_without_a_way_back_publishes_nothing_then_a_plan_back_is_published():
    h = Harness(monitor_period_s=60.0)
    h.manager.resume_script = [
        Decision("none", "no clear way back", resume=True),
        trajectory_decision("replan", threat_id=None, label="replan to goal"),
    ]

    async def main(h):
        await h.start()
        first = await h.resume()
        assert first.kind == "none" and first.resume
        assert h.bus.events == [] and h.texts == [] and h.engaged == []
        second = await h.resume()
        assert second.kind == "replan"
        assert [c[0] for c in h.manager.calls] == ["resume", "resume"]
        assert h.bus.events[0]["trigger"] == "resume" and h.engaged[0]["resume"] is False
        assert h.texts[0][0].startswith("RESUME: replan to goal, ") and h.texts[0][1] == "NOTICE"

    run(main, h)


def test_resume_waits_for_the_decision_under_way_and_never_overlaps_it():
    h = Harness(monitor_period_s=60.0)
    h.manager.gate = threading.Event()

    async def main(h):
        await h.start()
        h.put("p1")
        await until(h.manager.started.is_set, "a decision")
        task = asyncio.ensure_future(h.resume())
        await asyncio.sleep(0.05)
        assert not task.done()
        h.manager.gate.set()
        decision = await asyncio.wait_for(task, 10.0)
        assert decision.kind == "none"
        assert [c[0] for c in h.manager.calls] == ["on_threats", "resume"] and h.manager.max_running == 1

    run(main, h)


def test_resume_outside_a_leg_asks_nothing():
    h = Harness(monitor_period_s=60.0)

    async def main(h):
        await h.start(leg=False)
        assert await h.resume() is None and h.manager.calls == []

    run(main, h)


# ---------------------------------------------------------------------------- failures and alternatives
def test_a_failing_statustext_does_not_disturb_the_decision():
    h = Harness(monitor_period_s=60.0, statustext_error=LinkError("the link is not connected"))
    h.manager.on_threats_script = [trajectory_decision("switch")]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(lambda: h.bus.events, "the event")
        assert h.engaged and h.avoidance.decisions == 1

    run(main, h)


def test_a_failing_manager_keeps_the_reference_and_later_decisions_run():
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [None]  # .kind of None raises in apply

    async def main(h):
        await h.start()
        h.put("p1")
        await until(lambda: len(h.manager.calls) == 1, "the failing decision")
        h.manager.on_threats_script = [trajectory_decision("replan")]
        await asyncio.sleep(0.02)
        h.put("p2")
        await until(lambda: h.bus.events, "the next decision")
        assert h.engaged[0]["path_id"] == "replan-1"

    run(main, h)


def test_alternatives_are_refreshed_at_the_leg_start_and_after_a_decision():
    h = Harness(alternatives_k=2, monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("replan")]

    async def main(h):
        await h.start()
        await until(lambda: any(k == "alternatives" for k, _ in h.records), "the leg-start alternatives")
        h.put("p1")
        await until(lambda: sum(k == "alternatives" for k, _ in h.records) >= 2, "alternatives after the decision")
        assert h.avoidance.state.alternatives and h.bus.paths[-1]["alternatives"][0]["path_id"] == "alt0-1"

    run(main, h)


# ---------------------------------------------------------------------------- STATUSTEXT
@pytest.mark.parametrize(
    "kind, label, tid, latency, text, severity",
    [
        ("evade", "evade left", "m1", 31.4, "AVOID m1: evade left, 31 ms", "WARNING"),
        ("replan", "replan", "p1", 140.0, "AVOID p1: replan, 140 ms", "NOTICE"),
        ("retime", "retime pause 3.0 s", "m2", None, "AVOID m2: retime pause 3.0 s", "NOTICE"),
        ("hold", "hold", "m3", 12.0, "AVOID m3: hold, 12 ms", "WARNING"),
        ("switch", "switch alt2-5", None, 8.0, "RESUME: switch alt2-5, 8 ms", "NOTICE"),
        ("rejected", "radius_m", "bad", None, "THREAT bad rejected: radius_m", "WARNING"),
    ],
)
def test_statustext_for(kind, label, tid, latency, text, severity):
    assert statustext_for(kind, label, tid, latency) == (text, severity)


def test_statustext_is_cut_to_50_characters_keeping_the_latency():
    text, _ = statustext_for("switch", "switch " + "x" * 80, "a-long-threat-id", 1234.0)
    assert len(text) == STATUSTEXT_MAX_CHARS and text.endswith(", 1234 ms")


# ---------------------------------------------------------------------------- threats learnt locally
def test_a_local_threat_goes_the_way_of_a_zenoh_put_and_is_republished():
    """An ADS-B threat on the reference: stored, decided on like a PUT, recorded, and republished for others."""
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("evade", threat_id="adsb-4b1805")]

    async def main(h):
        await h.start()
        threat = Threat(
            "adsb-4b1805",
            "moving",
            "global",
            (47.397814, 8.545594, 498.0),
            (0.0, 20.0, 0.0),
            radius_m=20.0,
            ttl_s=5.0,
            received_t_s=4.0,
        )
        receipt = time.monotonic()
        h.reactor.on_local_threat(threat, receipt)
        await until(lambda: h.bus.events, "the decision")
        assert "adsb-4b1805" in h.reactor.table and h.reactor.table.get("adsb-4b1805").frame == "local_ned"
        assert h.manager.calls[0][:2] == ("on_threats", ("adsb-4b1805",))
        assert h.bus.events[0]["threat_id"] == "adsb-4b1805" and h.bus.events[0]["trigger"] == "threat"
        assert [t.id for t in h.bus.republished] == ["adsb-4b1805"]
        assert h.bus.republished[0].frame == "global"  # as received, for other consumers
        recorded = [f for kind, f in h.records if kind == "threat"]
        assert recorded[0]["id"] == "adsb-4b1805" and recorded[0]["t_s"] == 4.0

    run(main, h)


# ---------------------------------------------------------------------------- alternatives without threats
def test_a_quiet_refresh_on_the_same_reference_is_skipped():
    h = Harness(alternatives_k=2, monitor_period_s=60.0)

    async def main(h):
        await h.start()
        await until(lambda: any(k == "alternatives" for k, _ in h.records), "the leg-start alternatives")
        await until(lambda: not h.avoidance._alt_busy, "the refresh to end")
        h.avoidance.refresh_alternatives()
        assert h.avoidance.alternatives_skipped == 1 and h.manager.alternatives_planned == 1
        h.owner.engage(Line(), "replan-9", t0_s=5.0)  # a new reference: planned again
        h.avoidance.refresh_alternatives()
        await until(lambda: h.manager.alternatives_planned == 2, "the refresh on the new reference")

    run(main, h)
