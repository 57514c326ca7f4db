"""Issue 25 item 6: the live Foxglove view shows the vehicle's own telemetry (real processes:
``sim-vehicle``, ``companion run`` / ``companion serve``, an independent ``foxglove.sdk.v1``
client, ``tests/foxglove_client.py``, and the vehicle's own track, ``TrackListener``).

What is asserted is behaviour, not wall-clock lag (``benchmarks/view_lag.py`` measures that):
every state the companion reads reaches the viewer, in sequence, stamped with the vehicle's
``time_boot_ms``, at the rate the companion asks for LOCAL_POSITION_NED, at the position the
vehicle reported at that stamp; and ``companion serve`` keeps the server up and the vehicle on
it before and between flights.
"""

from __future__ import annotations

import asyncio
import socket
import time

import numpy as np
import pytest
from flight_support import DEMO_HOME, TrackListener, run_companion, spawn, wait_until
from foxglove_client import collect
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import MavlinkPeer

from companion.geo import LocalFrame
from companion.link.streams import StreamSettings
from companion.view import channels as ch
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
HOME = DEMO_HOME
NORTH_M = 20.0
NORTH_LAT = float(np.ravel(LocalFrame(*HOME).to_lla(NORTH_M, 0.0, 0.0)[0])[0])
MISSION = f"""QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t{HOME[0]}\t{HOME[1]}\t{HOME[2]}\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t8.0\t1
2\t0\t3\t16\t0\t1.0\t0\tnan\t{NORTH_LAT:.8f}\t{HOME[1]}\t8.0\t1
3\t0\t3\t21\t0\t0\t0\tnan\t{NORTH_LAT:.8f}\t{HOME[1]}\t0.0\t1
"""
#: The companion's LOCAL_POSITION_NED, ms of vehicle time between two (its [link.streams] rate).
STEP_MS = 1000.0 / StreamSettings().local_position_ned_hz


def sim_vehicle(tmp_path, vehicle_port: int, companion_port: int, track: TrackListener):
    return spawn(
        [
            "sim_vehicle.cli",
            "--port",
            str(vehicle_port),
            "--out",
            f"127.0.0.1:{companion_port}",
            "--out",
            track.address,
            "--speedup",
            str(SPEEDUP),
        ],
        tmp_path / "sim_vehicle.log",
    )


def watch(port: int, seconds: float, until=None) -> list[dict]:
    """The ``/vehicle/telemetry`` messages an independent client receives."""
    return asyncio.run(collect(port, {ch.TELEMETRY}, seconds, until=until)).messages.get(ch.TELEMETRY, [])


def assert_the_vehicles_own_states(states: list[dict], track: TrackListener, frames: set[str]) -> None:
    """In sequence, none lost, one per LOCAL_POSITION_NED the companion asked for, each where the
    vehicle's own telemetry put the vehicle at the state's ``time_boot_ms``."""
    seq = np.array([s["seq"] for s in states])
    boot = np.array([s["time_boot_ms"] for s in states], dtype=float)
    assert (np.diff(seq) == 1).all(), f"states lost or out of order: {seq.tolist()}"
    assert (np.diff(boot) > 0).all()
    mean_step_ms = (boot[-1] - boot[0]) / (len(boot) - 1)  # the vehicle's scheduler alternates 80 / 120
    assert abs(mean_step_ms - STEP_MS) < 0.1 * STEP_MS, np.diff(boot)
    assert {s["frame"] for s in states} == frames
    t_s, pos = track.samples()
    inside = (boot / 1000 >= t_s[0]) & (boot / 1000 <= t_s[-1])
    assert inside.sum() >= 0.9 * len(states)
    own = np.column_stack([np.interp(boot[inside] / 1000, t_s, pos[:, k]) for k in range(3)])
    shown = np.array([s["pos_ned_m"] for s in states])[inside]
    error = np.linalg.norm(shown - own, axis=1)
    assert np.percentile(error, 95) < 0.1, f"the view's position is not the vehicle's at its stamp: {error.max():.3f} m"


