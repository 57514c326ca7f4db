"""MAVProxy (from PyPI) loads a QGC WPL 110 file into a real ``sim-vehicle``; it flies it in AUTO.

Issue 2: MAVProxy loads the file non-interactively and the vehicle answers MISSION_ACK
ACCEPTED; then the vehicle flies the mission in AUTO to its land item and disarms. The pymavlink
peer asks for its telemetry (SET_MESSAGE_INTERVAL) and starts the rotor as with ArduCopter heli.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from support import MavlinkPeer, start_sim_vehicle

from heli_common.mavlink_ids import COPTER_MODES

pytestmark = pytest.mark.integration

DATA = Path(__file__).resolve().parents[1] / "data"
WAYPOINTS = DATA / "square_land.waypoints"
AUTO, GUIDED = COPTER_MODES["AUTO"], COPTER_MODES["GUIDED"]


def mavproxy_executable() -> str:
    local = Path(sys.executable).with_name("mavproxy.py")
    if local.exists():
        return str(local)
    found = shutil.which("mavproxy.py")
    if found is None:
        pytest.skip("mavproxy.py not installed (pip install MAVProxy)")
    return found


def read_wpl(path: Path) -> list[list[str]]:
    lines = path.read_text().splitlines()
    assert lines[0].startswith("QGC WPL 110")
    return [line.split("\t") for line in lines[1:] if line.strip()]


def load_with_mavproxy(port: int, path: Path, state_dir: Path, timeout_s: float = 30.0) -> str:
    """Run MAVProxy non-interactively with ``wp load``; returns its output once the ACK is in."""
    cmd = [
        mavproxy_executable(),
        f"--master=udpout:127.0.0.1:{port}",
        "--target-system=1",
        "--target-component=1",
        "--non-interactive",
        "--nowait",
        "--default-modules=wp,mode",
        f"--state-basedir={state_dir}",
        f"--cmd=wp load {path}",
    ]
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=str(state_dir)
    )
    lines: list[str] = []
    acked = threading.Event()

    def reader() -> None:
        for line in proc.stdout:
            lines.append(line)
            if "MISSION_ACK" in line:
                acked.set()

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    try:
        acked.wait(timeout_s)
        time.sleep(0.3)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        thread.join(timeout=5)
    return "".join(lines)


def test_mavproxy_loads_wpl_and_vehicle_flies_it_to_land(tmp_path):
    rows = read_wpl(WAYPOINTS)
    with start_sim_vehicle(speedup=10.0) as sim:
        output = load_with_mavproxy(sim.port, WAYPOINTS, tmp_path)
        assert "TYPE_MISSION: ACCEPTED" in output, f"MAVProxy output:\n{output}\nvehicle:\n{sim.log_tail()}"

        with MavlinkPeer(sim.port, sim.sysid) as gcs:
            items = gcs.download()
            assert items is not None and len(items) == len(rows)
            for item, row in zip(items, rows):
                assert item.command == int(row[3]) and item.frame == int(row[2])
                assert item.x == round(float(row[8]) * 1e7) and item.y == round(float(row[9]) * 1e7)
                assert math.isclose(item.z, float(row[10]), abs_tol=1e-3)

            gcs.request("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "EXTENDED_SYS_STATE", rate_hz=4.0)
            assert gcs.set_mode(AUTO).result == 0
            # arm in AUTO (interlock low first, as ArduCopter heli requires): the mission starts and
            # its takeoff waits for the interlock (high) and the rotor run-up
            gcs.arm_heli()

            reached: list[int] = []
            disarmed = None
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and disarmed is None:
                for msg in gcs.receive(0.1):
                    if msg.get_type() == "MISSION_ITEM_REACHED":
                        reached.append(msg.seq)
                    elif msg.get_type() == "HEARTBEAT" and not msg.base_mode & 128 and reached:
                        disarmed = msg
            assert disarmed is not None, f"no disarm; reached {reached}\n{sim.log_tail()}"
            # NAV items 1 (takeoff), 2, 4 (waypoints) and 5 (land) are reached; 3 is DO_CHANGE_SPEED
            assert reached == [1, 2, 4, 5]
            position = gcs.wait("LOCAL_POSITION_NED", 5.0)
            land_lat, land_lon = float(rows[5][8]), float(rows[5][9])
            glob = gcs.wait("GLOBAL_POSITION_INT", 5.0)
            assert abs(glob.lat - land_lat * 1e7) < 10 and abs(glob.lon - land_lon * 1e7) < 15  # about 1 m
            assert abs(position.z) < 0.05 and glob.relative_alt < 50
            state = gcs.wait("EXTENDED_SYS_STATE", 5.0)
            assert state.landed_state == 1  # MAV_LANDED_STATE_ON_GROUND
        assert sim.is_running()
