"""The vehicle routes other components' messages as ArduPilot does (issue 14: a ground station's
MISSION_START reaches the companion, component 191, through the vehicle; its answer comes back)."""

from __future__ import annotations

import socket
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle.mavlink.endpoint import Endpoint

GCS, COMPANION = (255, 190), (1, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)


class Peer:
    """A UDP socket on loopback speaking as ``ids``."""

    def __init__(self, ids: tuple[int, int], vehicle_port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.vehicle = ("127.0.0.1", vehicle_port)
        self.mav = mavlink.MAVLink(None, srcSystem=ids[0], srcComponent=ids[1])

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.vehicle)

    def received(self) -> list:
        out = []
        parser = mavlink.MAVLink(None)
        while True:
            try:
                data = self.sock.recv(65535)
            except (TimeoutError, BlockingIOError):
                return out
            out += parser.parse_buffer(data) or []


@pytest.fixture
def vehicle_and_peers():
    delivered = []
    endpoint = Endpoint(1, "127.0.0.1", 0, [], 5.0, lambda msg, address: delivered.append(msg.get_type()))
    gcs, companion = Peer(GCS, endpoint.port), Peer(COMPANION, endpoint.port)

    def pump(*senders_and_messages):
        for peer, msg in senders_and_messages:
            peer.send(msg)
            time.sleep(0.02)
            endpoint.receive()

    pump(
        (gcs, gcs.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)),
        (
            companion,
            companion.mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0),
        ),
    )
    gcs.received(), companion.received()  # the heartbeats forwarded so far
    yield endpoint, gcs, companion, pump, delivered
    endpoint.close()


def test_a_command_for_the_companion_reaches_it_and_its_answer_comes_back(vehicle_and_peers):
    endpoint, gcs, companion, pump, delivered = vehicle_and_peers
    pump((gcs, gcs.mav.command_long_encode(*COMPANION, mavlink.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)))
    got = [m for m in companion.received() if m.get_type() == "COMMAND_LONG"]
    assert [(m.command, m.get_srcSystem(), m.get_srcComponent()) for m in got] == [
        (mavlink.MAV_CMD_MISSION_START, *GCS)
    ]
    assert not [m for m in gcs.received() if m.get_type() == "COMMAND_LONG"], "never back to the sender"
    pump((companion, companion.mav.command_ack_encode(mavlink.MAV_CMD_MISSION_START, 0, 0, 0, *GCS)))
    acks = [m for m in gcs.received() if m.get_type() == "COMMAND_ACK"]
    assert [(m.get_srcSystem(), m.get_srcComponent()) for m in acks] == [COMPANION]


def test_commands_for_the_autopilot_stay_with_it(vehicle_and_peers):
    endpoint, gcs, companion, pump, delivered = vehicle_and_peers
    for target_component in (1, 0):
        pump(
            (gcs, gcs.mav.command_long_encode(1, target_component, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0))
        )
    assert delivered.count("COMMAND_LONG") == 2
    assert not [m for m in companion.received() if m.get_type() == "COMMAND_LONG"]


def test_a_command_for_an_unknown_component_goes_nowhere(vehicle_and_peers):
    endpoint, gcs, companion, pump, delivered = vehicle_and_peers
    pump((gcs, gcs.mav.command_long_encode(7, 1, mavlink.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)))
    assert not companion.received() and not gcs.received()


def test_heartbeats_and_texts_are_broadcast_to_the_others_only(vehicle_and_peers):
    endpoint, gcs, companion, pump, delivered = vehicle_and_peers
    pump(
        (
            companion,
            companion.mav.heartbeat_encode(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_STANDBY
            ),
        ),
        (companion, companion.mav.statustext_encode(mavlink.MAV_SEVERITY_INFO, b"companion ready")),
    )
    at_gcs = [(m.get_type(), m.get_srcComponent()) for m in gcs.received()]
    assert ("HEARTBEAT", COMPANION[1]) in at_gcs and ("STATUSTEXT", COMPANION[1]) in at_gcs
    assert not [m for m in companion.received() if m.get_srcComponent() == COMPANION[1]]


def test_an_adsb_receiver_s_traffic_reaches_the_companion_and_the_ground_station(vehicle_and_peers):
    """ADSB_VEHICLE of an ADS-B receiver component (MAV_COMP_ID_ADSB) is a broadcast: the vehicle
    forwards it to every other link, as ArduPilot's routing does, never back to the receiver."""
    endpoint, gcs, companion, pump, delivered = vehicle_and_peers
    receiver = Peer((1, mavlink.MAV_COMP_ID_ADSB), endpoint.port)
    pump(
        (
            receiver,
            receiver.mav.adsb_vehicle_encode(
                0xA00023, -353632610, 1491652300, 1, 600000, 9000, 5000, 0, b"N00035", 8, 1, 0x1FF, 1200
            ),
        )
    )
    for peer in (companion, gcs):
        got = [m for m in peer.received() if m.get_type() == "ADSB_VEHICLE"]
        assert [(m.ICAO_address, m.get_srcComponent()) for m in got] == [(0xA00023, mavlink.MAV_COMP_ID_ADSB)]
    assert not [m for m in receiver.received() if m.get_type() == "ADSB_VEHICLE"]
