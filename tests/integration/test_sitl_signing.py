"""MAVLink 2 signing of a real ``sim-vehicle`` (issue 11): pymavlink and MAVProxy with the key fly it,
unsigned, wrongly signed and replayed frames change nothing and are counted; SETUP_SIGNING rules.

Every client asks for its telemetry with SET_MESSAGE_INTERVAL and starts the rotor as with
ArduCopter heli (``MavlinkPeer`` helpers).
"""

from __future__ import annotations

import ast
import hashlib
import re
import subprocess
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import MavlinkPeer, start_sim_vehicle
from test_sitl_mavproxy import mavproxy_executable

pytestmark = pytest.mark.integration

GUIDED, LAND, BRAKE = 4, 9, 17
PASSPHRASE = "tango-sierra-42"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()  # what MAVProxy's "signing key PASSPHRASE" uses
WRONG_KEY = hashlib.sha256(b"not the key").digest()
MISSION = [  # frame, command, p1..p4, x, y, z
    (0, 16, 0.0, 0.0, 0.0, 0.0, 473977420, 85455940, 488.0),
    (3, 22, 0.0, 0.0, 0.0, 0.0, 0, 0, 10.0),
    (3, 16, 0.0, 2.0, 0.0, 0.0, 473978320, 85455940, 10.0),
]
POSITION_ONLY = 0b110111111000  # type_mask: position, no velocity, acceleration or yaw


def key_file(tmp_path: Path, text: str, name: str = "signing.key") -> str:
    path = tmp_path / name
    path.write_text(text + "\n")
    return str(path)


def link_statistics(log_text: str) -> dict:
    """The counters the vehicle logs at shutdown."""
    found = re.findall(r"link statistics: (\{.*\})", log_text)
    assert found, log_text[-3000:]
    return ast.literal_eval(found[-1])


def mode_of(gcs: MavlinkPeer) -> int:
    heartbeat = gcs.wait("HEARTBEAT", 3.0)
    assert heartbeat is not None
    return heartbeat.custom_mode


def unanswered_set_mode(peer: MavlinkPeer, mode: int) -> bool:
    """DO_SET_MODE from ``peer``: True if no COMMAND_ACK comes back (a dropped sender is not a peer)."""
    return (
        peer.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, timeout_s=1.5)
        is None
    )


def set_mode_frame(mav, sysid: int, mode: int) -> bytes:
    return bytes(
        mav.command_long_encode(
            sysid, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, 0, 0, 0, 0, 0
        ).pack(mav)
    )


@pytest.fixture
def mavutil_v2(monkeypatch):
    """mavutil with the MAVLink 2 dialect (signing needs it), put back afterwards."""
    monkeypatch.setenv("MAVLINK20", "1")
    mavutil.set_dialect("ardupilotmega")
    yield mavutil
    monkeypatch.undo()
    mavutil.set_dialect("ardupilotmega")


def test_mavutil_client_with_the_key_reads_params_changes_mode_and_arms(tmp_path, mavutil_v2):
    with start_sim_vehicle(
        speedup=5.0, extra_args=["--signing-key", key_file(tmp_path, KEY.hex())], signing_key=KEY
    ) as sim:
        conn = mavutil_v2.mavlink_connection(f"udpout:127.0.0.1:{sim.port}", source_system=250, source_component=190)
        try:
            conn.setup_signing(KEY, sign_outgoing=True)
            m = conn.mav
            conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            heartbeat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10.0)
            assert heartbeat is not None and heartbeat.get_signed() and heartbeat.get_srcSystem() == sim.sysid

            def command(cmd: int, *params: float):
                p = list(params) + [0.0] * (7 - len(params))
                m.command_long_send(sim.sysid, 1, cmd, 0, *p)
                return conn.recv_match(
                    type="COMMAND_ACK", blocking=True, timeout=5.0, condition=f"COMMAND_ACK.command=={cmd}"
                )

            ack = command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 200_000)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
            position = conn.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5.0)
            assert position is not None and position.get_signed()

            m.param_request_read_send(sim.sysid, 1, b"WPNAV_SPEED", -1)
            param = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=5.0)
            assert param is not None and param.param_id == "WPNAV_SPEED" and param.param_value == 500.0

            ack = command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
            ack = command(mavlink.MAV_CMD_DO_AUX_FUNCTION, 32, 0)  # motor interlock low, as ArduCopter heli
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
            ack = command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
            armed = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0, condition="HEARTBEAT.base_mode & 128")
            assert armed is not None and armed.custom_mode == GUIDED
            assert conn.mav.signing.badsig_count == 0  # everything the vehicle sent was signed with the key
        finally:
            conn.close()
    stats = link_statistics(sim.log_text())
    assert stats["unsigned"] == stats["bad_signature"] == stats["replayed"] == stats["stale"] == 0


