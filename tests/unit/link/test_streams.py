"""companion.link.streams: what is requested, the fallbacks, and requesting again.

The link is a double that answers SET_MESSAGE_INTERVAL / REQUEST_MESSAGE as scripted and records
every command and message sent (the real vehicles are in the integration tests).
"""

from __future__ import annotations

import asyncio
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.config import load_settings
from companion.errors import ConfigError
from companion.link.streams import DATA_STREAM_OF, StreamKeeper, StreamSettings, data_stream_rates, stream_requests

ACCEPTED, DENIED, UNSUPPORTED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED, mavlink.MAV_RESULT_UNSUPPORTED


class FakeLink:
    """``command_result`` answers from ``answer(command, params)``; everything is recorded."""

    target_system, target_component = 1, 1

    def __init__(self, answer):
        self.answer = answer
        self.commands: list[tuple[int, tuple]] = []
        self.messages: list[tuple[str, dict]] = []
        self.connected = True

    async def command_result(self, command, params=(), *, what=None, timeout_s=1.0):
        self.commands.append((command, tuple(params)))
        return self.answer(command, tuple(params))

    def send_message(self, name, fields):
        self.messages.append((name, fields))

    def intervals(self):
        return [int(p[0]) for c, p in self.commands if c == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL]


def keeper_of(link: FakeLink, settings: StreamSettings, **kw) -> StreamKeeper:
    """A keeper that asks, sends and checks the link through ``link``."""
    return StreamKeeper(settings, commands=link, sender=link, target=link, connected=lambda: link.connected, **kw)


def test_every_message_the_companion_uses_is_requested_with_pymavlink_ids():
    names = [r.name for r in stream_requests(StreamSettings())]
    assert names == [
        "LOCAL_POSITION_NED",
        "ATTITUDE",
        "GLOBAL_POSITION_INT",
        "EXTENDED_SYS_STATE",
        "HOME_POSITION",
        "GPS_GLOBAL_ORIGIN",
        "SYS_STATUS",
        "SERVO_OUTPUT_RAW",
        "RPM",
    ]
    with_adsb = stream_requests(StreamSettings(), adsb=True)
    assert with_adsb[-1].name == "ADSB_VEHICLE" and with_adsb[-1].msg_id == mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE
    local = with_adsb[0]
    assert local.msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED and local.interval_us == 100_000.0
    assert "RPM" not in [r.name for r in stream_requests(StreamSettings(rpm_hz=0.0))]


def test_data_stream_groups_take_their_fastest_message():
    rates = data_stream_rates(stream_requests(StreamSettings(local_position_ned_hz=12.5, global_position_int_hz=3.0)))
    assert rates[mavlink.MAV_DATA_STREAM_POSITION] == 13
    assert rates[mavlink.MAV_DATA_STREAM_EXTENDED_STATUS] == 2
    assert "HOME_POSITION" not in DATA_STREAM_OF and "GPS_GLOBAL_ORIGIN" not in DATA_STREAM_OF


def test_settings_are_validated():
    with pytest.raises(ConfigError, match="link.streams.attitude_hz"):
        StreamSettings(attitude_hz=-1.0)
    with pytest.raises(ConfigError, match="link.streams.rpm_hz"):
        load_settings(None, {"link": {"streams": {"rpm_hz": 500.0}}})


def test_an_ardupilot_like_vehicle_accepts_every_interval():
    link = FakeLink(lambda c, p: ACCEPTED)
    keeper = keeper_of(link, StreamSettings())
    status = asyncio.run(keeper.request_all())
    assert set(status.values()) == {"interval"}
    assert link.intervals() == [r.msg_id for r in keeper.requests]
    assert link.messages == []


def test_a_message_the_vehicle_cannot_stream_falls_back_then_is_left_out():
    """``sim-vehicle`` today: no GPS_GLOBAL_ORIGIN, no RPM, no ADSB_VEHICLE."""
    missing = {
        mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
        mavlink.MAVLINK_MSG_ID_RPM,
        mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE,
    }

    def answer(command, params):
        if int(params[0]) in missing:
            return DENIED if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL else UNSUPPORTED
        return ACCEPTED

    link = FakeLink(answer)
    keeper = keeper_of(link, StreamSettings(), adsb=True)
    status = asyncio.run(keeper.request_all())
    assert status["GPS_GLOBAL_ORIGIN"] == "unavailable" and keeper.unavailable("GPS_GLOBAL_ORIGIN")
    assert status["ADSB_VEHICLE"] == "unavailable"
    assert status["RPM"] == "data_stream"  # EXTRA3 carries RPM on ArduPilot
    assert (
        "REQUEST_DATA_STREAM",
        {
            "target_system": 1,
            "target_component": 1,
            "req_stream_id": mavlink.MAV_DATA_STREAM_EXTRA3,
            "req_message_rate": 2,
            "start_stop": 1,
        },
    ) in link.messages
    asked_once = [p[0] for c, p in link.commands if c == mavlink.MAV_CMD_REQUEST_MESSAGE]
    assert asked_once == [mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN]
    assert status["LOCAL_POSITION_NED"] == "interval"


def test_a_vehicle_without_set_message_interval_gets_request_data_stream():
    link = FakeLink(lambda c, p: UNSUPPORTED if c == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL else ACCEPTED)
    keeper = keeper_of(link, StreamSettings())
    status = asyncio.run(keeper.request_all())
    assert len(link.intervals()) == 1  # asked once, then not again
    groups = sorted(m[1]["req_stream_id"] for m in link.messages)
    assert groups == sorted(set(DATA_STREAM_OF.values()))
    assert status["HOME_POSITION"] == status["GPS_GLOBAL_ORIGIN"] == "requested"
    assert status["ATTITUDE"] == "data_stream"


def test_no_ack_leaves_the_request_pending():
    keeper = keeper_of(FakeLink(lambda c, p: None), StreamSettings())
    assert set(asyncio.run(keeper.request_all()).values()) == {"pending"}


def run_keeper(keeper, scenario):
    async def main():
        task = asyncio.create_task(keeper.run())
        try:
            await scenario()
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    asyncio.run(main())


async def until(predicate, what, timeout_s=5.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.01)


def test_a_reboot_link_back_or_silence_requests_everything_again():
    link = FakeLink(lambda c, p: ACCEPTED)
    keeper = keeper_of(link, StreamSettings(stale_after_s=0.3))

    async def scenario():
        await until(lambda: keeper.rounds == 1, "the first round")
        for name in ("LOCAL_POSITION_NED", "ATTITUDE"):
            keeper.note(name, 100.0)
        await asyncio.sleep(0.1)
        assert keeper.rounds == 1
        keeper.note("LOCAL_POSITION_NED", 3.0)  # boot time went back: a reboot
        await until(lambda: keeper.rounds == 2, "the round after the reboot")
        keeper.request_again("link back")
        await until(lambda: keeper.rounds == 3, "the round after the link came back")
        # no position for longer than stale_after_s while heartbeats arrive: ask again
        await until(lambda: keeper.rounds == 4, "the round after silence", timeout_s=3.0)
        link.connected = False  # but never while the link is down
        rounds = keeper.rounds
        await asyncio.sleep(1.0)
        assert keeper.rounds == rounds

    run_keeper(keeper, scenario)
    assert len(link.intervals()) == 4 * len(keeper.requests)
