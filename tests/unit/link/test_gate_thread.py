"""The gate's thread with real sockets: what reaches MAVSDK, the tlog and the link's readers."""

import socket
import threading
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.link.gate import LINK_ONLY_MESSAGES, Identity, InboundFilter, OutboundSigner
from companion.link.transport import TAP_HANDOVER_PERIOD_S, GateThread
from heli_common.tlog import TlogWriter

US = (1, 191)
VEHICLE = (1, 1)


def udp_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    return sock


def frames_from_vehicle() -> list[bytes]:
    mav = mavlink.MAVLink(None, srcSystem=VEHICLE[0], srcComponent=VEHICLE[1])
    return [
        mav.heartbeat_encode(mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4).pack(mav),
        mav.attitude_encode(1000, 0.1, 0.2, 0.3, 0, 0, 0).pack(mav),
        mav.local_position_ned_encode(1000, 1.0, 2.0, -10.0, 0, 0, 0).pack(mav),
        mav.command_ack_encode(22, 0, 0, 0, *US).pack(mav),
    ]


def received_types(sock: socket.socket, seconds: float) -> list[str]:
    parser, kinds, end = mavlink.MAVLink(None), [], time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        kinds += [m.get_type() for m in parser.parse_buffer(data) or []]
    return kinds


def test_link_only_telemetry_reaches_the_tlog_and_the_link_but_not_mavsdk(tmp_path):
    vehicle, mavsdk = udp_socket(), udp_socket()
    identity = Identity()
    gate = GateThread(
        f"udpout://127.0.0.1:{vehicle.getsockname()[1]}",
        InboundFilter(identity),
        OutboundSigner(identity),
        tlog=TlogWriter(tmp_path / "link.tlog", flush_period_s=0.0),
    )
    batches, lock = [], threading.Lock()

    def on_tap(batch):
        with lock:
            batches.append((time.monotonic(), [kind for kind, _ in batch]))

    gate.on_tap = on_tap
    gate.inbound.tapped.update({"ATTITUDE", "LOCAL_POSITION_NED"})
    gate.start()
    try:
        mav = mavlink.MAVLink(None, srcSystem=US[0], srcComponent=US[1])
        hb = mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        mavsdk.sendto(hb.pack(mav), gate.local.getsockname())  # MAVSDK speaks first
        assert "HEARTBEAT" in received_types(vehicle, 0.3)  # forwarded to the vehicle
        gate_address = ("127.0.0.1", gate.vehicle.sock.getsockname()[1])
        for frame in frames_from_vehicle():
            vehicle.sendto(frame, gate_address)
        seen_by_mavsdk = received_types(mavsdk, 0.5)
    finally:
        gate.close()
    assert "HEARTBEAT" in seen_by_mavsdk and "COMMAND_ACK" in seen_by_mavsdk
    assert not LINK_ONLY_MESSAGES & set(seen_by_mavsdk), seen_by_mavsdk
    in_tlog = []
    log = mavutil.mavlink_connection(str(tmp_path / "link.tlog"))
    while (msg := log.recv_match()) is not None:
        in_tlog.append(msg.get_type())
    assert {"ATTITUDE", "LOCAL_POSITION_NED", "COMMAND_ACK"} <= set(in_tlog)
    handed = [kind for _, kinds in batches for kind in kinds]
    assert handed == ["ATTITUDE", "LOCAL_POSITION_NED"]  # every tapped frame, in order
    assert len(batches) <= 2  # four datagrams, at most two wake-ups
    if len(batches) == 2:
        assert batches[1][0] - batches[0][0] >= TAP_HANDOVER_PERIOD_S * 0.9