def test_run_shows_every_state_of_the_vehicle_with_its_own_stamp(tmp_path):
    mission = tmp_path / "north.waypoints"
    mission.write_text(MISSION)
    companion_port, vehicle_port, fox_port = free_port(), free_port(), free_port(socket.SOCK_STREAM)
    with TrackListener() as track:
        vehicle = sim_vehicle(tmp_path, vehicle_port, companion_port, track)
        companion = spawn(
            [
                "companion.cli",
                "run",
                "--connect",
                f"udpin://127.0.0.1:{companion_port}",
                "--no-zenoh",
                "--foxglove",
                f"127.0.0.1:{fox_port}",
                "--mission",
                str(mission),
            ],
            tmp_path / "companion.log",
        )
        try:
            states = watch(fox_port, 200.0)  # until the flight ends (the server stops)
            companion.wait(30.0)
        finally:
            companion.stop()
            vehicle.stop()
    log_text = (tmp_path / "companion.log").read_text(errors="replace")
    assert companion.returncode == 0, log_text[-3000:]
    assert len(states) > 100, f"{len(states)} states; log:\n{log_text[-2000:]}"
    assert_the_vehicles_own_states(states, track, {"vehicle_local", "home"})
    shown = [s["frame"] for s in states]  # the vehicle's own frame until the planning home is set
    assert shown == sorted(shown, key=lambda frame: frame == "home"), "the frame went back"
    assert max(s["pos_ned_m"][0] for s in states) > NORTH_M - 1.5  # the flight itself was shown


def mission_start(gcs: MavlinkPeer) -> None:
    """MISSION_START to the companion's component (191), as a ground station sends it."""
    companion = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
    gcs.send(gcs.mav.command_long_encode(1, companion, mavlink.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0))
    ack = gcs.wait(
        "COMMAND_ACK", 5.0, lambda m: m.command == mavlink.MAV_CMD_MISSION_START and m.get_srcComponent() == companion
    )
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, ack


def test_serve_shows_the_vehicle_before_and_between_flights(tmp_path):
    mission = tmp_path / "north.waypoints"
    mission.write_text(MISSION)
    companion_port, vehicle_port, fox_port = free_port(), free_port(), free_port(socket.SOCK_STREAM)
    log_text = lambda: (tmp_path / "serve.log").read_text(errors="replace")  # noqa: E731
    with TrackListener() as track:
        vehicle = sim_vehicle(tmp_path, vehicle_port, companion_port, track)
        service = spawn(
            [
                "companion.cli",
                "-v",
                "serve",
                "--connect",
                f"udpin://127.0.0.1:{companion_port}",
                "--no-zenoh",
                "--foxglove",
                f"127.0.0.1:{fox_port}",
            ],
            tmp_path / "serve.log",
        )
        try:
            wait_until(lambda: "companion serve: ready" in log_text(), 60.0, "the service to be ready")
            before = watch(fox_port, 6.0)  # no flight yet
            assert_the_vehicles_own_states(before, track, {"vehicle_local"})
            assert np.linalg.norm(before[-1]["pos_ned_m"]) < 1.0, before[-1]  # on the ground at home
            upload = run_companion("upload", str(mission), "--connect", f"udpout://127.0.0.1:{vehicle_port}")
            assert upload.returncode == 0, upload.stderr
            with MavlinkPeer(vehicle_port, source_system=255, source_component=190) as gcs:
                mission_start(gcs)
            wait_until(lambda: log_text().count("companion serve: ready") >= 2, 150.0, "the flight to end")
            time.sleep(1.0)
            after = watch(fox_port, 6.0)  # no flight runs: the same server
        finally:
            service.stop()
            vehicle.stop()
    assert '"outcome": "completed"' in log_text(), log_text()[-3000:]
    assert_the_vehicles_own_states(after, track, {"home"})
    landed = np.array(after[-1]["pos_ned_m"])
    assert abs(landed[0] - NORTH_M) < 1.5 and abs(landed[2]) < 0.5, landed  # where it landed, north
    assert after[0]["seq"] > before[-1]["seq"]  # the one feed, still counting
