"""The companion's MAVLink gate: what MAVSDK may see, and what the vehicle receives from it."""

from hypothesis import given
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.link.gate import Identity, InboundFilter, OutboundSigner, SigningKey, silence_reason
from mavlink_signing import SignatureCheck, Verdict, key_from_text, signing_encoder

KEY = key_from_text("operator passphrase")
OTHER_KEY = key_from_text("somebody else")
US = (1, 191)  # MAVSDK's own system / component in these tests
VEHICLE = (1, 1)


def encoder(src=VEHICLE, key=None):
    if key is not None:
        return signing_encoder(key, 0, *src)
    return mavlink.MAVLink(None, srcSystem=src[0], srcComponent=src[1])


def ack_to(target_system, target_component, key=None):
    mav = encoder(key=key)
    return mav.command_ack_encode(22, 0, 0, 0, target_system, target_component).pack(mav)


def heartbeat(src=VEHICLE, key=None):
    mav = encoder(src, key)
    return mav.heartbeat_encode(mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4).pack(mav)


def learned_filter(check=None) -> InboundFilter:
    identity = Identity()
    OutboundSigner(identity).convert(heartbeat(US))
    return InboundFilter(identity, check)


def test_mavsdk_identity_is_learned_from_its_first_heartbeat():
    identity = Identity()
    OutboundSigner(identity).convert(heartbeat(US))
    OutboundSigner(identity).convert(heartbeat((7, 8)))
    assert (identity.system, identity.component) == US


def test_answers_to_other_senders_never_reach_mavsdk():
    gate = learned_filter()
    assert gate.filter(ack_to(*US)) == [ack_to(*US)]
    assert gate.filter(ack_to(US[0], 0)) != []  # our system, any component
    assert gate.filter(ack_to(255, 190)) == []  # a ground station's answer
    assert gate.filter(ack_to(US[0], 190)) == []  # our system, another component
    assert gate.filter(heartbeat()) != []  # broadcast
    assert gate.counts == {"passed": 3, "not_for_us": 2, "onboard": 0, "malformed": 0}


def test_before_mavsdk_spoke_only_broadcasts_pass():
    gate = InboundFilter(Identity())
    assert gate.filter(ack_to(*US)) == []
    assert gate.filter(heartbeat()) != []


def test_with_a_key_only_correctly_signed_fresh_frames_pass():
    gate = learned_filter(SignatureCheck(KEY))
    signed = heartbeat(key=KEY)
    assert gate.filter(signed) == [signed]
    assert gate.filter(signed) == []  # replayed
    assert gate.filter(heartbeat()) == []  # unsigned
    assert gate.filter(heartbeat(key=OTHER_KEY)) == []  # another key
    radio = encoder().radio_status_encode(200, 190, 50, 40, 30, 0, 0)
    assert gate.filter(radio.pack(encoder())) != []  # a radio cannot sign
    counts = gate.counts
    assert (counts["replayed"], counts["unsigned"], counts["bad_signature"], counts["passed"]) == (1, 1, 1, 2)


def test_a_wrong_key_is_named_when_nothing_is_heard():
    gate = learned_filter(SignatureCheck(KEY))
    gate.filter(heartbeat(key=OTHER_KEY))
    key = SigningKey(KEY, "/etc/heli/signing.key")
    assert "another key than --signing-key /etc/heli/signing.key" in silence_reason(gate.counts, key)
    gate.filter(heartbeat())
    assert "/etc/heli/signing.key" in silence_reason({"unsigned": 1}, key)
    assert "running" in silence_reason({}, None)


def test_outbound_frames_are_signed_keeping_their_sender_and_sequence():
    identity = Identity()
    signer = OutboundSigner(identity, KEY, link_id=3)
    plain = heartbeat(US)
    (signed,) = signer.convert(plain)
    msg = mavlink.MAVLink(None).parse_char(signed)
    assert (msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq()) == (*US, 0)
    assert SignatureCheck(KEY).check(signed, msg.get_msgId(), *US) is Verdict.ACCEPTED
    assert SignatureCheck(OTHER_KEY).check(signed, msg.get_msgId(), *US) is Verdict.BAD_SIGNATURE
    assert signed[-13] == 3  # link id


def test_without_a_key_outbound_bytes_pass_unchanged():
    plain = heartbeat(US)
    assert OutboundSigner(Identity()).convert(plain) == [plain]
    assert OutboundSigner(Identity()).convert(b"\x00garbage") == []


@given(st.lists(st.binary(max_size=300), max_size=20), st.integers(0, 40))
def test_garbage_never_raises_and_never_passes_a_signed_gate(chunks, cut):
    datagrams, stream = learned_filter(SignatureCheck(KEY)), learned_filter(SignatureCheck(KEY))
    stream.stream = True
    signed = heartbeat(key=KEY)
    for chunk in chunks:
        assert datagrams.filter(chunk) == [] and stream.filter(chunk) == []
    # a good datagram after any garbage gets through; on a byte stream, even split in two reads
    assert datagrams.filter(signed) == [signed]
    assert stream.filter(bytes(300)) == []  # (zeros resynchronise a stream)
    assert stream.filter(signed[:cut]) + stream.filter(signed[cut:]) == [signed]


def test_the_types_the_link_reads_are_tapped_as_fields_once_admitted():
    gate = learned_filter(SignatureCheck(KEY))
    gate.tapped.add("HEARTBEAT")
    gate.filter(heartbeat(key=KEY))
    gate.filter(heartbeat(key=OTHER_KEY))  # refused: never tapped
    gate.filter(ack_to(*US, key=KEY))  # admitted, not a tapped type
    assert [kind for kind, _ in gate.taps] == ["HEARTBEAT"]
    fields = gate.taps[0][1]
    assert (fields["type"], fields["autopilot"], fields["_sysid"], fields["_compid"]) == (
        mavlink.MAV_TYPE_HELICOPTER,
        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        *VEHICLE,
    )
    assert "mavpackettype" not in fields and fields["_t_s"] > 0


def setpoint():
    return mavlink.MAVLink_set_position_target_local_ned_message(
        1000, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0, 1.0, 2.0, -10.0, 0, 0, 0, 0, 0, 0, 0.5, 0
    )


def test_own_messages_go_out_from_mavsdks_address_with_their_own_sequence_signed_with_the_key():
    identity = Identity()
    for key in (None, KEY):
        signer = OutboundSigner(identity, key)
        assert identity.system is not None or signer.pack_own(setpoint()) is None  # address unknown yet
        signer.convert(heartbeat(US))
        frames = [signer.pack_own(setpoint()) for _ in range(3)]
        parsed = [mavlink.MAVLink(None).parse_buffer(frame)[0] for frame in frames]
        assert [(m.get_srcSystem(), m.get_srcComponent()) for m in parsed] == [US] * 3
        assert [m.get_seq() for m in parsed] == [0, 1, 2] and parsed[0].x == 1.0
        if key is not None:
            check = SignatureCheck(KEY)
            assert [check.check(m.get_msgbuf(), m.get_msgId(), *US) for m in parsed] == [Verdict.ACCEPTED] * 3
