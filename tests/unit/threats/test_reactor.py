"""ThreatReactor plumbing (companion.threats.reactor): decisions one at a time, monitor, resume,
publishing and STATUSTEXT, with a scripted manager and an in-memory bus (no zenoh, no vehicle)."""

from __future__ import annotations

import asyncio
import dataclasses
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from companion.config import Settings
from companion.errors import LinkError
from companion.threats.model import Threat, payload_error
from companion.threats.reactor import ThreatReactor
from companion.threats.statustext import STATUSTEXT_MAX_CHARS, statustext_for
from companion.threats.transport.update import ThreatUpdate

HOME = (47.397742, 8.545594, 488.0)


# ---------------------------------------------------------------------------- test doubles
class Line:
    """A straight 10 s trajectory (what the reactor samples for the path message)."""

    duration_s = 10.0
    end_pos_ned_m = np.array([10.0, 0.0, -10.0])

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pos = np.stack([t, np.zeros_like(t), np.full_like(t, -10.0)], axis=1)
        return pos, np.zeros_like(pos), np.zeros_like(pos)


@dataclasses.dataclass(frozen=True)
class Conflict:
    threat_id: str
    time_to_conflict_s: float = 4.0


@dataclasses.dataclass(frozen=True)
class Decision:
    """The manager's Decision contract as the reactor uses it (``label`` optional)."""

    kind: str
    reason: str = "test"
    trajectory: object = None
    start_t_s: float | None = None
    path_id: str | None = None
    path_ned_m: np.ndarray | None = None
    conflict: Conflict | None = None
    decide_ms: float = 1.0
    plan_ms: float = 0.0
    resume: bool = False

    def as_event(self) -> dict:
        out = {"event": self.kind, "reason": self.reason, "path_id": self.path_id}
        if self.conflict is not None:
            out["threat_id"] = self.conflict.threat_id
        return out


@dataclasses.dataclass(frozen=True)
class LabelledDecision(Decision):
    label: str = ""


def trajectory_decision(kind, threat_id="p1", resume=False, label=None, t0=5.0):
    fields = dict(trajectory=Line(), start_t_s=t0, path_id=f"{kind}-1", path_ned_m=np.zeros((2, 3)),
                  conflict=Conflict(threat_id) if threat_id else None, resume=resume)
    if label is not None:
        return LabelledDecision(kind, label=label, **fields)
    return Decision(kind, **fields)


class ScriptedManager:
    """Answers ``on_threats`` / ``resume`` from scripts (default: ``none``); records every call."""

    def __init__(self):
        self.calls: list[tuple[str, tuple[str, ...], float]] = []
        self.on_threats_script: list[Decision] = []
        self.resume_script: list[Decision] = []
        self.gate: threading.Event | None = None
        self.started = threading.Event()
        self.active = []
        self.alternatives = ()
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

    def on_threats(self, threats, t_s):
        return self._call("on_threats", self.on_threats_script, threats, t_s)

    def resume(self, threats, t_s):
        return self._call("resume", self.resume_script, threats, t_s)

    def set_leg(self, world, goal):
        pass

    def set_active(self, trajectory, start_t_s, path_id, ends_short=False):
        self.active.append((path_id, ends_short))

    def set_alternatives(self, alternatives):
        self.alternatives = tuple(alternatives)

    def compute_alternatives(self, threats, t_s, k, **kw):
        return [SimpleNamespace(path_id="alt0-1", path_ned_m=np.zeros((2, 3)))]


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


