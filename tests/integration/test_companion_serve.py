"""Issue 14: ``companion serve``, the long-running service (real processes: sim-vehicle, companion
serve, a pymavlink ground station on the vehicle's other link, zenoh).

The service starts before the vehicle exists and outlives a vehicle restart; a ground station's
MISSION_START to component 191 (routed by the vehicle, as ArduPilot routes it) starts a flight of
the stored mission; the next flight, asked over zenoh, is ended by the pilot's mode change. The
vehicle is judged by its own telemetry (``TrackListener``), the service by what a ground station
sees (HEARTBEAT, COMMAND_ACK, STATUSTEXT of component 191).
"""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest
from flight_support import DEMO_HOME, TrackListener, last_json_line, run_companion, spawn, wait_until
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import MavlinkPeer

from companion.geo import LocalFrame
from companion.threats.transport.bus import ThreatBus
from heli_common.mavlink_ids import COPTER_MODES
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
COMPANION = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
HOME = DEMO_HOME
NORTH_M = 30.0  # out 30 m north and back home
NORTH_LAT = float(np.ravel(LocalFrame(*HOME).to_lla(NORTH_M, 0.0, 0.0)[0])[0])
MISSION = f"""QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t{HOME[0]}\t{HOME[1]}\t{HOME[2]}\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t10.0\t1
2\t0\t3\t16\t0\t1.0\t0\tnan\t{NORTH_LAT:.8f}\t{HOME[1]}\t10.0\t1
3\t0\t3\t16\t0\t1.0\t0\tnan\t{HOME[0]}\t{HOME[1]}\t10.0\t1
4\t0\t3\t21\t0\t0\t0\tnan\t{HOME[0]}\t{HOME[1]}\t0.0\t1
"""


def from_companion(msg) -> bool:
    return msg.get_srcComponent() == COMPANION


