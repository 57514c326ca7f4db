"""Issue 11: every command is answered to its own sender, even when two stations command at once.

A common deployment: MAVProxy on the companion computer is the vehicle's router, and forwards
everything the vehicle sends to every output, so the companion also sees the COMMAND_ACKs the
vehicle addresses to the ground station. Here the ground station (pymavlink, system 255)
sends commands at 20 Hz through the same MAVProxy, refused ones included (a NAV_TAKEOFF to
-5 m, an unknown mode, an unsupported command), while ``companion run`` arms, spins the rotor
up, takes off and flies a mission. The companion must take none of those answers for its own.
"""

from __future__ import annotations

import socket
import threading
import time

import pytest
from flight_support import run_companion
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import REPO_ROOT, start_sim_vehicle
from test_sitl_mavproxy import mavproxy_executable

from companion.sitl.processes import spawn
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

SPEEDUP = 4.0
MISSION = REPO_ROOT / "mission_files" / "square.waypoints"
GCS = (255, 190)
#: (command, params) the ground station repeats: refused, refused, unsupported, accepted.
GCS_COMMANDS = (
    (mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, -5.0)),
    (mavlink.MAV_CMD_DO_SET_MODE, (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 99)),
    (31010, ()),
    (mavlink.MAV_CMD_REQUEST_MESSAGE, (mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,)),
)


class CommandingStation(threading.Thread):
    """A ground station behind MAVProxy that commands at ``rate_hz`` and sorts the answers."""

    def __init__(self, port: int, rate_hz: float = 20.0) -> None:
        super().__init__(daemon=True, name="second-gcs")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.01)
        self.mav = mavlink.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1])
        self.mav.robust_parsing = True
        self.period_s = 1.0 / rate_hz
        self.router = None
        self.sent = 0
        self.answers_to_us = 0
        self.answers_to_others = 0
        self.running = threading.Event()
        self.running.set()

    def run(self) -> None:
        next_send = time.monotonic()
        while self.running.is_set():
            self._receive()
            if self.router is not None and time.monotonic() >= next_send:
                self._send_next()
                next_send += self.period_s

    def _receive(self) -> None:
        try:
            data, self.router = self.sock.recvfrom(65535)
        except (TimeoutError, OSError):
            return
        for msg in self.mav.parse_buffer(data) or []:
            if msg.get_type() == "COMMAND_ACK":
                if (msg.target_system, msg.target_component) == GCS:
                    self.answers_to_us += 1
                else:
                    self.answers_to_others += 1

    def _send_next(self) -> None:
        command, params = GCS_COMMANDS[self.sent % len(GCS_COMMANDS)]
        p = list(params) + [0.0] * (7 - len(params))
        self.sock.sendto(self.mav.command_long_encode(1, 1, command, 0, *p).pack(self.mav), self.router)
        self.sent += 1

    def stop(self) -> None:
        self.running.clear()
        self.join(timeout=2.0)
        self.sock.close()


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("command_matching")
    companion_port, gcs_port = free_port(), free_port()
    with start_sim_vehicle(speedup=SPEEDUP) as sim:
        router = spawn(
            [
                mavproxy_executable(),
                f"--master=udpout:127.0.0.1:{sim.port}",
                f"--out=udp:127.0.0.1:{companion_port}",
                f"--out=udp:127.0.0.1:{gcs_port}",
                "--non-interactive",
                "--nowait",
                "--default-modules=",
                f"--state-basedir={tmp}",
            ],
            tmp / "mavproxy.log",
            cwd=tmp,
        )
        station = CommandingStation(gcs_port)
        station.start()
        try:
            result = run_companion(
                "run",
                "--connect",
                f"udpin://127.0.0.1:{companion_port}",
                "--mission",
                str(MISSION),
                "--time-scale",
                str(SPEEDUP),
                "--no-zenoh",
            )
            time.sleep(0.5)  # the last answers come in
        finally:
            station.stop()
            router.stop()
        yield {"result": result, "station": station}


def test_the_companion_flies_its_mission_while_another_station_commands(flight):
    result = flight["result"]
    assert result.returncode == 0, result.stderr[-3000:]
    assert '"outcome": "completed"' in result.stdout.strip().splitlines()[-1]
    assert "refused by the vehicle" not in result.stderr


def test_the_other_station_got_an_answer_to_each_of_its_commands(flight):
    station = flight["station"]
    assert station.sent > 200, "the station hardly commanded"
    assert station.answers_to_us >= 0.95 * station.sent - 5, (station.sent, station.answers_to_us)


def test_answers_for_the_companion_travelled_on_the_shared_link(flight):
    """The link really carried both stations' answers: the test is not passing by isolation."""
    assert flight["station"].answers_to_others > 0