class Harness:
    """A reactor wired to doubles of the daemon's callables."""

    def __init__(self, *, alternatives_k=0, monitor_period_s=0.01, statustext_error=None):
        s = Settings()                   # the fleet needs a zenoh session: not this bus in memory
        self.settings = dataclasses.replace(s, flight=dataclasses.replace(s.flight, alternatives_k=alternatives_k),
                                            fleet=dataclasses.replace(s.fleet, enabled=False))
        self.manager = ScriptedManager()
        self.bus = MemoryBus()
        self.reference = SimpleNamespace(trajectory=Line(), t0_s=0.0, path_id="leg0", first_sent_monotonic_s=None,
                                         state=lambda t: Line().sample([t]))
        self.engaged: list[dict] = []
        self.records: list[tuple[str, dict]] = []
        self.texts: list[tuple[str, str]] = []
        self.statustext_error = statustext_error
        self.reactor = ThreatReactor(
            self.settings, clock_now_s=lambda: 5.0, in_worker=self.in_worker, rng=np.random.default_rng(0),
            engage=self.engage, send_now=self.send_now, reference=lambda: self.reference,
            position_ned_m=lambda: np.array([1.0, 2.0, -10.0]), record=self.record, statustext=self.statustext,
            bus=self.bus, manager_factory=lambda leg: self.manager, monitor_period_s=monitor_period_s)
        self.leg = SimpleNamespace(index=1, world=None, goal_ned_m=np.array([10.0, 0.0, -10.0]))

    async def in_worker(self, fn, *args, **kwargs):
        return await asyncio.to_thread(fn, *args, **kwargs)

    def engage(self, trajectory, path_id, *, t0_s, resume):
        """As ``CompanionDaemon.engage``: the new reference, also given to the reactor."""
        self.reference = SimpleNamespace(trajectory=trajectory, t0_s=t0_s, path_id=path_id, resume=resume,
                                         first_sent_monotonic_s=None, state=lambda t: trajectory.sample([t]))
        self.engaged.append({"path_id": path_id, "t0_s": t0_s, "resume": resume})
        self.reactor.set_active(self.reference)
        return self.reference

    def send_now(self):
        self.reference.first_sent_monotonic_s = time.monotonic()

    def record(self, line_type, /, **fields):
        self.records.append((line_type, fields))

    def statustext(self, text, severity):
        if self.statustext_error is not None:
            raise self.statustext_error
        self.texts.append((text, severity))

    def decisions_recorded(self):
        return [f for kind, f in self.records if kind == "decision"]

    async def start(self, *, leg=True):
        await self.reactor.start(HOME)
        if leg:
            self.reactor.on_leg_started(self.leg, self.reference)

    def put(self, tid, pos=(20.0, 0.0, -10.0), received_mono_s=None):
        threat = Threat(tid, "popup", "local_ned", pos, radius_m=3.0, received_t_s=5.0)
        self.bus.handler(ThreatUpdate("put", tid, threat, None, f"uav/1/threats/{tid}", 5.0,
                                      time.monotonic() if received_mono_s is None else received_mono_s, 1))


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
            await harness.reactor.stop()
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
        assert h.engaged == [{"path_id": "replan-1", "t0_s": 5.0, "resume": False}]
        assert h.reference.first_sent_monotonic_s >= receipt
        assert h.manager.calls[0][:2] == ("on_threats", ("p1",))
        assert h.manager.active == [("leg0", False), ("replan-1", False)]
        assert h.decisions_recorded()[0]["kind"] == "replan"
        text, severity = h.texts[0]
        assert text.startswith("AVOID p1: replan, ") and text.endswith(" ms") and severity == "NOTICE"
        assert h.bus.paths[-1]["path_id"] == "replan-1"
        assert h.reactor.decisions == 1 and len(h.reactor.latencies_ms["replan"]) == 1
        assert set(h.reactor.latency_summary()["replan"]) == {"n", "p50", "p99", "max"}

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
        assert h.reactor.decisions == 0

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
        h.reactor.on_leg_started(h.leg, h.reference)
        await until(lambda: h.manager.calls, "the check at the leg's start")
        h.reactor.on_leg_ended()
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
        h.reactor.on_leg_ended()
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
        h.engage(Line(), "leg1-resume", t0_s=6.0, resume=False)      # what resume_leg does
        h.manager.gate.set()
        await until(lambda: h.manager.calls, "the decision")
        await asyncio.sleep(0.05)
        assert [e["path_id"] for e in h.engaged] == ["leg1-resume"] and h.bus.events == []
        assert h.manager.active[-1] == ("leg1-resume", False), "the manager checks the daemon's reference"

    run(main, h)


def test_nothing_is_decided_while_the_daemon_holds_without_a_reference():
    h = Harness(monitor_period_s=0.01)

    async def main(h):
        await h.start()
        h.reference = None                   # hold_here after a link loss
        h.put("p1")
        await asyncio.sleep(0.1)
        assert h.manager.calls == [] and await h.reactor.resume() is None

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
        assert h.engaged[-1]["resume"] is True and h.manager.active[-1] == ("evade-1", True)
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
        await asyncio.sleep(0.1)                 # about 20 ticks while the decision blocks
        h.manager.gate.set()
        await until(lambda: len(h.manager.calls) >= 3, "monitor checks after the decision")
        assert h.manager.max_running == 1

    run(main, h)