class GroundStation(MavlinkPeer):
    """A pymavlink ground station that keeps every STATUSTEXT of the companion it receives."""

    def __init__(self, port: int) -> None:
        self.texts: list[str] = []
        super().__init__(port, source_system=255, source_component=190)

    def receive(self, timeout_s: float = 0.05) -> list:
        out = super().receive(timeout_s)
        self.texts += [m.text for m in out if m.get_type() == "STATUSTEXT" and from_companion(m)]
        return out

    def wait_for_text(self, prefix: str, timeout_s: float, since: int = 0) -> list[str]:
        """The companion's texts from index ``since`` until one that starts with ``prefix``."""
        deadline = time.monotonic() + timeout_s
        while not any(text.startswith(prefix) for text in self.texts[since:]):
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"no STATUSTEXT {prefix!r} from the companion within {timeout_s} s; got {self.texts[since:]}"
                )
            self.receive(0.1)
        return self.texts[since:]

    def wait_while(self, predicate, timeout_s: float, what: str) -> None:
        """Listen (and heartbeat, as a ground station does) until ``predicate()``."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
            self.receive(0.1)


def mission_start(gcs: GroundStation):
    gcs.send(gcs.mav.command_long_encode(1, COMPANION, mavlink.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0))
    return gcs.wait("COMMAND_ACK", 5.0, lambda m: m.command == mavlink.MAV_CMD_MISSION_START and from_companion(m))


def sim_vehicle(tmp_path, vehicle_port: int, mav_port: int, name: str, track: TrackListener | None = None):
    outs = ["--out", f"127.0.0.1:{mav_port}"] + (["--out", track.address] if track else [])
    return spawn(
        ["sim_vehicle.cli", "--port", str(vehicle_port), *outs, "--speedup", str(SPEEDUP)], tmp_path / f"{name}.log"
    )


def test_serve_waits_for_the_vehicle_flies_each_start_and_yields_to_the_pilot(tmp_path):
    mission = tmp_path / "north.waypoints"
    mission.write_text(MISSION)
    mav_port, vehicle_port, zenoh_port = free_port(), free_port(), free_port(socket.SOCK_STREAM)
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    service = spawn(
        [
            "companion.cli",
            "-v",
            "serve",
            "--connect",
            f"udpin://127.0.0.1:{mav_port}",
            "--zenoh-listen",
            endpoint,
            "--flights",
            "2",
            "--record-dir",
            str(tmp_path / "flights"),
            "--tlog",
            str(tmp_path / "serve.tlog"),
        ],
        tmp_path / "serve.log",
    )
    log_text = lambda: (tmp_path / "serve.log").read_text(errors="replace")  # noqa: E731
    try:
        time.sleep(3.0)  # the service waits: no vehicle yet
        first = sim_vehicle(tmp_path, vehicle_port, mav_port, "sim_vehicle_1")
        try:
            with GroundStation(vehicle_port) as gcs:
                hb = gcs.wait("HEARTBEAT", 40.0, from_companion)
                assert hb is not None, f"no HEARTBEAT from component 191; log:\n{log_text()[-3000:]}"
                assert (hb.type, hb.autopilot, hb.system_status) == (
                    mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    mavlink.MAV_STATE_STANDBY,
                )
        finally:
            first.stop()
        time.sleep(5.0)  # a vehicle reboot: its heartbeats stop
        with TrackListener() as track:
            vehicle = sim_vehicle(tmp_path, vehicle_port, mav_port, "sim_vehicle_2", track)
            try:
                wait_until(
                    lambda: log_text().count("companion serve: ready") >= 2,
                    40.0,
                    "the service to be ready again after the vehicle came back",
                )
                upload = run_companion("upload", str(mission), "--connect", f"udpout://127.0.0.1:{vehicle_port}")
                assert upload.returncode == 0, upload.stderr
                with GroundStation(vehicle_port) as gcs:
                    fly_from_the_ground_station(gcs, track)
                    hand_the_next_flight_to_the_pilot(gcs, track, endpoint)
                service.wait(60.0)
            finally:
                vehicle.stop()
    finally:
        service.stop()
    assert service.returncode == 0, log_text()[-3000:]
    summaries = [json.loads(line) for line in log_text().splitlines() if line.startswith('{"flight"')]
    assert [s["flight"] for s in summaries] == [1, 2]
    assert summaries[0]["outcome"] == "completed" and summaries[0]["legs_reached"] == summaries[0]["legs_planned"]
    assert summaries[1]["outcome"].startswith("aborted") and "left GUIDED" in summaries[1]["outcome"]
    records = sorted((tmp_path / "flights").glob("flight-*.mcap"))
    assert [r.name.split("-")[1] for r in records] == ["1", "2"]


def fly_from_the_ground_station(gcs: GroundStation, track: TrackListener) -> None:
    """MISSION_START to 191: accepted, a second one refused while flying, the mission flown and
    landed (the vehicle's own track), then ready again."""
    ack = mission_start(gcs)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
    assert (ack.target_system, ack.target_component) == (255, 190)
    busy = mission_start(gcs)
    assert busy is not None and busy.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED, busy
    active = gcs.wait("HEARTBEAT", 5.0, lambda m: from_companion(m) and m.system_status == mavlink.MAV_STATE_ACTIVE)
    assert active is not None, "the companion's HEARTBEAT never said ACTIVE while flying"
    texts = gcs.wait_for_text("companion ready", 150.0)
    assert "companion: flight 1 completed" in texts, texts
    _, pos = track.samples()
    assert pos[:, 0].max() > NORTH_M - 1.5, f"the waypoint {NORTH_M} m north was not reached: {pos[:, 0].max():.1f}"
    assert -pos[:, 2].min() > 8.0, "the vehicle never climbed to the mission's 10 m"
    assert track.armed is False and -pos[-1, 2] < 0.5, "the vehicle did not land and disarm"
    assert np.hypot(*pos[-1, :2]) < 1.5, f"it did not land back home: {pos[-1]}"


def hand_the_next_flight_to_the_pilot(gcs: GroundStation, track: TrackListener, endpoint: str) -> None:
    """A zenoh command starts the next flight; the pilot switches to LOITER once it climbs: the
    companion stops commanding (the mode stays LOITER) and is ready again."""
    answers: list[dict] = []
    with ThreatBus(1, listen=(), connect=(endpoint,)) as bus:
        bus.subscribe_json(
            "events", lambda key, msg: answers.append(msg) if msg and msg.get("event") == "command" else None
        )
        time.sleep(1.0)
        bus.session.put(bus.key("command"), json.dumps({"command": "mission_start"}))
        wait_until(lambda: answers, 10.0, "the answer to the zenoh command")
    assert answers[0]["result"] == "accepted", answers
    start = len(track.track)
    gcs.wait_while(lambda: len(track.track) > start and -track.positions()[-1, 2] > 4.0, 90.0, "the second takeoff")
    loiter = COPTER_MODES["LOITER"]
    since = len(gcs.texts)
    ack = gcs.set_mode(loiter)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
    texts = gcs.wait_for_text("companion: service stopped", 30.0, since)  # after --flights 2
    assert "companion: flight 2 aborted" in texts, texts
    assert any("left GUIDED" in text for text in texts), texts
    time.sleep(2.0)
    assert track.mode == loiter, "the companion took the vehicle back from the pilot"
    assert np.isfinite(track.positions()[-1]).all()


def test_serve_resume_takes_over_the_hovering_vehicle_after_a_crash(tmp_path):
    """SIGKILL mid-leg (what systemd restarts): ``serve --resume`` finds the vehicle hovering in
    GUIDED, flies on from its current item and lands it home (the vehicle's own track)."""
    mission = tmp_path / "north.waypoints"
    mission.write_text(MISSION)
    mav_port, vehicle_port = free_port(), free_port()
    args = [
        "companion.cli",
        "-v",
        "serve",
        "--connect",
        f"udpin://127.0.0.1:{mav_port}",
        "--no-zenoh",
        "--state-dir",
        str(tmp_path / "state"),
        "--resume",
        "--flights",
        "1",
    ]
    with TrackListener() as track:
        vehicle = sim_vehicle(tmp_path, vehicle_port, mav_port, "sim_vehicle", track)
        first = second = None
        try:
            wait_until(
                lambda: (
                    run_companion("upload", str(mission), "--connect", f"udpout://127.0.0.1:{vehicle_port}").returncode
                    == 0
                ),
                60.0,
                "the upload",
            )
            first = spawn(args, tmp_path / "serve_1.log")
            with GroundStation(vehicle_port) as gcs:
                gcs.wait_for_text("companion ready", 60.0)
                ack = mission_start(gcs)
                assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
                gcs.wait_while(
                    lambda: len(track.track) > 20 and track.positions()[-1, 0] > 8.0,
                    120.0,
                    "the vehicle on its way north",
                )
                first.kill()  # a crash: no goodbye
                first.wait(10.0)
                assert "companion: service stopped" not in gcs.texts
                second = spawn(args, tmp_path / "serve_2.log")
                texts = gcs.wait_for_text("companion: flight 1 completed", 150.0, len(gcs.texts))
                assert "companion: flight 1 (resumed after a restart)" in texts, texts
            second.wait(30.0)
        finally:
            for proc in (first, second, vehicle):
                if proc is not None:
                    proc.stop()
    assert second.returncode == 0
    summary = last_json_line(tmp_path / "serve_2.log")
    assert summary["outcome"] == "completed" and summary["resumed_at_seq"] is not None, summary
    _, pos = track.samples()
    assert pos[:, 0].max() > NORTH_M - 1.5, "the waypoint north was never reached"
    assert track.armed is False and np.hypot(*pos[-1, :2]) < 1.5 and -pos[-1, 2] < 0.5, pos[-1]
