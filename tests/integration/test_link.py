"""VehicleLink and SetpointStreamer against a real sim-vehicle (real MAVSDK, free ports)."""

from __future__ import annotations

import asyncio
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.errors import LinkError
from companion.flight.reference import VehicleClock
from companion.link import COPTER_MODES, SetpointStreamer, VehicleLink, hold_position
from companion.service.startup import StartupSettings, start_vehicle
from heli_common.ports import free_port

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support import start_sim_vehicle  # noqa: E402

pytestmark = pytest.mark.integration


async def connected_link(sim) -> VehicleLink:
    link = VehicleLink()
    await link.connect(f"udpout://127.0.0.1:{sim.port}", timeout_s=20)
    await link.waits.wait_ready(10)
    return link


def test_connect_and_telemetry():
    async def main(sim):
        link = await connected_link(sim)
        try:
            t = link.telemetry
            assert t.connected and t.armed is False and t.in_air in (False, None)
            assert t.mode in COPTER_MODES.values()
            assert t.pos_ned_m.shape == (3,) and np.all(np.abs(t.pos_ned_m) < 1.0)
            home = await link.waits.wait_home(10)
            assert home == pytest.approx((47.397742, 8.545594, 488.0), abs=1e-5)
            assert t.lat_deg == pytest.approx(47.397742, abs=1e-4)
            assert link.target_system == sim.sysid
        finally:
            await link.aclose()

    with start_sim_vehicle(speedup=1.0) as sim:
        asyncio.run(main(sim))


def test_no_autopilot_times_out():
    async def main():
        link = VehicleLink()
        with pytest.raises(LinkError, match="no autopilot"):
            await link.connect(f"udpin://127.0.0.1:{free_port()}", timeout_s=1.0)
        with pytest.raises(LinkError, match="cannot open udpin://127.0.0.1:0"):
            await VehicleLink().connect("udpin://127.0.0.1:0", timeout_s=1.0)

    asyncio.run(main())


def test_guided_takeoff_and_setpoints_move_the_vehicle():
    async def main(sim):
        link = await connected_link(sim)
        streamer = SetpointStreamer(link.direct.send_setpoint)
        try:
            with pytest.raises(LinkError, match="refused"):
                await link.commands.takeoff(10.0)  # disarmed: the vehicle refuses
            # a helicopter: interlock low, arm, interlock after the arming delay, run-up, takeoff
            await start_vehicle(
                link, StartupSettings(), 10.0, VehicleClock(4.0).now_s, time_scale=4.0, climb_speed_m_s=2.5
            )
            await link.waits.wait_for(lambda t: t.pos_ned_m[2] < -8.0, 60, "takeoff to 10 m")
            target = np.array([15.0, 10.0, -12.0])
            streamer.set_source(hold_position(target, 0.0))
            streamer.start()
            t = await link.waits.wait_for(
                lambda t: np.linalg.norm(t.pos_ned_m - target) < 1.5, 90, "the vehicle to reach the GUIDED setpoint"
            )
            assert t.mode == COPTER_MODES["GUIDED"] and t.armed and t.in_air is not False
            assert streamer.sent > 10 and streamer.send_errors == 0
        finally:
            await streamer.stop()
            await link.aclose()

    with start_sim_vehicle(speedup=4.0) as sim:
        asyncio.run(main(sim))


def test_link_loss_is_detected_and_recovered():
    async def main(sim):
        link = await connected_link(sim)
        changes = []
        link.on_link_change(changes.append)
        try:
            sim.proc.send_signal(signal.SIGSTOP)
            try:
                await link.waits.wait_for(lambda t: not t.connected and changes, 15, "link loss")
                assert not link.connected and not link.telemetry.connected
            finally:
                sim.proc.send_signal(signal.SIGCONT)
            assert await link.wait_connected(15)
            await asyncio.sleep(0.5)
            assert changes[:2] == [False, True]
            await link.waits.wait_position(5)
        finally:
            await link.aclose()

    with start_sim_vehicle(speedup=1.0) as sim:
        asyncio.run(main(sim))
