"""Issue 9 end to end: threats put over real zenoh into a real flight, judged by the vehicle.

``sim-vehicle`` and ``companion run`` are separate processes; this test process is the third,
threat-injecting one (a zenoh peer connected to the companion's endpoint), and an independent
pymavlink listener records the vehicle's own LOCAL_POSITION_NED. One flight of
``mission_files/exclusion_zones.plan`` carries the whole sequence:

- leg 1: a threat coming head-on along the leg at 3 m/s;
- leg 2: an invalid payload (rejected); a harmless threat put then DELETEd; a pop-up on the
  path 3 s ahead (its inflated radius is met in about 2 s: only a stop or a sidestep clears it);
- leg 3: a threat in the *global* frame crossing the leg at right angles at 2 m/s, timed to
  meet the vehicle where the path crosses its track;

and the flight completes with no sample of the vehicle's own track inside any threat. The ground
station (the pymavlink listener on the vehicle's other output) receives the traffic alerts
(issue 24): ``COLLISION`` as AP_Avoidance sends it and a STATUSTEXT, then the decision's action.

The same flight checks the operator's view (issue 14): a Foxglove WebSocket client connected to
``--foxglove`` during the flight, the MCAP record (``--record flight.mcap``) and the ``--tlog``.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import zlib

import numpy as np
import pytest
from flight_support import (
    DEMO_HOME,
    FlightWatcher,
    Injection,
    TrackListener,
    flight_processes,
    inject,
    last_json_line,
    wait_until,
)
from foxglove_client import collect
from mcap.reader import make_reader
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from support import REPO_ROOT

from companion.geo import LocalFrame
from companion.threats.model import Threat
from companion.threats.transport.bus import ThreatBus
from companion.view import channels as ch
from companion.view.mcap_record import load_flight
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 2.0
MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
HEAD_ON = Injection(
    "headon1", "moving", leg=1, after_s=3.0, ahead_s=6.0, radius_m=3.0, speed_m_s=3.0, heading="head_on"
)
POPUP = Injection("popup2", "popup", leg=2, after_s=5.0, ahead_s=3.0, radius_m=3.0)
CROSSING = Injection(
    "cross3", "moving", leg=3, after_s=3.0, ahead_s=5.0, radius_m=3.0, speed_m_s=2.0, lateral_m=-10.0, frame="global"
)
LIVE_TOPICS = {"/flight/decision", "/flight/threat", ch.SCENE_WORLD, ch.SCENE_THREATS, ch.SCENE_PATHS, ch.TRANSFORMS}
HARMLESS = Threat("far1", "popup", "local_ned", (300.0, 300.0, -15.0), (0.0, 0.0, 0.0), 2.0, 60.0)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("threat_flight")
    seen = {"threats": []}
    live: dict = {}
    fox_port, tlog = free_port(socket.SOCK_STREAM), tmp / "companion.tlog"
    view_args = ["--foxglove", f"127.0.0.1:{fox_port}", "--tlog", str(tlog)]
    with (
        TrackListener() as track,
        flight_processes(
            tmp, MISSION, speedup=SPEEDUP, gcs_out=track.address, extra_args=view_args, record_name="flight.mcap"
        ) as flight,
    ):
        watch = threading.Thread(
            target=lambda: live.update(
                got=asyncio.run(
                    collect(fox_port, LIVE_TOPICS, 600.0, until=lambda: flight.companion.poll() is not None)
                )
            ),
            daemon=True,
        )
        watch.start()
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = FlightWatcher(bus)
            running = lambda: flight.companion.poll() is not None  # noqa: E731
            seen["threats"] += inject(watcher, [HEAD_ON], 240, done=running)
            wait_until(lambda: watcher.status and watcher.status["leg"] == 2, 120, "leg 2")
            bus.client.put_raw("broken", b'{"v": 1, "id": "broken", "kind": "popup", "radius_m": -1}')
            bus.client.put_threat(HARMLESS)
            wait_until(lambda: (watcher.status or {}).get("threats", 0) >= 2, 20, "two threats held")
            seen["listed"] = sorted(t.id for t in bus.client.list_threats(5.0))
            bus.client.delete_threat(HARMLESS.id)
            wait_until(lambda: HARMLESS.id not in [t.id for t in bus.client.list_threats(2.0)], 20, "the DELETE")
            seen["listed_after_delete"] = sorted(t.id for t in bus.client.list_threats(5.0))
            seen["threats"] += inject(watcher, [POPUP, CROSSING], 240, done=running)
            flight.companion.wait(300)
            seen["events"] = list(watcher.events)
        track_t, track_pos = track.samples()
        watch.join(30)
    seen["collisions"], seen["texts"] = list(track.collisions), list(track.companion_texts)
    yield {
        "rc": flight.companion.returncode,
        "summary": last_json_line(flight.log),
        "seen": seen,
        "record": load_flight(flight.record),
        "mcap": flight.record,
        "tlog": tlog,
        "live": live.get("got"),
        "log": flight.log.read_text(),
        "track_t_s": track_t,
        "track_ned_m": track_pos,
    }


def first_decision(flight, threat_id):
    mine = [e for e in flight["seen"]["events"] if e.get("threat_id") == threat_id]
    assert mine, f"no decision about {threat_id}: {flight['seen']['events']}"
    return mine[0]


def separation_m(flight, threat_id) -> float:
    """Smallest distance from the vehicle's own track to the threat's surface while it lives."""
    sent = next(t for t in flight["seen"]["threats"] if t.id == threat_id)
    stamp = next(th["t_s"] for th in flight["record"].threats if th.get("id") == threat_id)
    local = sent.to_local(LocalFrame(*DEMO_HOME))
    t, pos = flight["track_t_s"], flight["track_ned_m"]
    after = (t >= stamp) & (t <= stamp + (sent.ttl_s or np.inf))
    assert after.sum() > 50
    centre = local.pos_ned_m[None, :] + np.outer(t[after] - stamp, local.velocity_ned_m_s)
    return float(np.min(np.linalg.norm(pos[after] - centre, axis=1)) - sent.radius_m)


def test_the_flight_completes_despite_the_threats(flight):
    assert flight["rc"] == 0, flight["log"][-3000:]
    assert f"time scale {SPEEDUP:g} (the vehicle's SIM_SPEEDUP)" in flight["log"]  # no --time-scale given
    assert flight["summary"]["outcome"] == "completed"
    assert flight["summary"]["landed"] is True
    assert flight["summary"]["legs_reached"] == flight["summary"]["legs_planned"]


def test_a_head_on_mover_is_evaded_without_intrusion(flight):
    first = first_decision(flight, "headon1")
    assert first["event"] in ("evade", "switch", "replan"), first
    assert first["latency_ms"] is not None and first["latency_ms"] > 0
    assert separation_m(flight, "headon1") > 0.0


def test_a_close_popup_is_stopped_or_sidestepped_not_flown_into(flight):
    first = first_decision(flight, "popup2")
    assert first["event"] in ("hold", "evade", "switch"), first
    assert first["time_to_conflict_s"] < 3.0
    assert separation_m(flight, "popup2") > 0.0


def test_a_crossing_mover_in_the_global_frame_is_avoided_retiming_was_judged(flight):
    first = first_decision(flight, "cross3")
    assert first["event"] in ("retime", "switch", "evade", "hold", "replan"), first
    assert first["candidates"].get("retime", 0) > 0 or first["event"] == "replan"
    assert separation_m(flight, "cross3") > 0.0


def test_every_decision_is_told_once(flight):
    """Decisions carry a label, their candidates and latency; no answer is decided twice in a row."""
    decisions = [e for e in flight["seen"]["events"] if e.get("event") not in ("rejected", None)]
    assert decisions
    for e in decisions:
        assert e["label"] and isinstance(e["candidates"], dict) and "latency_ms" in e
    per_threat = {}
    for e in decisions:
        per_threat.setdefault(e.get("threat_id"), []).append(e["event"])
    assert all(len(kinds) <= 6 for kinds in per_threat.values()), per_threat


def test_the_ground_station_is_alerted_before_the_decision_then_told_its_action(flight):
    """COLLISION for the head-on mover with its CRC-32 id, first as REPORT, then with the action
    of the decision that followed; a TRAFFIC STATUSTEXT arrives before the AVOID one."""
    ident = zlib.crc32(HEAD_ON.threat_id.encode())
    mine = [(t, m) for t, m in flight["seen"]["collisions"] if m.id == ident]
    assert mine, f"no COLLISION for {HEAD_ON.threat_id}: {flight['seen']['collisions'][:5]}"
    assert all(m.src == mavlink2.MAV_COLLISION_SRC_MAVLINK_GPS_GLOBAL_INT for _, m in mine)
    first = mine[0][1]
    assert first.action == mavlink2.MAV_COLLISION_ACTION_REPORT and first.threat_level >= 1
    assert first.time_to_minimum_delta > 0.0
    acted = [
        m for _, m in mine if m.action not in (mavlink2.MAV_COLLISION_ACTION_NONE, mavlink2.MAV_COLLISION_ACTION_REPORT)
    ]
    assert acted, [(m.action, m.threat_level) for _, m in mine]
    assert mine[-1][1].threat_level == mavlink2.MAV_COLLISION_THREAT_LEVEL_NONE, "the alert was never cleared"
    texts = [(t, m.text) for t, m in flight["seen"]["texts"]]
    alert_t = next(t for t, text in texts if text.startswith(f"TRAFFIC {HEAD_ON.threat_id}"))
    avoid_t = next(t for t, text in texts if text.startswith(f"AVOID {HEAD_ON.threat_id}"))
    assert alert_t <= avoid_t
    assert any(a["threat_id"] == HEAD_ON.threat_id for a in flight["record"].alerts)


def test_an_invalid_payload_is_rejected_naming_the_field(flight):
    rejected = [e for e in flight["seen"]["events"] if e.get("event") == "rejected"]
    assert rejected and rejected[0]["threat_id"] == "broken"
    assert rejected[0]["field"]


def test_delete_removes_a_threat(flight):
    assert "far1" in flight["seen"]["listed"]
    assert "far1" not in flight["seen"]["listed_after_delete"]


def test_a_live_foxglove_client_saw_the_scene_the_threats_and_every_decision(flight):
    live = flight["live"]
    assert live is not None, "the WebSocket client never connected"
    assert LIVE_TOPICS <= live.topics()
    for topic in (ch.SCENE_WORLD, ch.SCENE_THREATS, ch.SCENE_PATHS, ch.TRANSFORMS, "/flight/threat"):
        assert live.messages.get(topic), topic
    seen = [(d["kind"], d["reason"]) for d in live.messages["/flight/decision"]]
    assert seen == [(d["kind"], d["reason"]) for d in flight["record"].decisions]
    assert {kind for kind, _ in seen} >= {"rejected"} and len(seen) >= 4


def test_the_mcap_record_has_every_channel_with_its_schema_and_monotonic_times(flight):
    with open(flight["mcap"], "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        times: dict[str, list[int]] = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            times.setdefault(channel.topic, []).append(message.log_time)
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    expected = (
        {topic for topic, _ in ch.RECORD_TOPICS.values()}
        | set(ch.SAMPLE_TOPICS)
        | {ch.SCENE_WORLD, ch.SCENE_PATHS, ch.SCENE_THREATS, ch.SCENE_VEHICLE, ch.TRANSFORMS, ch.LOCATION, ch.LOG}
    )
    assert expected <= set(schemas) and expected <= set(times)
    assert all(schema.data and schema.name for schema in schemas.values())
    assert all(stamps == sorted(stamps) for stamps in times.values())
    record = flight["record"]
    assert record.summary["outcome"] == "completed" and len(record.samples["t_s"]) > 300


def test_the_tlog_holds_the_setpoints_sent_and_the_vehicles_telemetry(flight):
    log = mavutil.mavlink_connection(str(flight["tlog"]))
    counts: dict[str, int] = {}
    stamps = []
    while (msg := log.recv_match()) is not None:
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
        stamps.append(msg._timestamp)
    assert counts.get("SET_POSITION_TARGET_LOCAL_NED", 0) > 1000  # 50 Hz for minutes
    assert counts.get("LOCAL_POSITION_NED", 0) > 500 and counts.get("HEARTBEAT", 0) > 50
    assert counts.get("COMMAND_LONG", 0) and counts.get("COMMAND_ACK", 0)
    assert stamps == sorted(stamps)
