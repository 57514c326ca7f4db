"""Issue 11 end to end: a flight whose companion takes threats from authenticated sources only.

``sim-vehicle`` and ``companion run --zenoh-config companion.json5`` (written by ``companion keys
init``) fly ``exclusion_zones.plan``; this process holds two zenoh sessions over mutual TLS: the
authorised source ``radar1`` and the observer ``gcs``. On leg 1 the observer puts a pop-up right
on the path (refused by the companion's access control) and then ``radar1`` a threat coming
head-on. The flight is followed to leg 2 and stopped there (keep it short): the head-on threat
was avoided, its decision event names ``radar1``, and the observer's threat never reached the
companion.
"""

from __future__ import annotations

import socket

import numpy as np
import pytest
from flight_support import (
    DEMO_HOME,
    FlightWatcher,
    Injection,
    TrackListener,
    flight_processes,
    inject,
    place,
    wait_until,
)
from support import REPO_ROOT

from companion.geo import LocalFrame
from companion.record.flight_record import load_record
from companion.security.deployment import init_deployment
from companion.threats.transport.bus import ThreatBus
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 3.0
MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
HEAD_ON = Injection(
    "headon1", "moving", leg=1, after_s=3.0, ahead_s=6.0, radius_m=3.0, speed_m_s=3.0, heading="head_on"
)
INTRUSION = Injection("gcs1", "popup", leg=1, after_s=2.0, ahead_s=4.0, radius_m=4.0)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("threat_auth_flight")
    endpoint = f"tls/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    dep = init_deployment(tmp / "deploy", sources=["radar1"], observers=["gcs"], listen=[endpoint], connect=[endpoint])
    seen: dict = {}
    with (
        TrackListener() as track,
        flight_processes(
            tmp,
            MISSION,
            speedup=SPEEDUP,
            gcs_out=track.address,
            extra_args=["--zenoh-config", str(dep.configs["companion"])],
        ) as flight,
    ):
        with (
            ThreatBus(1, zenoh_config=dep.configs["radar1"]) as radar1,
            ThreatBus(1, zenoh_config=dep.configs["gcs"]) as gcs,
        ):
            watcher = FlightWatcher(radar1)
            observer = FlightWatcher(gcs)
            running = lambda: flight.companion.poll() is not None  # noqa: E731
            wait_until(lambda: observer.due(INTRUSION) or running(), 240, "leg 1 (observer)")
            intrusion = place(INTRUSION, observer)
            gcs.client.put_threat(intrusion)
            seen["threats"] = inject(watcher, [HEAD_ON], 240, done=running)
            wait_until(lambda: (watcher.status or {}).get("leg", 0) >= 2 or running(), 240, "leg 2")
            seen["status"] = dict(watcher.status or {})
            seen["events"] = list(watcher.events)
            seen["observer_events"] = list(observer.events)
            seen["listed"] = sorted(t.uid for t in radar1.client.list_threats(5.0))
        track_t, track_pos = track.samples()
    yield {
        "seen": seen,
        "record": load_record(flight.record),
        "log": flight.log.read_text(),
        "track_t_s": track_t,
        "track_ned_m": track_pos,
        "intrusion": intrusion,
    }


def test_the_authorised_threat_is_decided_and_its_event_names_the_source(flight):
    seen = flight["seen"]
    assert seen["status"].get("leg", 0) >= 2, flight["log"][-3000:]
    mine = [e for e in seen["events"] if e.get("threat_id") == "radar1/headon1"]
    assert mine, seen["events"]
    assert mine[0]["source"] == "radar1" and mine[0]["event"] in ("evade", "switch", "replan", "hold")
    assert any(e == mine[0] for e in seen["observer_events"])  # the observer reads events
    assert "radar1/headon1" in seen["listed"]
    held = [th for th in flight["record"].threats if th.get("id") == "radar1/headon1"]
    assert held and held[0]["source"] == "radar1"


def test_the_head_on_threat_is_avoided(flight):
    sent = flight["seen"]["threats"][0]
    stamp = next(th["t_s"] for th in flight["record"].threats if th.get("id") == "radar1/headon1")
    local = sent.to_local(LocalFrame(*DEMO_HOME))
    t, pos = flight["track_t_s"], flight["track_ned_m"]
    after = t >= stamp
    assert after.sum() > 50
    centre = local.pos_ned_m[None, :] + np.outer(t[after] - stamp, local.velocity_ned_m_s)
    assert float(np.min(np.linalg.norm(pos[after] - centre, axis=1)) - sent.radius_m) > 0.0


def test_the_observers_threat_never_reached_the_companion(flight):
    ids = {th.get("id") for th in flight["record"].threats}
    assert not any("gcs1" in str(i) for i in ids), ids
    assert not any("gcs1" in str(e.get("threat_id")) for e in flight["seen"]["events"])
