"""Issue 11: a companion killed in flight, taken over by ``companion run --resume``; a zenoh
router that stops and comes back (real processes: sim-vehicle, companion run, companion router).

The vehicle is judged by its own telemetry (``TrackListener``, an independent pymavlink
listener), never by the companion's logs.
"""

from __future__ import annotations

import signal
import socket
import time

import numpy as np
import pytest
from flight_support import FlightWatcher, Injection, TrackListener, inject, last_json_line, spawn, wait_until
from support import REPO_ROOT

from companion.record.flight_record import load_record
from companion.threats.model import Threat
from companion.threats.snapshot import read_snapshot, snapshot_path
from companion.threats.transport.bus import ThreatBus
from heli_common.mavlink_ids import COPTER_MODES
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
SPEEDUP = 4.0
GUIDED = COPTER_MODES["GUIDED"]
GUIDED_TIMEOUT_S = 3.0  # sim-vehicle's default GUID_TIMEOUT (simulated s)
BRAKE_S = 6.0  # simulated s allowed for braking to a hover after it
THREAT_TTL_S = 2000.0  # simulated s: alive through the crash and the rest of the flight
THREAT_RADIUS_M = 3.0


def companion_args(mav_port: int, zenoh_listen: str, record, *extra: str) -> list[str]:
    return [
        "companion.cli",
        "-v",
        "run",
        "--connect",
        f"udpin://127.0.0.1:{mav_port}",
        "--time-scale",
        str(SPEEDUP),
        "--zenoh-listen",
        zenoh_listen,
        "--record",
        str(record),
        *extra,
    ]


def vehicle(tmp_path, mav_port: int, track: TrackListener):
    return spawn(
        [
            "sim_vehicle.cli",
            "--port",
            str(free_port()),
            "--out",
            f"127.0.0.1:{mav_port}",
            "--out",
            track.address,
            "--speedup",
            str(SPEEDUP),
        ],
        tmp_path / "sim_vehicle.log",
    )


def midpoint_of(path_ned_m) -> np.ndarray:
    """The point halfway along a polyline (by length)."""
    path = np.asarray(path_ned_m, dtype=float)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    half = s[-1] / 2.0
    return np.array([np.interp(half, s, path[:, i]) for i in range(3)])


def horizontal_speed(track: TrackListener, over_s: float = 1.0) -> float:
    """The vehicle's mean horizontal speed over its last ``over_s`` simulated seconds (its own track)."""
    t, pos = track.samples()
    if len(t) < 2 or t[-1] - t[0] < over_s:
        return 0.0
    recent = pos[t >= t[-1] - over_s]
    return float(np.linalg.norm(recent[-1, :2] - recent[0, :2])) / over_s


def window(track_t, track_pos, t0: float, t1: float) -> np.ndarray:
    return track_pos[(track_t >= t0) & (track_t <= t1)]


