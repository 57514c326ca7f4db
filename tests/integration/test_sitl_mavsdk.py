"""A real ``sim-vehicle`` process flown by real MAVSDK 4.x (and pymavlink for GUIDED setpoints).

Issue 2, "What it must show": MAVSDK discovers the vehicle, uploads a 5-item mission with
mission_raw and downloads it identical, imports a ``.plan`` with a fence and rally points and
uploads them, arms, takes off to 10 m (within 0.5 m), flies in GUIDED by position setpoints to
a point 30 m away and holds there within 0.5 m.

As with ArduCopter heli (issue 10): MAVSDK asks for the position itself (``set_rate_position``:
SET_MESSAGE_INTERVAL), the pymavlink link asks for LOCAL_POSITION_NED, arming is refused while the
motor interlock is engaged, and the takeoff is accepted once the interlock is in effect.
"""

from __future__ import annotations

import asyncio
import math
import socket
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import start_sim_vehicle

from heli_common.ports import free_port

pytestmark = pytest.mark.integration

DATA = Path(__file__).resolve().parents[1] / "data"
SPEEDUP = 5.0


def five_items():
    """The 5 items of ``tests/data/five_items.waypoints`` (QGC WPL 110) as MAVSDK raw items."""
    from mavsdk.plugins.mission_raw import MissionItem

    lines = (DATA / "five_items.waypoints").read_text().splitlines()
    assert lines[0].startswith("QGC WPL 110")
    items = []
    for line in lines[1:]:
        c = line.split("\t")
        seq, current, frame, command = (int(v) for v in c[:4])
        p1, p2, p3, p4 = (float(v) for v in c[4:8])
        x, y, z = round(float(c[8]) * 1e7), round(float(c[9]) * 1e7), float(c[10])
        items.append(MissionItem(seq, frame, command, current, int(c[11]), p1, p2, p3, p4, x, y, z, 0))
    assert len(items) == 5
    return items


def fields(item) -> tuple:
    return (
        item.seq,
        item.frame,
        item.command,
        item.current,
        item.autocontinue,
        item.param1,
        item.param2,
        item.param3,
        item.param4,
        item.x,
        item.y,
        round(item.z, 3),
        item.mission_type,
    )


async def connect(port: int):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
    system = await mavsdk.first_autopilot(20.0)
    return mavsdk, system