def test_unsigned_wrong_and_replayed_frames_change_nothing_and_are_counted(tmp_path):
    with start_sim_vehicle(
        speedup=5.0, extra_args=["--signing-key", key_file(tmp_path, PASSPHRASE)], signing_key=KEY
    ) as sim:
        with (
            MavlinkPeer(sim.port, sim.sysid, signing_key=KEY) as gcs,
            MavlinkPeer(sim.port, sim.sysid, source_system=251) as unsigned,
            MavlinkPeer(sim.port, sim.sysid, source_system=252, signing_key=WRONG_KEY) as wrong,
        ):
            assert gcs.upload(MISSION) == mavlink.MAV_MISSION_ACCEPTED
            gcs.request("LOCAL_POSITION_NED", rate_hz=5.0)
            gcs.heli_takeoff(5.0)
            hover = gcs.wait("LOCAL_POSITION_NED", 40.0, lambda p: abs(p.z + 5.0) < 0.2 and abs(p.vz) < 0.1)
            assert hover is not None, sim.log_tail()

            # ---- unsigned and wrongly signed: LAND, a setpoint 15 m away, MISSION_CLEAR_ALL
            for peer in (unsigned, wrong):
                assert unanswered_set_mode(peer, LAND)  # the vehicle does not even answer
                peer.send(peer.mav.mission_clear_all_encode(sim.sysid, 1, 0))
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                for peer in (unsigned, wrong):
                    peer.send(
                        peer.mav.set_position_target_local_ned_encode(
                            0,
                            sim.sysid,
                            1,
                            mavlink.MAV_FRAME_LOCAL_NED,
                            POSITION_ONLY,
                            15.0,
                            0.0,
                            -5.0,
                            0,
                            0,
                            0,
                            0,
                            0,
                            0,
                            0,
                            0,
                        )
                    )
                gcs.receive(0.1)
            assert mode_of(gcs) == GUIDED
            here = gcs.wait("LOCAL_POSITION_NED", 3.0)
            assert abs(here.x - hover.x) < 1.0 and abs(here.y - hover.y) < 1.0 and abs(here.z + 5.0) < 0.5
            items = gcs.download()
            assert items is not None and len(items) == len(MISSION)

            # ---- an unsigned STATUSTEXT of the companion is not routed; a signed one is
            companion_ids = dict(source_system=sim.sysid, source_component=191)
            with (
                MavlinkPeer(sim.port, sim.sysid, signing_key=KEY, **companion_ids) as companion,
                MavlinkPeer(sim.port, sim.sysid, **companion_ids) as fake,
            ):
                fake.send(fake.mav.statustext_encode(mavlink.MAV_SEVERITY_ALERT, b"unsigned alert"))
                companion.send(companion.mav.statustext_encode(mavlink.MAV_SEVERITY_INFO, b"signed note"))
                texts = []
                deadline = time.monotonic() + 3.0
                while time.monotonic() < deadline and "signed note" not in texts:
                    texts += [msg.text for msg in gcs.receive(0.1) if msg.get_type() == "STATUSTEXT"]
                assert "signed note" in texts and "unsigned alert" not in texts

            # ---- a replayed signed frame: captured BRAKE, then GUIDED again, then the capture once more
            captured = set_mode_frame(gcs.mav, sim.sysid, BRAKE)
            gcs.send_raw(captured)
            assert gcs.wait("COMMAND_ACK", 3.0, lambda a: a.command == mavlink.MAV_CMD_DO_SET_MODE).result == 0
            assert gcs.wait("HEARTBEAT", 3.0, lambda h: h.custom_mode == BRAKE) is not None
            assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED
            gcs.send_raw(captured)
            assert gcs.wait("COMMAND_ACK", 1.5, lambda a: a.command == mavlink.MAV_CMD_DO_SET_MODE) is None
            assert mode_of(gcs) == GUIDED

            # ---- control: the same setpoint signed with the key is followed
            followed = None
            deadline = time.monotonic() + 20.0
            while time.monotonic() < deadline and followed is None:
                gcs.send(
                    gcs.mav.set_position_target_local_ned_encode(
                        0,
                        sim.sysid,
                        1,
                        mavlink.MAV_FRAME_LOCAL_NED,
                        POSITION_ONLY,
                        hover.x + 3.0,
                        hover.y,
                        -5.0,
                        0,
                        0,
                        0,
                        0,
                        0,
                        0,
                        0,
                        0,
                    )
                )
                followed = gcs.wait("LOCAL_POSITION_NED", 0.3, lambda p: p.x > hover.x + 1.5)
            assert followed is not None
            unsigned_port, wrong_port = unsigned.sock.getsockname()[1], wrong.sock.getsockname()[1]
    log_text = sim.log_text()
    stats = link_statistics(log_text)
    # at least: a heartbeat, COMMAND_LONG, MISSION_CLEAR_ALL and a setpoint each (and the fake STATUSTEXT)
    assert stats["unsigned"] >= 5 and stats["bad_signature"] >= 4, stats
    assert stats["replayed"] == 1 and stats["stale"] == 0, stats
    assert f"dropped unauthenticated message from 127.0.0.1:{unsigned_port} (unsigned: COMMAND_LONG" in log_text
    assert f"dropped unauthenticated message from 127.0.0.1:{wrong_port} (bad_signature: COMMAND_LONG" in log_text
    assert "(replayed: COMMAND_LONG" in log_text
    assert "mode GUIDED -> LAND" not in log_text


