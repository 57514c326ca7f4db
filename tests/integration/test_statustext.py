"""STATUSTEXT from the companion reaches the ground station through the vehicle (DESIGN 7.5).

A real ``sim-vehicle`` sends telemetry to two ``--out`` ports: a pymavlink socket playing the
ground station, and the companion's ``VehicleLink`` (real MAVSDK, ``udpin``). The companion's
STATUSTEXT is broadcast; the vehicle forwards it to its other links (as ArduPilot's MAVLink
routing does), so the ground station receives it with the same text.
"""

from __future__ import annotations

import asyncio
import socket
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from support import start_sim_vehicle

from companion.errors import LinkError
from companion.link import VehicleLink
from heli_common.ports import free_port

pytestmark = pytest.mark.integration

TEXT = "AVOID m1: evade left, 31 ms"


class GroundStation:
    """A pymavlink socket bound to one of the vehicle's ``--out`` ports (like QGroundControl)."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.mav = mavlink2.MAVLink(None)
        self.mav.robust_parsing = True
        self.statustexts: list = []

    def drain(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except (BlockingIOError, InterruptedError):
                return
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "STATUSTEXT":
                    self.statustexts.append(msg)

    def close(self) -> None:
        self.sock.close()


def test_the_companions_statustext_reaches_the_ground_station():
    gcs = GroundStation()
    companion_port = free_port()

    async def main(sim) -> list:
        link = VehicleLink("companion")
        await link.connect(f"udpin://127.0.0.1:{companion_port}", timeout_s=20)
        try:
            await link.waits.wait_ready(10)
            with pytest.raises(LinkError, match="severity"):
                link.direct.send_statustext("x", severity="LOUD")
            received: list = []
            deadline = time.monotonic() + 15.0
            while time.monotonic() < deadline and not received:
                link.direct.send_statustext(TEXT, severity="WARNING")
                link.direct.send_statustext("x" * 80, severity=mavlink2.MAV_SEVERITY_NOTICE)
                await asyncio.sleep(0.3)
                gcs.drain()
                received = [m for m in gcs.statustexts if m.text == TEXT]
            return received
        finally:
            await link.aclose()

    try:
        with start_sim_vehicle(out=[f"127.0.0.1:{gcs.port}", f"127.0.0.1:{companion_port}"], speedup=1.0) as sim:
            received = asyncio.run(main(sim))
            texts = [m.text for m in gcs.statustexts]
            assert received, f"no STATUSTEXT {TEXT!r} at the ground station; got {texts}\n{sim.log_tail()}"
            msg = received[0]
            assert msg.severity == mavlink2.MAV_SEVERITY_WARNING
            assert (msg.get_srcSystem(), msg.get_srcComponent()) != (sim.sysid, 1), (
                "forwarded with the companion's ids, not sent by the autopilot itself"
            )
            assert "x" * 50 in texts, "a long text arrives cut to 50 characters"
    finally:
        gcs.close()