def test_batched_reads_keep_each_datagrams_kernel_arrival_time():
    vehicle = udp_socket()
    identity = Identity()
    gate = GateThread(
        f"udpout://127.0.0.1:{vehicle.getsockname()[1]}", InboundFilter(identity), OutboundSigner(identity)
    )
    batches = []
    gate.on_tap = lambda batch: batches.append((time.monotonic(), [(k, f["_t_s"]) for k, f in batch]))
    gate.inbound.tapped.update({"ATTITUDE", "LOCAL_POSITION_NED"})
    gate.batch_reads(0.4)
    gate.start()
    try:
        mav = mavlink.MAVLink(None, srcSystem=VEHICLE[0], srcComponent=VEHICLE[1])
        gate.vehicle.write(b"\0")  # binds the gate's side (udpout)
        gate_address = ("127.0.0.1", gate.vehicle.sock.getsockname()[1])
        sent = {}
        hb = mav.heartbeat_encode(mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4)
        vehicle.sendto(hb.pack(mav), gate_address)  # read at once; the next batch in 0.4 s
        time.sleep(0.05)
        for kind, msg in (
            ("ATTITUDE", mav.attitude_encode(1000, 0.1, 0.2, 0.3, 0, 0, 0)),
            ("LOCAL_POSITION_NED", mav.local_position_ned_encode(1000, 1.0, 2.0, -10.0, 0, 0, 0)),
        ):
            sent[kind] = time.monotonic()
            vehicle.sendto(msg.pack(mav), gate_address)
            time.sleep(0.15)
        deadline = time.monotonic() + 2.0
        while not batches and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        gate.close()
    handed_at, taps = batches[0]
    assert [kind for kind, _ in taps] == ["ATTITUDE", "LOCAL_POSITION_NED"]  # one batch, both
    assert handed_at - sent["ATTITUDE"] >= 0.2  # read late, together
    for kind, t_s in taps:
        assert abs(t_s - sent[kind]) < 0.02, (kind, t_s - sent[kind])  # stamped on arrival


def test_a_listener_hears_each_message_on_the_gate_thread_as_it_is_read():
    """``MessageTap.listen``: the live view's path, no hand-over to the loop; a listener that
    raises costs the link nothing (MAVSDK still gets the frames)."""
    import asyncio

    from companion.link.message_tap import LIVE_READ_PERIOD_S, MessageTap
    from companion.link.session import LinkSession

    vehicle, mavsdk = udp_socket(), udp_socket()
    identity = Identity()
    gate = GateThread(
        f"udpout://127.0.0.1:{vehicle.getsockname()[1]}", InboundFilter(identity), OutboundSigner(identity)
    )
    session = LinkSession()
    session.gate = gate
    tap = MessageTap(session)
    loop = asyncio.new_event_loop()
    tap.attach(gate, loop)
    heard = []
    stop_position = tap.listen(
        "LOCAL_POSITION_NED", lambda f: heard.append((threading.current_thread().name, f["time_boot_ms"]))
    )
    stop_attitude = tap.listen("ATTITUDE", lambda f: 1 / 0)
    gate.start()
    try:
        mav = mavlink.MAVLink(None, srcSystem=US[0], srcComponent=US[1])
        hb = mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        mavsdk.sendto(hb.pack(mav), gate.local.getsockname())
        assert "HEARTBEAT" in received_types(vehicle, 0.3)
        gate_address = ("127.0.0.1", gate.vehicle.sock.getsockname()[1])
        for frame in frames_from_vehicle():
            vehicle.sendto(frame, gate_address)
        seen_by_mavsdk = received_types(mavsdk, 0.5)
        running = type("Schedule", (), {"running": True})()  # a schedule that runs
        tap.batch_reads(running)
        assert gate.read_period_s == LIVE_READ_PERIOD_S  # read often while someone listens
        stop_attitude()
        assert gate.read_period_s == LIVE_READ_PERIOD_S
        stop_position()
        assert gate.read_period_s == TAP_HANDOVER_PERIOD_S  # nobody listens: the usual batches
    finally:
        gate.close()
        loop.close()
    assert heard == [("mavlink-gate", 1000)]
    assert "HEARTBEAT" in seen_by_mavsdk and "COMMAND_ACK" in seen_by_mavsdk  # the raise dropped nothing
    assert not gate.inbound.taps  # nobody reads: nothing kept for the loop