class Mavproxy:
    """MAVProxy from the venv, driven line by line on stdin (interactive mode: ``--non-interactive``
    does not read stdin), its output collected by a thread."""

    def __init__(self, port: int, state_dir: Path, startup: str = "") -> None:
        cmd = [
            mavproxy_executable(),
            f"--master=udpout:127.0.0.1:{port}",
            "--target-system=1",
            "--target-component=1",
            "--default-modules=signing,param,mode",
            f"--state-basedir={state_dir}",
        ]
        if startup:
            cmd.append(f"--cmd={startup}")
        self.proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=str(state_dir)
        )
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def send(self, line: str) -> None:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match | None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            found = re.search(pattern, self.output)
            if found:
                return found
            time.sleep(0.1)
        return None

    def close(self) -> None:
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        self.proc.terminate()
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.thread.join(timeout=5)


def test_mavproxy_with_the_passphrase_reads_params_and_changes_mode(tmp_path):
    with (
        start_sim_vehicle(
            speedup=5.0, extra_args=["--signing-key", key_file(tmp_path, PASSPHRASE)], signing_key=KEY
        ) as sim,
        MavlinkPeer(sim.port, sim.sysid, signing_key=KEY) as watcher,
    ):
        mavproxy = Mavproxy(sim.port, tmp_path, startup=f"signing key {PASSPHRASE}")
        try:
            assert mavproxy.wait_for(r"Detected vehicle 1:1", 30.0), mavproxy.output
            mavproxy.send("param fetch WPNAV_SPEED")
            assert mavproxy.wait_for(r"WPNAV_SPEED = 500", 15.0), mavproxy.output
            mavproxy.send("mode GUIDED")
            assert mavproxy.wait_for(r"DO_SET_MODE: ACCEPTED", 15.0), mavproxy.output
            assert watcher.wait("HEARTBEAT", 5.0, lambda h: h.custom_mode == GUIDED) is not None
        finally:
            mavproxy.close()
    stats = link_statistics(sim.log_text())
    assert stats["unsigned"] == 0 and stats["bad_signature"] == 0, stats


