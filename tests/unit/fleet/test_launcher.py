"""companion.fleet.launcher and ``companion fleet up``'s argument checks: mission selection,
homes, the crossing missions, the command lines of the fleet's processes, and bad arguments
through the CLI (one line naming the option, exit status 2)."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from support import REPO_ROOT

from companion.errors import ConfigError, MissionError
from companion.fleet.launcher import Fleet
from companion.fleet.missions import (
    crossing_missions,
    head_on_missions,
    mission_home,
    planned_length_m,
    select_missions,
    write_missions,
)
from companion.mission import load_mission_file, mission_to_local
from companion.sitl.processes import spawn
from heli_common.frames import LocalFrame

FLEET_MISSIONS = REPO_ROOT / "mission_files" / "fleet"
CENTRE = (47.397742, 8.545594, 488.0)


def companion_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=str(REPO_ROOT),
    )


@pytest.mark.parametrize(
    "args, option",
    [
        (["--vehicles", "0", "--mission-dir", "mission_files/fleet/crossing3"], "--vehicles"),
        (["--vehicles", "2", "--mission-dir", "no/such/dir"], "--mission-dir"),
        (["--vehicles", "4", "--mission-dir", "mission_files/fleet/crossing3"], "--mission-dir"),
        (["--vehicles", "2", "--mission-dir", "mission_files/fleet/crossing3", "--speedup", "0"], "--speedup"),
        (["--vehicles", "2", "--mission-dir", "mission_files/fleet/crossing3", "--speedup", "-2"], "--speedup"),
        (
            ["--vehicles", "2", "--mission-dir", "mission_files/fleet/crossing3", "--trajectory-delay-ms", "-5"],
            "--trajectory-delay-ms",
        ),
    ],
)
def test_fleet_up_bad_arguments_are_one_line_naming_the_option(args, option, tmp_path):
    done = companion_cli("fleet", "up", "--logs", str(tmp_path / "logs"), *args)
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("companion: error: ") and option in lines[0]
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "logs").exists()  # nothing started


def test_too_few_missions_names_the_directory_and_the_count(tmp_path):
    done = companion_cli("fleet", "up", "--vehicles", "4", "--mission-dir", "mission_files/fleet/crossing3")
    assert "mission_files/fleet/crossing3 has 3 mission file(s)" in done.stderr


def test_fleet_status_without_a_fleet_directory_is_an_error(tmp_path):
    done = companion_cli("fleet", "status", "--logs", str(tmp_path))
    assert done.returncode == 2 and "--logs" in done.stderr and "fleet.json" in done.stderr


def test_select_missions_takes_the_first_n_sorted(tmp_path):
    for name in ("b.plan", "a.waypoints", "c.txt", "d.plan"):
        (tmp_path / name).write_text("x")
    assert [p.name for p in select_missions(tmp_path, 3)] == ["a.waypoints", "b.plan", "d.plan"]
    with pytest.raises(ConfigError, match=r"has 3 mission file\(s\).*--vehicles 4"):
        select_missions(tmp_path, 4)
    with pytest.raises(ConfigError, match="--vehicles"):
        select_missions(tmp_path, 0)


def test_the_home_of_a_plan_and_of_a_waypoints_file(tmp_path):
    assert mission_home(REPO_ROOT / "mission_files" / "exclusion_zones.plan") == pytest.approx(CENTRE)
    wpl = REPO_ROOT / "mission_files" / "square.waypoints"
    first = wpl.read_text().splitlines()[1].split("\t")
    assert mission_home(wpl) == pytest.approx((float(first[8]), float(first[9]), float(first[10])))
    no_home = tmp_path / "nohome.waypoints"
    no_home.write_text("QGC WPL 110\n1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t15\t1\n")
    with pytest.raises(MissionError, match="gives no home"):
        mission_home(no_home)


@pytest.mark.parametrize("directory, count", [("crossing3", 3), ("headon2", 2)])
def test_the_fleet_missions_cross_at_one_point_at_one_altitude(directory, count):
    files = select_missions(FLEET_MISSIONS / directory, count)
    centre = LocalFrame(*CENTRE)
    homes, legs = [], []
    for path in files:
        plan = load_mission_file(path)
        plan.validate()
        home = mission_home(path)
        assert home[2] == CENTRE[2]  # one ground level, one altitude
        local = mission_to_local(plan, home_lla=home)
        assert local.end_action == "rtl"
        kinds = [w.kind for w in local.waypoints]
        assert kinds == ["takeoff", "waypoint", "rtl"]
        assert all(w.pos_ned_m[2] == pytest.approx(-15.0, abs=0.01) for w in local.waypoints)
        h = centre.to_ned_array(np.array([home]))[0]
        far = h + local.waypoints[1].pos_ned_m
        homes.append(h[:2])
        legs.append((h[:2], far[:2]))
        assert 60.0 <= np.linalg.norm(h[:2]) <= 80.0 or directory == "headon2"
        # the outbound leg passes through the centre
        d = far[:2] - h[:2]
        closest = h[:2] + np.clip(-h[:2] @ d / (d @ d), 0, 1) * d
        assert np.linalg.norm(closest) < 0.5
        # about the same time: same distance home -> centre for all, same speed
        assert planned_length_m(path) < 90.0 * 7.0
    dist_to_centre = [np.linalg.norm(h) for h in homes]
    assert max(dist_to_centre) - min(dist_to_centre) < 0.5
    if count == 3:
        bearings = sorted(math.degrees(math.atan2(h[1], h[0])) % 360 for h in homes)
        assert np.diff(bearings) == pytest.approx([120.0, 120.0], abs=0.5)


def test_crossing_missions_on_a_circle(tmp_path):
    paths = write_missions(crossing_missions(5, radius_m=50.0, beyond_m=20.0), tmp_path)
    assert [p.name for p in paths] == [f"uav{k}.plan" for k in range(1, 6)]
    centre = LocalFrame(*CENTRE)
    homes = np.array([centre.to_ned_array(np.array([mission_home(p)]))[0] for p in paths])
    np.testing.assert_allclose(np.linalg.norm(homes[:, :2], axis=1), 50.0, atol=0.05)
    assert planned_length_m(paths[0]) == pytest.approx(15 + 70 + 70 + 15, abs=0.05)
    assert len(head_on_missions()) == 2


def test_fleet_command_lines(tmp_path):
    files = select_missions(FLEET_MISSIONS / "crossing3", 2)
    fleet = Fleet(files, tmp_path, speedup=2.0, share=False, trajectory_delay_ms=150, seed=7, gcs_out=None)
    v = fleet.vehicles[1]
    v.sim_port, v.companion_port, v.zenoh_listen = 40001, 40002, "tcp/127.0.0.1:40003"
    fleet.router_endpoint = "tcp/127.0.0.1:40000"
    sim = fleet.sim_command(v)
    assert sim[:3] == ["sim_vehicle.cli", "--instance", "1"]
    home = sim[sim.index("--home") + 1].split(",")
    assert [float(x) for x in home] == pytest.approx([*mission_home(files[1]), 300.0])  # facing its first leg
    assert sim[sim.index("--port") + 1] == "40001" and sim.count("--out") == 1
    assert sim[sim.index("--out") + 1] == "127.0.0.1:40002"
    assert sim[sim.index("--tlog") + 1] == str(tmp_path / "sim1.tlog")
    assert sim[sim.index("--speedup") + 1] == "2" and sim[sim.index("--seed") + 1] == "8"
    assert sim[sim.index("--config") + 1] == str(tmp_path / "sim_hold_start.toml")  # the start gate
    comp = fleet.companion_command(v)
    assert comp[:4] == ["companion.cli", "run", "--instance", "1"]
    assert comp[comp.index("--connect") + 1] == "udpin://127.0.0.1:40002"
    assert comp[comp.index("--zenoh-connect") + 1] == "tcp/127.0.0.1:40000"
    assert comp[comp.index("--zenoh-listen") + 1] == "tcp/127.0.0.1:40003"
    assert comp[comp.index("--record") + 1] == str(tmp_path / "uav2.jsonl")
    assert comp[comp.index("--time-scale") + 1] == "2"
    assert "--no-fleet" in comp and not any("delay" in arg for arg in comp)
    assert fleet.companion_env()["HELI_COMPANION_TEST_FLEET_DELAY_MS"] == "150"  # not an option of run
    assert v.sysid == 2 and fleet.paths["vehicles"][2]["tlog"] == tmp_path / "sim1.tlog"
    shared = Fleet(files, tmp_path, gcs_out="127.0.0.1:14550", sync_start=False, face_first_leg=False)
    assert "--config" not in shared.sim_command(shared.vehicles[0])
    assert shared.sim_command(shared.vehicles[0])[4].endswith(",0")
    assert "--no-fleet" not in shared.companion_command(shared.vehicles[0])
    assert shared.companion_env() is shared.env and "HELI_COMPANION_TEST_FLEET_DELAY_MS" not in (shared.env or {})
    assert shared.sim_command(shared.vehicles[0]).count("--out") == 2


def test_fleet_arguments_are_checked(tmp_path):
    files = select_missions(FLEET_MISSIONS / "headon2", 2)
    with pytest.raises(ConfigError, match="--speedup"):
        Fleet(files, tmp_path, speedup=0.0)
    with pytest.raises(ConfigError, match="--speedup"):
        Fleet(files, tmp_path, speedup=float("nan"))
    with pytest.raises(ConfigError, match="--trajectory-delay-ms"):
        Fleet(files, tmp_path, trajectory_delay_ms=-1.0)
    with pytest.raises(ConfigError, match="--vehicles"):
        Fleet([], tmp_path)


class FakeFleet(Fleet):
    """The fleet's process handling on stand-in processes: each "companion" runs until SIGINT
    (then prints a summary and exits 130), each "simulator" and the router until SIGTERM."""

    COMPANION = (
        "import json, signal, sys, time\n"
        "def stop(*_):\n"
        "    print(json.dumps({'outcome': 'interrupted', 'legs_reached': 1, 'legs_planned': 2}), flush=True)\n"
        "    sys.exit(130)\n"
        "signal.signal(signal.SIGINT, stop)\n"
        "while True: time.sleep(0.05)\n"
    )
    DONE = "import json\nprint(json.dumps({'outcome': 'completed', 'legs_reached': 2, 'legs_planned': 2}))\n"
    ROUTER = "import time\nprint('zenoh router listening on x', flush=True)\nwhile True: time.sleep(0.05)\n"

    def __init__(self, *a, finish=False, **k):
        super().__init__(*a, **k)
        self.finish = finish

    def _spawn(self, module_args, log_path, env=None):
        code = {"companion.cli": self.DONE if self.finish else self.COMPANION, "sim_vehicle.cli": self.ROUTER}
        script = self.ROUTER if module_args[1] == "router" else code[module_args[0]]
        return spawn([sys.executable, "-c", script], log_path)


def test_stop_interrupts_the_companions_then_ends_everything(tmp_path):
    files = select_missions(FLEET_MISSIONS / "crossing3", 3)
    fleet = FakeFleet(files, tmp_path, speedup=2.0)
    fleet.start()
    desc = (tmp_path / "fleet.json").read_text()
    assert fleet.router_endpoint in desc and str(fleet.vehicles[2].tlog) in desc
    with pytest.raises(TimeoutError):
        fleet.wait(0.5)
    result = fleet.stop()
    assert [v.exit_code for v in result.vehicles] == [130, 130, 130]
    assert [v.outcome for v in result.vehicles] == ["interrupted"] * 3
    assert not result.completed and "NOT all missions completed" in result.table()
    procs = [fleet.router] + [v.sim for v in fleet.vehicles] + [v.companion for v in fleet.vehicles]
    assert all(p.poll() is not None for p in procs)
    assert fleet.stop() is result  # idempotent


def test_wait_returns_once_every_companion_has_exited(tmp_path):
    files = select_missions(FLEET_MISSIONS / "headon2", 2)
    with FakeFleet(files, tmp_path, finish=True) as fleet:
        result = fleet.wait(30.0)
    assert result.completed
    assert [(v.sysid, v.exit_code, v.legs_reached) for v in result.vehicles] == [(1, 0, 2), (2, 0, 2)]
    assert result.as_dict()["completed"] is True
    assert all(v.sim.poll() is not None for v in fleet.vehicles) and fleet.router.poll() is not None


class FakeVehicle:
    """A UDP MAVLink vehicle for the start gate: HEARTBEATs (GUIDED, disarmed once ``waiting``)
    to whoever sent it something, SYS_STATUS without the pre-arm bit, PARAM_SET answered."""

    def __init__(self, sysid: int) -> None:
        import socket
        import threading

        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        self.sysid = sysid
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self.waiting = False
        self.prearm_fail = 1.0
        self.param_sets: list[tuple[float, bool]] = []  # (value, was waiting then)
        self.peer = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import time

        last = 0.0
        while not self._stop.is_set():
            try:
                data, self.peer = self.sock.recvfrom(65535)
                for msg in self.mav.parse_buffer(data) or []:
                    if msg.get_type() == "PARAM_SET" and msg.target_system == self.sysid:
                        self.prearm_fail = msg.param_value
                        self.param_sets.append((msg.param_value, self.waiting))
                        self.sock.sendto(
                            self.mav.param_value_encode(b"SIM_PREARM_FAIL", msg.param_value, 2, 1, 0).pack(self.mav),
                            self.peer,
                        )
            except OSError:
                pass
            if self.peer is not None and time.monotonic() - last > 0.1:
                last = time.monotonic()
                mode = 4 if self.waiting else 0
                self.sock.sendto(self.mav.heartbeat_encode(4, 3, 1, mode, 3).pack(self.mav), self.peer)
                self.sock.sendto(
                    self.mav.sys_status_encode(1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(self.mav), self.peer
                )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


def test_the_start_gate_releases_every_vehicle_once_all_wait_to_arm():
    import time

    from companion.fleet.start_gate import StartGate

    vehicles = [FakeVehicle(1), FakeVehicle(2)]
    try:
        gate = StartGate([(v.sysid, v.port, lambda: True) for v in vehicles], speedup=1.0).start()
        vehicles[0].waiting = True
        time.sleep(1.0)  # the other is not ready: held
        assert all(not v.param_sets for v in vehicles)
        assert gate.waiting() == [1]
        vehicles[1].waiting = True
        wait = time.monotonic() + 5.0
        while any(v.prearm_fail != 0.0 for v in vehicles) and time.monotonic() < wait:
            time.sleep(0.05)
        gate.stop()
        assert [v.prearm_fail for v in vehicles] == [0.0, 0.0]
        assert all(was_waiting for v in vehicles for _, was_waiting in v.param_sets)
        info = gate.describe()
        assert info["released"] and info["waiting_at_release"] == [1, 2] and info["confirmed"] == [1, 2]
        assert info["vehicles_report_prearm"] == {1: False, 2: False}
        assert info["max_hold_s"] == pytest.approx(gate.retry_hold_s, abs=0.06)  # they do not report pre-arm
    finally:
        for v in vehicles:
            v.close()


def test_the_start_gate_never_holds_a_ready_companion_past_its_arm_retries():
    import time

    from companion.fleet.start_gate import StartGate

    vehicles = [FakeVehicle(1), FakeVehicle(2)]
    try:
        gate = StartGate([(v.sysid, v.port, lambda: True) for v in vehicles], speedup=100.0)
        assert gate.retry_hold_s < 1.0 < gate.prearm_hold_s * 100
        gate.start()
        vehicles[0].waiting = True  # vehicle 2 is never ready
        wait = time.monotonic() + 5.0
        while vehicles[0].prearm_fail != 0.0 and time.monotonic() < wait:
            time.sleep(0.05)
        gate.stop()
        assert vehicles[0].prearm_fail == 0.0 and vehicles[1].prearm_fail == 0.0
        assert gate.describe()["waiting_at_release"] == [1]
        assert gate.held_s <= gate.retry_hold_s + 0.5
    finally:
        for v in vehicles:
            v.close()