def test_a_killed_companion_leaves_a_hover_and_resume_finishes_the_mission_with_its_threats(tmp_path):
    mav_port, state = free_port(), tmp_path / "state"
    first_zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    with TrackListener() as track:
        sim = vehicle(tmp_path, mav_port, track)
        first = spawn(
            companion_args(
                mav_port, first_zenoh, tmp_path / "first.jsonl", "--mission", str(MISSION), "--state-dir", str(state)
            ),
            tmp_path / "first.log",
        )
        second = None
        try:
            # -------- first companion: a threat on a later leg, then SIGKILL mid-leg
            with ThreatBus(1, listen=(), connect=(first_zenoh,)) as bus:
                watcher = FlightWatcher(bus)
                wait_until(
                    lambda: watcher.status and watcher.status["leg"] >= 0 and watcher.status["path_id"],
                    180,
                    "leg 0 flown",
                )
                wait_until(lambda: 7 in _plans(tmp_path / "first.jsonl"), 30, "the plans in the record")
                plans = _plans(tmp_path / "first.jsonl")
                # on the return leg (item 6 to home): a straight line whichever way GART took around
                # the exclusion zones, so the resumed companion's own plan meets it too
                centre = midpoint_of(plans[7]["path_ned_m"])
                threat = Threat(
                    "keep1",
                    "popup",
                    "local_ned",
                    tuple(map(float, centre)),
                    (0.0, 0.0, 0.0),
                    THREAT_RADIUS_M,
                    THREAT_TTL_S,
                )
                assert bus.client.wait_for_subscriber(10.0, threat.id)
                bus.client.put_threat(threat)
                wait_until(lambda: _snapshot_ids(state) == ["keep1"], 30, "the threat in the snapshot")
                wait_until(lambda: watcher.status["leg"] >= 1, 120, "leg 1 (towards item 4)")
                wait_until(lambda: horizontal_speed(track) > 2.0, 60, "the vehicle under way on leg 1")
                leg_at_kill = watcher.status["leg"]
            kill_track_t = track.samples()[0][-1]
            first.send_signal(signal.SIGKILL)
            first.wait(10)
            # -------- the vehicle on its own: brakes to a hover after its guided timeout
            wait_until(
                lambda: track.samples()[0][-1] > kill_track_t + GUIDED_TIMEOUT_S + BRAKE_S + 2.0,
                60,
                "the vehicle's track after the kill",
            )
            t, pos = track.samples()
            before = window(t, pos, kill_track_t - 1.0, kill_track_t)
            hover = window(
                t, pos, kill_track_t + GUIDED_TIMEOUT_S + BRAKE_S, kill_track_t + GUIDED_TIMEOUT_S + BRAKE_S + 2.0
            )
            assert np.linalg.norm(before[-1, :2] - before[0, :2]) > 1.0, "it was flying when killed"
            assert len(hover) >= 5
            assert np.ptp(hover[:, 0]) < 0.5 and np.ptp(hover[:, 1]) < 0.5, "it hovers (under 0.25 m/s)"
            assert hover[:, 2].max() < -5.0, "in the air"
            assert track.armed is True and track.mode == GUIDED
            resume_track_t = t[-1]
            # -------- the resumed companion
            second_zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
            second = spawn(
                companion_args(
                    mav_port, second_zenoh, tmp_path / "second.jsonl", "--resume", "--state-dir", str(state)
                ),
                tmp_path / "second.log",
            )
            assert second.wait(300) == 0, (tmp_path / "second.log").read_text()[-3000:]
            wait_until(lambda: track.armed is False, 30, "the vehicle's disarm after landing")
            t, pos = track.samples()
        finally:
            for proc in (second, first, sim):
                if proc is not None:
                    proc.stop()
    summary = last_json_line(tmp_path / "second.log")
    record = load_record(tmp_path / "second.jsonl")
    seq_of_leg = {p["leg"]: p["seq"] for p in load_record(tmp_path / "first.jsonl").plans}
    current = seq_of_leg[leg_at_kill]  # 4 unless the machine is very slow
    remaining = [q for q in (2, 4, 5, 6, 7) if q >= current]
    events = {e["name"]: e for e in record.events}
    # it took over at the leg flown when the first one died, and flew the rest
    assert summary["outcome"] == "completed" and summary["landed"] is True
    assert summary["resumed_at_seq"] == current and summary["joined"] is True
    reached = [e["seq"] for e in record.events if e["name"] == "reached"]
    assert reached == remaining
    # the threat put before the crash: restored with its remaining TTL, and kept out of
    assert summary["threats_restored"] == 1 and events["threats_restored"]["ids"] == ["keep1"]
    ttl_left = events["threats_restored"]["remaining_ttl_s"]["keep1"]
    assert 0.0 < ttl_left < THREAT_TTL_S - GUIDED_TIMEOUT_S
    assert any(th.get("id") == "keep1" and th.get("restored") for th in record.threats)
    assert any(d.get("threat_id") == "keep1" for d in record.decisions), "decided on from the restored table"
    # judged by the vehicle: every remaining goal visited after the resume, no sample in the threat
    after = pos[t >= resume_track_t]
    goals = {p["seq"]: np.asarray(p["path_ned_m"])[-1] for p in load_record(tmp_path / "first.jsonl").plans}
    for seq in [q for q in remaining if q != 7]:
        closest = np.min(np.linalg.norm(after - goals[seq], axis=1))
        assert closest < 3.0, f"item {seq}: the vehicle came no closer than {closest:.1f} m"
    assert np.min(np.linalg.norm(pos - centre, axis=1)) > THREAT_RADIUS_M
    assert pos[-1, 2] > -1.0, "landed"


