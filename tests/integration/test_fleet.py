"""Several vehicles through one zenoh router (``companion fleet up``; DESIGN 6): real processes.

Three ``sim-vehicle`` and three ``companion run`` fly ``mission_files/fleet/crossing3`` (three
legs through one point at one altitude, at about the same time, and back) through one
``companion router``, started by ``companion.fleet.launcher.Fleet``. The vehicles are judged by
their own tlogs (``companion.fleet.tracks``: GLOBAL_POSITION_INT with wall-clock stamps, on one
grid), never by the companions' records: every mission completes, and no two vehicles came
closer than ``FleetSettings().separation_m``. The numbers of the flight (separations of every
pair, lengths flown, the simulators' achieved speed-up, the CPU of the whole fleet) are in every
assertion's message.

The launcher starts the vehicles together and parks them facing their first waypoint (see
``companion.fleet.launcher``): without sharing (``--no-share``, speed-up 2) crossing3's vehicles
then came within 0.23-1.19 m of each other at the centre in four runs of four (0.47, 1.19, 0.23,
0.58 m). ``headon2`` (two vehicles along one corridor, head-on and back) is a conflict whatever
the timing (0.03 m without sharing).

Speed-up 2: three companions and three simulators on two cores keep it (the simulators' clocks
ran at 2.000x the wall clock, samples within 20 ms of it; the fleet used about half a core on
average, more at start-up while the companions load).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from flight_support import wait_until
from support import REPO_ROOT, checkout_env

from companion.fleet.launcher import Fleet
from companion.fleet.missions import select_missions
from companion.fleet.settings import FleetSettings
from companion.fleet.tracks import fleet_separation

pytestmark = pytest.mark.integration

CROSSING3 = REPO_ROOT / "mission_files" / "fleet" / "crossing3"
HEADON2 = REPO_ROOT / "mission_files" / "fleet" / "headon2"
SPEEDUP = 2.0
FLEET_TIMEOUT_S = 200.0


def fly(logs: Path, mission_dir: Path = CROSSING3, vehicles: int = 3, **kwargs) -> tuple:
    """Fly the missions of ``mission_dir``; (result, numbers, one-line description)."""
    fleet = Fleet(
        select_missions(mission_dir, vehicles), logs, speedup=SPEEDUP, gcs_out=None, env=checkout_env(), **kwargs
    )
    before, t0 = os.times(), time.monotonic()
    try:
        fleet.start()
        try:
            fleet.wait(FLEET_TIMEOUT_S)
        except TimeoutError:
            pass  # judged below: not completed
    finally:
        result = fleet.stop()
    after, wall = os.times(), time.monotonic() - t0
    cpu_s = (after.children_user + after.children_system) - (before.children_user + before.children_system)
    numbers = fleet_separation([v.tlog for v in fleet.vehicles], [v.sysid for v in fleet.vehicles])
    numbers.pop("separation")
    numbers.update(
        cpu_s=round(cpu_s, 1),
        wall_s=round(wall, 1),
        cores=round(cpu_s / wall, 2),
        vehicles=[v.as_dict() for v in result.vehicles],
    )
    (logs / "numbers.json").write_text(json.dumps(numbers, indent=1, default=str))
    text = (
        f"min separation {numbers['min_separation_m']:.2f} m (pair {numbers['closest_pair']}; every pair "
        f"{ {k: round(v, 2) for k, v in numbers['pair_min_m'].items()} }), required "
        f"{FleetSettings().separation_m:.2f} m; completed {[v.completed for v in result.vehicles]} "
        f"(outcomes {[v.outcome for v in result.vehicles]}, exit {[v.exit_code for v in result.vehicles]}); "
        f"decisions {[(v.summary or {}).get('decisions') for v in result.vehicles]}; "
        f"flown { {k: round(v, 1) for k, v in numbers['path_length_m'].items()} } m; simulators' speed-up "
        f"{ {k: round(v, 3) for k, v in numbers['speedup'].items()} }; fleet CPU {numbers['cpu_s']} s over "
        f"{numbers['wall_s']} s wall ({numbers['cores']} cores); "
        f"start gate {fleet.gate and fleet.gate.describe()}; "
        f"logs {logs}"
    )
    print(text)
    return result, numbers, text


def test_three_vehicles_crossing_at_one_point_complete_and_keep_their_separation(tmp_path):
    result, numbers, text = fly(tmp_path / "fleet")
    assert result.completed, text
    assert numbers["min_separation_m"] >= FleetSettings().separation_m, text


def test_with_trajectory_messages_delayed_150_ms_they_still_keep_their_separation(tmp_path):
    result, numbers, text = fly(tmp_path / "fleet", trajectory_delay_ms=150)
    assert result.completed, text
    assert numbers["min_separation_m"] >= FleetSettings().separation_m, text


def test_two_vehicles_head_on_along_one_corridor_complete_and_keep_their_separation(tmp_path):
    result, numbers, text = fly(tmp_path / "fleet", HEADON2, 2)
    assert result.completed, text
    assert numbers["min_separation_m"] >= FleetSettings().separation_m, text


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def processes_mentioning(text: str) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/cmdline", "rb") as fh:
                    if text.encode() in fh.read() and alive(int(entry)):
                        out.append(int(entry))
            except OSError:
                pass
    return out


def test_fleet_up_interrupted_in_flight_stops_the_companions_first_and_leaves_no_process(tmp_path):
    logs = tmp_path / "fleet"
    launcher = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "fleet",
            "up",
            "--vehicles",
            "2",
            "--mission-dir",
            str(HEADON2),
            "--speedup",
            str(SPEEDUP),
            "--logs",
            str(logs),
            "--gcs",
            "none",
        ],
        env=checkout_env(),
        cwd=str(REPO_ROOT),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_until(
            lambda: (
                all(
                    "takeoff_complete" in p.read_text(errors="replace")
                    for p in (logs / "uav1.log", logs / "uav2.log")
                    if p.exists()
                )
                and (logs / "uav2.log").exists()
            ),
            150.0,
            "both vehicles in the air",
        )
        desc = json.loads((logs / "fleet.json").read_text())
        pids = [desc["router_pid"]] + [pid for v in desc["vehicles"] for pid in v["pids"].values()]
        launcher.send_signal(signal.SIGINT)
        out, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
    assert launcher.returncode == 130, out
    summary = json.loads((logs / "summary.json").read_text())
    assert [v["outcome"] for v in summary["vehicles"]] == ["interrupted", "interrupted"], out
    assert [v["exit_code"] for v in summary["vehicles"]] == [130, 130], out
    for sysid in (1, 2):  # the companion stopped its vehicle, then exited
        assert "interrupted" in (logs / f"uav{sysid}.log").read_text(errors="replace")
    wait_until(
        lambda: not any(alive(pid) for pid in pids) and not processes_mentioning(str(logs)),
        10.0,
        f"no process of the fleet left ({[p for p in pids if alive(p)]}, {processes_mentioning(str(logs))})",
    )
