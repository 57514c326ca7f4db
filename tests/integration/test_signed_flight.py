"""Issue 11: with MAVLink 2 signing, only the companion holding the key commands the helicopter.

A real ``sim-vehicle --signing-key`` and ``companion run --signing-key`` (MAVSDK behind the
companion's signing gate) fly a mission while an intruder on the same network sends, unsigned
and signed with another key, what would end the flight: DO_SET_MODE LAND, position setpoints
far away and MISSION_CLEAR_ALL. The flight is judged by the vehicle: the companion completes
(it aborts if the mode changes under it), the vehicle's mission is still there afterwards, and
the vehicle's own counters show the intruder's frames dropped.
"""

from __future__ import annotations

import hashlib
import re
import threading

import pytest
from flight_support import run_companion
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import REPO_ROOT, MavlinkPeer, start_sim_vehicle

from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
MISSION = REPO_ROOT / "mission_files" / "square.waypoints"
PASSPHRASE = "heli-ops-2026"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()
INTRUDER_KEY = hashlib.sha256(b"a guess").digest()
LAND = 9


class Intruder(threading.Thread):
    """Sends the vehicle LAND, a far setpoint and MISSION_CLEAR_ALL, unsigned and mis-signed."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True, name="intruder")
        self.plain = MavlinkPeer(port, source_system=1, source_component=191)  # posing as the companion
        self.forger = MavlinkPeer(port, source_system=255, source_component=190, signing_key=INTRUDER_KEY)
        self.stop_event = threading.Event()
        self.rounds = 0

    def run(self) -> None:
        while not self.stop_event.wait(0.2):
            for peer in (self.plain, self.forger):
                m = peer.mav
                peer.send(
                    m.command_long_encode(
                        1,
                        1,
                        mavlink.MAV_CMD_DO_SET_MODE,
                        0,
                        mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                        LAND,
                        0,
                        0,
                        0,
                        0,
                        0,
                    )
                )
                peer.send(
                    m.set_position_target_local_ned_encode(
                        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, 80.0, -80.0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0
                    )
                )
                peer.send(m.mission_clear_all_encode(1, 1, 0))
            self.rounds += 1

    def stop(self) -> None:
        self.stop_event.set()
        self.join(timeout=2.0)
        self.plain.close()
        self.forger.close()


@pytest.fixture(scope="module")
def key_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("signing") / "heli.key"
    path.write_text(PASSPHRASE + "\n")
    return path


@pytest.fixture(scope="module")
def flight(key_file):
    port = free_port()
    with start_sim_vehicle(
        out=[f"127.0.0.1:{port}"], speedup=SPEEDUP, signing_key=KEY, extra_args=["--signing-key", str(key_file)]
    ) as sim:
        intruder = Intruder(sim.port)
        intruder.start()
        try:
            result = run_companion(
                "run",
                "--connect",
                f"udpin://127.0.0.1:{port}",
                "--mission",
                str(MISSION),
                "--time-scale",
                str(SPEEDUP),
                "--no-zenoh",
                "--signing-key",
                str(key_file),
            )
        finally:
            intruder.stop()
        with MavlinkPeer(sim.port, signing_key=KEY) as operator:
            mission = operator.download()
        yield {"result": result, "intruder": intruder, "mission": mission, "log": sim.log_text()}


def test_the_keyed_companion_completes_the_mission_under_attack(flight):
    result = flight["result"]
    assert result.returncode == 0, result.stderr[-3000:]
    assert '"outcome": "completed"' in result.stdout.strip().splitlines()[-1]
    assert flight["intruder"].rounds > 20


def test_the_intruders_mission_clear_changed_nothing(flight):
    uploaded = [line for line in MISSION.read_text().splitlines()[1:] if line.strip()]
    assert flight["mission"] is not None
    assert len(flight["mission"]) == len(uploaded)


def test_the_vehicle_dropped_the_intruders_frames_by_reason(flight):
    log = flight["log"]
    for reason in ("unsigned", "bad_signature"):
        counts = [int(n) for n in re.findall(rf"\({reason}: [A-Z_]+; (\d+) so far\)", log)]
        assert counts and max(counts) >= 10, f"no {reason} drops logged"


def test_a_companion_with_the_wrong_key_fails_with_one_line_naming_it(tmp_path):
    wrong = tmp_path / "wrong.key"
    wrong.write_text("not the operator's passphrase\n")
    config = tmp_path / "quick.toml"
    config.write_text("[link]\nconnect_timeout_s = 4.0\n")
    right = tmp_path / "right.key"
    right.write_text(PASSPHRASE)
    port = free_port()
    with start_sim_vehicle(
        out=[f"127.0.0.1:{port}"], speedup=SPEEDUP, signing_key=KEY, extra_args=["--signing-key", str(right)]
    ):
        result = run_companion(
            "run",
            "--connect",
            f"udpin://127.0.0.1:{port}",
            "--mission",
            str(MISSION),
            "--no-zenoh",
            "--config",
            str(config),
            "--signing-key",
            str(wrong),
            timeout_s=60,
        )
    assert result.returncode == 2, result.stderr[-2000:]
    errors = [line for line in result.stderr.splitlines() if line.startswith("companion: error:")]
    assert len(errors) == 1, result.stderr[-2000:]
    assert str(wrong) in errors[0] and "another key" in errors[0], errors[0]


def test_upload_and_download_sign_with_the_key_and_are_refused_without_it(key_file, tmp_path):
    with start_sim_vehicle(speedup=SPEEDUP, signing_key=KEY, extra_args=["--signing-key", str(key_file)]) as sim:
        url = f"udpout://127.0.0.1:{sim.port}"
        up = run_companion("upload", str(MISSION), "--connect", url, "--signing-key", str(key_file), timeout_s=90)
        assert up.returncode == 0, up.stderr[-2000:]
        back = tmp_path / "back.waypoints"
        down = run_companion("download", str(back), "--connect", url, "--signing-key", str(key_file), timeout_s=90)
        assert down.returncode == 0, down.stderr[-2000:]
        assert len(back.read_text().splitlines()) == len(MISSION.read_text().splitlines())
        unsigned = run_companion(
            "download", str(tmp_path / "x.waypoints"), "--connect", url, "--timeout", "3", timeout_s=60
        )
        assert unsigned.returncode == 2 and "no autopilot heard" in unsigned.stderr