def test_mavproxy_with_a_wrong_passphrase_is_not_heard(tmp_path):
    with start_sim_vehicle(
        speedup=5.0, extra_args=["--signing-key", key_file(tmp_path, PASSPHRASE)], signing_key=KEY
    ) as sim:
        mavproxy = Mavproxy(sim.port, tmp_path, startup="signing key wrong-passphrase")
        try:
            mavproxy.send("mode LAND")
            time.sleep(4.0)
            assert "Detected vehicle" not in mavproxy.output
        finally:
            mavproxy.close()
    stats = link_statistics(sim.log_text())
    assert stats["bad_signature"] >= 2, stats  # MAVProxy's heartbeats at least
    assert "-> LAND" not in sim.log_text()


def setup_signing_frame(mav, sysid: int, key: bytes, timestamp: int = 0) -> bytes:
    return bytes(mav.setup_signing_encode(sysid, 1, list(key), timestamp).pack(mav))


def test_setup_signing_signed_with_the_current_key_changes_it_unsigned_is_refused(tmp_path):
    new_key = hashlib.sha256(b"the new key").digest()
    with start_sim_vehicle(
        speedup=5.0, extra_args=["--signing-key", key_file(tmp_path, KEY.hex())], signing_key=KEY
    ) as sim:
        with MavlinkPeer(sim.port, sim.sysid, source_system=251) as unsigned:
            unsigned.send_raw(setup_signing_frame(unsigned.mav, sim.sysid, new_key))
        with MavlinkPeer(sim.port, sim.sysid, signing_key=KEY) as gcs:
            assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED  # the old key still works
            gcs.send_raw(setup_signing_frame(gcs.mav, sim.sysid, new_key))
            gcs.wait("NONE", 0.5)  # what the vehicle sent before it took the new key
            assert gcs.wait("HEARTBEAT", 3.0) is None  # the vehicle now signs with the new key only
        with MavlinkPeer(sim.port, sim.sysid, signing_key=new_key) as new:
            assert new.set_mode(BRAKE).result == mavlink.MAV_RESULT_ACCEPTED
        with MavlinkPeer(sim.port, sim.sysid, signing_key=KEY) as old:
            assert unanswered_set_mode(old, GUIDED)
    log_text = sim.log_text()
    stats = link_statistics(log_text)
    assert stats["unsigned"] >= 2 and stats["bad_signature"] >= 2, stats
    assert "(unsigned: SETUP_SIGNING" in log_text
    assert log_text.count("SETUP_SIGNING from") == 1 and "signing key " in log_text


def test_without_a_key_setup_signing_needs_accept_signing_setup(tmp_path):
    with start_sim_vehicle(speedup=5.0) as sim, MavlinkPeer(sim.port, sim.sysid) as plain:
        plain.send_raw(setup_signing_frame(plain.mav, sim.sysid, KEY))
        assert plain.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED  # still unsigned
    assert (
        "SETUP_SIGNING from" in sim.log_text()
        and "refused: no signing key and no --accept-signing-setup" in sim.log_text()
    )

    with (
        start_sim_vehicle(speedup=5.0, extra_args=["--accept-signing-setup"]) as sim,
        MavlinkPeer(sim.port, sim.sysid, signing_key=KEY) as watcher,
    ):
        mavproxy = Mavproxy(sim.port, tmp_path)
        try:
            assert mavproxy.wait_for(r"Detected vehicle 1:1", 30.0), mavproxy.output
            mavproxy.send(f"signing setup {PASSPHRASE}")  # unsigned SETUP_SIGNING, then MAVProxy signs
            assert mavproxy.wait_for(r"Setup signing key", 10.0), mavproxy.output
            assert watcher.wait("HEARTBEAT", 10.0) is not None  # the vehicle signs with the passphrase's key
            mavproxy.send("mode GUIDED")
            assert watcher.wait("HEARTBEAT", 10.0, lambda h: h.custom_mode == GUIDED) is not None, mavproxy.output
            with MavlinkPeer(sim.port, sim.sysid, source_system=251) as unsigned:
                assert unanswered_set_mode(unsigned, LAND)
        finally:
            mavproxy.close()
    assert "-> LAND" not in sim.log_text()
    assert link_statistics(sim.log_text())["unsigned"] >= 1