class GuidedLink:
    """A pymavlink peer of the vehicle: sends setpoints, reads LOCAL_POSITION_NED."""

    def __init__(self, vehicle_port: int, sysid: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.address = ("127.0.0.1", vehicle_port)
        self.sysid = sysid
        self.mav = mavlink.MAVLink(None, srcSystem=250, srcComponent=191)
        self.mav.robust_parsing = True
        self.local = None
        self.time_boot_ms = 0

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.address)

    def command(self, command: int, *params: float, timeout_s: float = 3.0):
        """COMMAND_LONG; returns its COMMAND_ACK (None if none came)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.send(self.mav.command_long_encode(self.sysid, 1, command, 0, *p))
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                time.sleep(0.01)
                continue
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                    return msg
        return None

    def interlock(self, engaged: bool) -> int:
        """MAV_CMD_DO_AUX_FUNCTION 32 (motor interlock) high or low; returns the MAV_RESULT."""
        ack = self.command(mavlink.MAV_CMD_DO_AUX_FUNCTION, 32, 2 if engaged else 0)
        return -1 if ack is None else ack.result

    def position_target(self, north: float, east: float, down: float) -> None:
        mask = 0b110111111000  # position only
        self.send(
            self.mav.set_position_target_local_ned_encode(
                0, self.sysid, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, north, east, down, 0, 0, 0, 0, 0, 0, 0, 0
            )
        )

    def poll(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "LOCAL_POSITION_NED" and msg.get_srcSystem() == self.sysid:
                    self.local = (msg.x, msg.y, msg.z)
                    self.time_boot_ms = msg.time_boot_ms

    def close(self) -> None:
        self.sock.close()


async def wait_for(predicate, timeout_s: float, what: str, poll_s: float = 0.05):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = await predicate()
        if value:
            return value
        await asyncio.sleep(poll_s)
    raise AssertionError(f"timed out waiting for {what}")


def test_mavsdk_missions_and_guided_flight():
    asyncio.run(_missions_and_guided_flight())


async def _missions_and_guided_flight():
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    gcs_port = free_port()
    with start_sim_vehicle(out=[f"127.0.0.1:{gcs_port}"], speedup=SPEEDUP) as sim:
        mavsdk, system = await connect(gcs_port)
        try:
            assert system is not None, f"MAVSDK found no autopilot\n{sim.log_tail()}"
            assert await system.get_system_id() == sim.sysid

            # ---- 5-item mission: upload, download identical
            mission_raw = MissionRawAsync(system)
            items = five_items()
            await mission_raw.upload_mission(items)
            downloaded = await mission_raw.download_mission()
            assert [fields(i) for i in downloaded] == [fields(i) for i in items]

            # ---- .plan with fence and rally points
            imported = await mission_raw.import_qgroundcontrol_mission(str(DATA / "fence_rally.plan"))
            assert len(imported.geofence_items) == 4
            assert len(imported.rally_items) == 2
            await mission_raw.upload_geofence(imported.geofence_items)
            await mission_raw.upload_rally_points(imported.rally_items)
            fence = await mission_raw.download_geofence()
            rally = await mission_raw.download_rallypoints()
            assert [fields(i)[1:] for i in fence] == [fields(i)[1:] for i in imported.geofence_items]
            assert [fields(i)[1:] for i in rally] == [fields(i)[1:] for i in imported.rally_items]
            # the mission list was not touched by the fence and rally uploads
            assert [fields(i) for i in await mission_raw.download_mission()] == [fields(i) for i in items]

            # ---- arm, take off to 10 m: ArduCopter heli's interlock and run-up
            from mavsdk.asyncio.plugins.action import ActionError

            action = ActionAsync(system)
            telemetry = TelemetryAsync(system)
            await telemetry.set_rate_position(10.0)  # as ArduPilot, nothing is streamed unasked
            await action.set_takeoff_altitude(10.0)
            link = GuidedLink(sim.port, sim.sysid)
            link.send(
                link.mav.command_long_encode(
                    sim.sysid,
                    1,
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    0,
                    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                    50_000,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
            )
            with pytest.raises(ActionError):
                await action.arm()  # the SITL's RC8 (1500 us) engages the interlock: "Arm: Motor Interlock Enabled"
            assert "Arm: Motor Interlock Enabled" in sim.log_text()
            assert link.interlock(False) == mavlink.MAV_RESULT_ACCEPTED
            await action.arm()
            assert link.interlock(True) == mavlink.MAV_RESULT_ACCEPTED  # effective 2 s (simulated) after arming
            deadline = time.monotonic() + 10.0
            while True:
                try:
                    await action.takeoff()
                    break
                except ActionError:  # refused until the interlock is in effect, as ArduPilot does
                    assert time.monotonic() < deadline, sim.log_tail()
                    await asyncio.sleep(0.1)

            async def relative_alt():
                return (await telemetry.position()).relative_altitude_m

            await wait_for(lambda: _near(relative_alt, 10.0, 0.3), 60.0, "takeoff to 10 m")
            await asyncio.sleep(2.0 / SPEEDUP * 3)
            alt = await relative_alt()
            assert abs(alt - 10.0) <= 0.5, f"altitude {alt:.2f} m after takeoff"

            # ---- GUIDED: position setpoints to a point 30 m away, then hold
            try:
                target = (30.0, 0.0, -10.0)
                deadline = time.monotonic() + 60.0
                arrived_ms = None
                while time.monotonic() < deadline:
                    link.position_target(*target)
                    link.poll()
                    if link.local is not None and _dist(link.local, target) < 0.5:
                        arrived_ms = link.time_boot_ms
                        break
                    await asyncio.sleep(0.05)
                assert arrived_ms is not None, f"never reached {target}: at {link.local}\n{sim.log_tail()}"
                worst = 0.0
                while link.time_boot_ms - arrived_ms < 5000:  # 5 s of simulated time holding
                    link.position_target(*target)
                    await asyncio.sleep(0.05)
                    link.poll()
                    worst = max(worst, _dist(link.local, target))
                assert worst <= 0.5, f"hold error {worst:.2f} m"

                # MAVSDK goto_location (MAV_CMD_DO_REPOSITION): 10 m east of there, 488 + 12 m AMSL
                lat = 47.397742 + 30.0 / 111_132.95
                lon = 8.545594 + 10.0 / (111_319.49 * math.cos(math.radians(47.397742)))
                await action.goto_location(lat, lon, 500.0, 0.0)
                deadline = time.monotonic() + 30.0
                while time.monotonic() < deadline:
                    await asyncio.sleep(0.1)
                    link.poll()
                    if _dist(link.local, (30.0, 10.0, -12.0)) < 0.5:
                        break
                assert _dist(link.local, (30.0, 10.0, -12.0)) < 0.5, f"goto_location: at {link.local}"
            finally:
                link.close()

            # ---- land: disarms on touchdown
            await action.land()

            async def disarmed():
                return not await telemetry.armed()

            await wait_for(disarmed, 60.0, "disarm after landing")
            assert sim.is_running()
        finally:
            mavsdk.destroy()


async def _near(getter, target: float, tol: float) -> bool:
    value = await getter()
    return value is not None and abs(value - target) <= tol


def _dist(a, b) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))
