"""The companion component (sysid, 191): heartbeats, commands addressed to it, acks (issue 14)."""

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.link.gate import new_parser
from companion.link.onboard import COMPONENT_ID, OnboardComponent


def parse(frame: bytes):
    (msg,) = new_parser().parse_buffer(frame)
    return msg


def gcs_command(target_component: int, command: int = mavlink.MAV_CMD_MISSION_START, sysid: int = 3):
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    return parse(bytes(gcs.command_long_encode(sysid, target_component, command, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs)))


def test_commands_for_the_companion_are_answered_to_their_sender():
    seen = []
    onboard = OnboardComponent(3, lambda cmd: seen.append(cmd) or mavlink.MAV_RESULT_ACCEPTED)
    msg = gcs_command(COMPONENT_ID)
    assert onboard.addressed_to_us(msg)
    ack = parse(onboard.handle(msg))
    assert (ack.get_type(), ack.command, ack.result) == (
        "COMMAND_ACK",
        mavlink.MAV_CMD_MISSION_START,
        mavlink.MAV_RESULT_ACCEPTED,
    )
    assert (ack.target_system, ack.target_component) == (255, 190)
    assert (ack.get_srcSystem(), ack.get_srcComponent()) == (3, COMPONENT_ID)
    assert [(c.command, c.sender_system, c.sender_component) for c in seen] == [
        (mavlink.MAV_CMD_MISSION_START, 255, 190)
    ]


def test_commands_for_the_autopilot_or_another_system_are_not_ours():
    onboard = OnboardComponent(3, lambda cmd: mavlink.MAV_RESULT_ACCEPTED)
    assert not onboard.addressed_to_us(gcs_command(1))  # the autopilot
    assert not onboard.addressed_to_us(gcs_command(COMPONENT_ID, sysid=4))  # another vehicle
    assert not onboard.addressed_to_us(gcs_command(0))  # a broadcast


def test_a_failing_owner_still_answers_failed():
    onboard = OnboardComponent(3, lambda cmd: 1 / 0)
    assert parse(onboard.handle(gcs_command(COMPONENT_ID))).result == mavlink.MAV_RESULT_FAILED


def test_heartbeat_and_status_text_come_from_the_companion_component():
    onboard = OnboardComponent(3, lambda cmd: 0)
    hb = parse(onboard.heartbeat())
    assert (hb.type, hb.autopilot, hb.system_status) == (
        mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
        mavlink.MAV_AUTOPILOT_INVALID,
        mavlink.MAV_STATE_STANDBY,
    )
    onboard.active = True
    assert parse(onboard.heartbeat()).system_status == mavlink.MAV_STATE_ACTIVE
    text = parse(onboard.statustext(mavlink.MAV_SEVERITY_INFO, "companion ready: " + "x" * 80))
    assert text.text.startswith("companion ready: ") and len(text.text) == 50
    assert (text.get_srcSystem(), text.get_srcComponent()) == (3, COMPONENT_ID)


def test_the_gate_answers_commands_for_the_companion_signed_and_keeps_them_from_mavsdk():
    from companion.link.gate import Identity, InboundFilter, OutboundSigner
    from mavlink_signing import SignatureCheck, Verdict

    key = bytes(range(32))
    identity = Identity(system=1, component=195)  # MAVSDK's own address
    onboard = OnboardComponent(3, lambda cmd: mavlink.MAV_RESULT_ACCEPTED)
    inbound = InboundFilter(identity, onboard=onboard)
    command = gcs_command(COMPONENT_ID)
    assert inbound.filter(bytes(command.get_msgbuf())) == []
    assert inbound.counts["onboard"] == 1 and len(inbound.replies) == 1
    signer = OutboundSigner(identity, key)
    signed = signer.sign(inbound.replies.pop())
    ack = parse(signed)
    check = SignatureCheck(key)
    assert (
        check.check(ack.get_msgbuf(), ack.get_msgId(), ack.get_srcSystem(), ack.get_srcComponent()) is Verdict.ACCEPTED
    )
    assert (ack.get_srcSystem(), ack.get_srcComponent()) == (3, COMPONENT_ID)
    assert identity == Identity(system=1, component=195)  # our own frames teach nothing
    assert OutboundSigner(Identity()).sign(onboard.heartbeat()) == onboard.heartbeat()  # no key: as is


def test_the_component_learns_its_system_and_is_silent_before():
    onboard = OnboardComponent(None, lambda cmd: 0)
    assert onboard.heartbeat() is None
    assert not onboard.addressed_to_us(gcs_command(COMPONENT_ID))
    onboard.set_system(3)
    assert (parse(onboard.heartbeat()).get_srcSystem(), onboard.addressed_to_us(gcs_command(COMPONENT_ID))) == (3, True)


def test_heartbeats_are_told_from_other_frames_in_both_versions():
    from pymavlink.dialects.v10 import ardupilotmega as mavlink1

    from companion.link.transport import is_heartbeat

    v2 = mavlink.MAVLink(None, srcSystem=1, srcComponent=195)
    v1 = mavlink1.MAVLink(None, srcSystem=1, srcComponent=195)
    for mav in (v2, v1):
        hb = mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert is_heartbeat(bytes(hb.pack(mav)))
        text = mav.statustext_encode(mavlink.MAV_SEVERITY_INFO, b"x")
        assert not is_heartbeat(bytes(text.pack(mav)))
    assert not is_heartbeat(b"") and not is_heartbeat(b"\x00" * 12)
