"""Issue 5: the companion survives a dropped link and stops safely on SIGINT (real processes)."""

from __future__ import annotations

import signal
import time

import pytest
from flight_support import FlightWatcher, flight_processes, last_json_line, wait_until
from support import REPO_ROOT, MavlinkPeer

from companion.record.flight_record import load_record
from companion.threats.transport.bus import ThreatBus

pytestmark = pytest.mark.integration

MISSION = REPO_ROOT / "mission_files" / "exclusion_zones.plan"
LOITER = 5


def flying_leg_1(watcher: FlightWatcher) -> bool:
    return bool(watcher.status and watcher.status["leg"] >= 1 and watcher.status["path_id"])


def test_sigint_in_flight_leaves_the_vehicle_hovering_in_loiter(tmp_path):
    with flight_processes(tmp_path, MISSION, speedup=4.0) as flight:
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = FlightWatcher(bus)
            wait_until(lambda: flying_leg_1(watcher), 120, "leg 1")
        flight.companion.send_signal(signal.SIGINT)
        assert flight.companion.wait(30) == 130, flight.log.read_text()[-2000:]
        assert last_json_line(flight.log)["outcome"] == "interrupted"
        with MavlinkPeer(flight.vehicle_port, 1) as gcs:
            hb = gcs.wait("HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1)
            assert hb.custom_mode == LOITER
            assert hb.base_mode & 128, "the vehicle must still be armed (hovering, not dropped)"
            gcs.request("LOCAL_POSITION_NED")  # as ArduPilot: only what is asked for
            first = gcs.wait("LOCAL_POSITION_NED", 5.0)
            time.sleep(1.0)
            later = gcs.wait("LOCAL_POSITION_NED", 5.0)
            assert first.z < -10.0 and later.z < -10.0
            assert abs(later.x - first.x) + abs(later.y - first.y) < 2.0


def test_a_dropped_link_is_survived_and_the_mission_completed(tmp_path):
    with flight_processes(tmp_path, MISSION, speedup=4.0) as flight:
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = FlightWatcher(bus)
            wait_until(lambda: flying_leg_1(watcher), 120, "leg 1")
            flight.sim.send_signal(signal.SIGSTOP)  # no heartbeat, no telemetry for 4 s
            time.sleep(4.0)
            flight.sim.send_signal(signal.SIGCONT)
            assert flight.companion.wait(240) == 0, flight.log.read_text()[-3000:]
        summary = last_json_line(flight.log)
        assert summary["outcome"] == "completed" and summary["legs_reached"] == summary["legs_planned"]
        names = [e["name"] for e in load_record(flight.record).events]
        assert "link_lost" in names and "link_back" in names and "resumed" in names