# ---------------------------------------------------------------------------- resume
def test_resume_without_a_way_back_publishes_nothing_then_a_plan_back_is_published():
    h = Harness(monitor_period_s=60.0)
    h.manager.resume_script = [Decision("none", "no clear way back", resume=True),
                               trajectory_decision("replan", threat_id=None, label="replan to goal")]

    async def main(h):
        await h.start()
        first = await h.reactor.resume()
        assert first.kind == "none" and first.resume
        assert h.bus.events == [] and h.texts == [] and h.engaged == []
        second = await h.reactor.resume()
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
        task = asyncio.ensure_future(h.reactor.resume())
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
        assert await h.reactor.resume() is None and h.manager.calls == []

    run(main, h)


# ---------------------------------------------------------------------------- failures and alternatives
def test_a_failing_statustext_does_not_disturb_the_decision():
    h = Harness(monitor_period_s=60.0, statustext_error=LinkError("the link is not connected"))
    h.manager.on_threats_script = [trajectory_decision("switch")]

    async def main(h):
        await h.start()
        h.put("p1")
        await until(lambda: h.bus.events, "the event")
        assert h.engaged and h.reactor.decisions == 1

    run(main, h)


def test_a_failing_manager_keeps_the_reference_and_later_decisions_run():
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [None]          # .kind of None raises in apply

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
        assert h.manager.alternatives and h.bus.paths[-1]["alternatives"][0]["path_id"] == "alt0-1"

    run(main, h)


# ---------------------------------------------------------------------------- STATUSTEXT
@pytest.mark.parametrize("kind, label, tid, latency, text, severity", [
    ("evade", "evade left", "m1", 31.4, "AVOID m1: evade left, 31 ms", "WARNING"),
    ("replan", "replan", "p1", 140.0, "AVOID p1: replan, 140 ms", "NOTICE"),
    ("retime", "retime pause 3.0 s", "m2", None, "AVOID m2: retime pause 3.0 s", "NOTICE"),
    ("hold", "hold", "m3", 12.0, "AVOID m3: hold, 12 ms", "WARNING"),
    ("switch", "switch alt2-5", None, 8.0, "RESUME: switch alt2-5, 8 ms", "NOTICE"),
    ("rejected", "radius_m", "bad", None, "THREAT bad rejected: radius_m", "WARNING"),
])
def test_statustext_for(kind, label, tid, latency, text, severity):
    assert statustext_for(kind, label, tid, latency) == (text, severity)


def test_statustext_is_cut_to_50_characters_keeping_the_latency():
    text, _ = statustext_for("switch", "switch " + "x" * 80, "a-long-threat-id", 1234.0)
    assert len(text) == STATUSTEXT_MAX_CHARS and text.endswith(", 1234 ms")


# ---------------------------------------------------------------------------- threats learnt locally
def test_a_local_threat_goes_the_way_of_a_zenoh_put_and_is_republished():
    """An ADS-B threat: stored, decided on like a PUT, recorded, and republished for others."""
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("evade", threat_id="adsb-4b1805")]

    async def main(h):
        await h.start()
        threat = Threat("adsb-4b1805", "moving", "global", (47.3986, 8.5456, 508.0), (0.0, 20.0, 0.0),
                        radius_m=20.0, ttl_s=5.0, received_t_s=4.0)
        receipt = time.monotonic()
        h.reactor.on_local_threat(threat, receipt)
        await until(lambda: h.bus.events, "the decision")
        assert "adsb-4b1805" in h.reactor.table and h.reactor.table.get("adsb-4b1805").frame == "local_ned"
        assert h.manager.calls[0][:2] == ("on_threats", ("adsb-4b1805",))
        assert h.bus.events[0]["threat_id"] == "adsb-4b1805" and h.bus.events[0]["trigger"] == "threat"
        assert [t.id for t in h.bus.republished] == ["adsb-4b1805"]
        assert h.bus.republished[0].frame == "global"               # as received, for other consumers
        recorded = [f for kind, f in h.records if kind == "threat"]
        assert recorded[0]["id"] == "adsb-4b1805" and recorded[0]["t_s"] == 4.0

    run(main, h)