def _plans(record_path) -> dict:
    return {p["seq"]: p for p in load_record(record_path).plans}


def _snapshot_ids(state) -> list[str]:
    snap = read_snapshot(snapshot_path(state, 1))
    return [] if snap is None else [t.id for t in snap.threats]


def test_resume_refuses_a_vehicle_on_the_ground(tmp_path):
    mav_port = free_port()
    with TrackListener() as track:
        sim = vehicle(tmp_path, mav_port, track)
        companion = spawn(
            companion_args(
                mav_port, f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}", tmp_path / "r.jsonl", "--resume"
            ),
            tmp_path / "companion.log",
        )
        try:
            assert companion.wait(120) == 2
        finally:
            companion.stop()
            sim.stop()
    text = (tmp_path / "companion.log").read_text()
    assert "cannot resume: the vehicle is not flying" in text
    assert track.armed is False


AFTER_RESTART = Injection("after1", "popup", leg=3, after_s=3.0, ahead_s=5.0, radius_m=3.0, ttl_s=300.0)


def router(port: int, log_path):
    """``companion router`` on ``port``, once it says it listens."""
    proc = spawn(["companion.cli", "router", "--listen", f"tcp/127.0.0.1:{port}"], log_path)
    wait_until(
        lambda: "zenoh router listening" in log_path.read_text(errors="replace") or proc.poll() is not None,
        60,
        "the router",
    )
    assert proc.poll() is None, log_path.read_text()
    return proc


def test_a_router_that_stops_and_returns_loses_neither_the_flight_nor_later_threats(tmp_path):
    mav_port, router_port = free_port(), free_port(socket.SOCK_STREAM)
    router_ep = f"tcp/127.0.0.1:{router_port}"
    with TrackListener() as track:
        sim = vehicle(tmp_path, mav_port, track)
        rtr = router(router_port, tmp_path / "router1.log")
        companion = spawn(
            companion_args(
                mav_port,
                f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}",
                tmp_path / "flight.jsonl",
                "--mission",
                str(MISSION),
                "--zenoh-connect",
                router_ep,
            ),
            tmp_path / "companion.log",
        )
        try:
            with ThreatBus(1, listen=(), connect=(router_ep,), mode="client") as bus:
                watcher = FlightWatcher(bus)
                wait_until(lambda: watcher.status and watcher.status["leg"] >= 1, 180, "leg 1 through the router")
            rtr.send_signal(signal.SIGKILL)
            rtr.wait(10)
            down_track_t = track.samples()[0][-1]
            time.sleep(3.0)
            rtr = router(router_port, tmp_path / "router2.log")
            with ThreatBus(1, listen=(), connect=(router_ep,), mode="client") as bus:
                watcher = FlightWatcher(bus)
                wait_until(lambda: watcher.status is not None, 60, "status through the restarted router")
                sent = inject(watcher, [AFTER_RESTART], 240, done=lambda: companion.poll() is not None)
                assert [t.id for t in sent] == ["after1"]
                wait_until(
                    lambda: any(e.get("threat_id") == "after1" for e in watcher.events),
                    30,
                    "a decision about the threat put after the restart",
                )
                assert companion.wait(300) == 0, (tmp_path / "companion.log").read_text()[-3000:]
            t, pos = track.samples()
        finally:
            companion.stop()
            rtr.stop()
            sim.stop()
    summary = last_json_line(tmp_path / "companion.log")
    assert summary["outcome"] == "completed" and summary["legs_reached"] == summary["legs_planned"]
    names = [e["name"] for e in load_record(tmp_path / "flight.jsonl").events]
    assert "zenoh_lost" in names and "zenoh_back" in names
    # the vehicle flew on while the router was down (its own track: it kept moving)
    during = window(t, pos, down_track_t, down_track_t + 3.0 * SPEEDUP)
    assert np.linalg.norm(during[-1, :2] - during[0, :2]) > 5.0
