"""The live view's vehicle state, fed from the telemetry as it is read (issue 25, item 6).

A real Foxglove server and the tests' own ``foxglove.sdk.v1`` client (``tests/foxglove_client.py``):
each LOCAL_POSITION_NED becomes one ``/vehicle/telemetry`` message with the vehicle's own
``time_boot_ms`` and a sequence number, and a ``/tf``; a flight's view on the same server
leaves the helicopter to the feed and leaves the server up when it closes.
"""

import asyncio

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.link.frames import LinkFrames
from companion.link.gate import tapped_fields
from companion.view import channels as ch
from companion.view.live import FIX_PERIOD_S, LiveServer, VehicleFeed
from companion.view.publisher import FlightView
from tests.foxglove_client import collect

HOME = (47.397742, 8.545594, 488.0)
ORIGIN = (47.3977, 8.5456, 486.0)  # the EKF origin a few metres from home
STATES = 40
STEP_MS = 100


def as_read(mav, msg) -> dict:
    """``msg`` as the gate hands it to a listener: packed by the vehicle, read back as fields."""
    return tapped_fields(mav.decode(bytearray(msg.pack(mav))))


def telemetry(k: int, sysid: int = 1, x: float | None = None) -> list[dict]:
    """ATTITUDE, LOCAL_POSITION_NED and GLOBAL_POSITION_INT at ``time_boot_ms`` 1000 + k steps."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
    boot_ms = 1000 + STEP_MS * k
    return [
        as_read(mav, mav.attitude_encode(boot_ms, 0.01 * k, -0.02, 0.5, 0, 0, 0)),
        as_read(mav, mav.local_position_ned_encode(boot_ms, 0.5 * k if x is None else x, 1.0, -10.0, 5.0, 0, 0)),
        as_read(
            mav,
            mav.global_position_int_encode(
                boot_ms, int(HOME[0] * 1e7), int(HOME[1] * 1e7), 498_000, 10_000, 0, 0, 0, 0
            ),
        ),
    ]


def feed_one(feed: VehicleFeed, fields: list[dict]) -> None:
    feed.on_attitude(fields[0])
    feed.on_local_position(fields[1])
    feed.on_global_position(fields[2])


def watch_while(port: int, topics: set[str], publish) -> dict:
    """Subscribe to ``topics``, run ``publish()`` once subscribed, collect for a while."""

    async def run():
        watch = asyncio.create_task(collect(port, topics, seconds=2.5))
        await asyncio.sleep(0.5)  # the client subscribes first
        await publish()
        return await watch

    return asyncio.run(run()).messages


def test_each_state_reaches_the_viewer_with_the_vehicles_own_time_stamp_and_in_sequence():
    server = LiveServer("127.0.0.1", 0)
    frames = LinkFrames.build(HOME, ORIGIN)
    feed = VehicleFeed(server.context, frames=lambda: frames, sysid=lambda: 1)

    async def publish():
        for k in range(STATES):
            feed_one(feed, telemetry(k))
            feed_one(feed, telemetry(k, sysid=2))  # another system on the link: left out
            await asyncio.sleep(0.002)
        feed.on_local_position(telemetry(STATES, x=float("nan"))[1])  # not finite: dropped

    try:
        got = watch_while(server.port, {ch.TELEMETRY, ch.TRANSFORMS, ch.LOCATION, ch.SCENE_VEHICLE}, publish)
    finally:
        server.close()
    states = got[ch.TELEMETRY]
    assert [s["seq"] for s in states] == list(range(1, STATES + 1))  # every one, in order, none lost
    assert [s["time_boot_ms"] for s in states] == [1000 + STEP_MS * k for k in range(STATES)]
    assert feed.published == STATES
    sent = np.array([[0.5 * k, 1.0, -10.0] for k in range(STATES)])
    np.testing.assert_allclose([s["pos_ned_m"] for s in states], frames.to_home(sent), atol=1e-4)
    assert {s["frame"] for s in states} == {"home"}
    # the attitude is the ATTITUDE read just before (float32 on the wire)
    np.testing.assert_allclose(states[7]["euler_rad"], [0.07, -0.02, 0.5], atol=1e-6)
    assert states[0]["vel_ned_m_s"] == [5.0, 0.0, 0.0]
    assert len(got[ch.TRANSFORMS]) == STATES
    span_s = (STATES - 1) * STEP_MS / 1000
    assert len(got[ch.LOCATION]) == int(span_s / FIX_PERIOD_S) + 1  # the map's fix, 2 Hz of vehicle time
    assert len(got[ch.SCENE_VEHICLE]) == 1  # the shape, every 2 s of wall clock


def test_a_vehicle_without_a_planning_home_is_shown_in_its_own_local_frame():
    server = LiveServer("127.0.0.1", 0)
    feed = VehicleFeed(server.context, frames=LinkFrames, sysid=lambda: 1)

    async def publish():
        for k in range(5):
            feed_one(feed, telemetry(k))
            await asyncio.sleep(0.01)

    try:
        got = watch_while(server.port, {ch.TELEMETRY}, publish)
    finally:
        server.close()
    assert [s["frame"] for s in got[ch.TELEMETRY]] == ["vehicle_local"] * 5
    assert got[ch.TELEMETRY][2]["pos_ned_m"] == [1.0, 1.0, -10.0]


def test_a_flights_view_on_a_live_server_leaves_the_helicopter_to_the_feed_and_the_server_up():
    server = LiveServer("127.0.0.1", 0)
    feed = VehicleFeed(server.context, frames=lambda: LinkFrames.build(HOME), sysid=lambda: 1)
    view = FlightView(live=server)
    assert view.port == server.port

    async def fly():
        view.write("header", home_lla=list(HOME), seed=0)
        for k in range(10):
            view.write(
                "sample",
                t_s=1.0 + 0.1 * k,
                pos_ned_m=[k, 0, -10],
                ref_pos_ned_m=[k, 0, -10],
                vel_ned_m_s=[1, 0, 0],
                euler_rad=[0, 0, 0],
                path_id="leg0",
                leg=0,
            )
            await asyncio.sleep(0.01)
        view.close()  # the flight ends
        for k in range(5):
            feed_one(feed, telemetry(k))
            await asyncio.sleep(0.01)

    try:
        got = watch_while(server.port, {"/vehicle/state", ch.TRANSFORMS, ch.TELEMETRY}, fly)
    finally:
        server.close()
    assert len(got["/vehicle/state"]) == 10  # the record's samples, for the report
    assert len(got[ch.TRANSFORMS]) == 5  # /tf only from the telemetry
    assert len(got[ch.TELEMETRY]) == 5  # after the flight's view closed
