"""The shared MAVLink 2 signing package: key file, signing encoder, signature check (issue 11)."""

from __future__ import annotations

import hashlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from mavlink_signing import (
    SignatureCheck,
    SigningKeyError,
    Verdict,
    frame_timestamp,
    key_from_text,
    load_key,
    signature_matches,
    signing_encoder,
    signing_timestamp_now,
)
from mavlink_signing.verify import NEW_STREAM_WINDOW

KEY = hashlib.sha256(b"unit-test key").digest()
OTHER_KEY = hashlib.sha256(b"another key").digest()


def mavproxy_key(passphrase: str) -> bytes:
    """The key MAVProxy's ``signing key PASSPHRASE`` derives (its own code, from the venv)."""
    from MAVProxy.modules.mavproxy_signing import SigningModule

    return SigningModule.passphrase_to_key(None, passphrase)


def command_frame(mav, command: int = mavlink.MAV_CMD_DO_SET_MODE) -> bytes:
    return bytes(mav.command_long_encode(1, 1, command, 0, 1, 9, 0, 0, 0, 0, 0).pack(mav))


def judge(
    check: SignatureCheck,
    buf: bytes,
    msg_id: int = mavlink.MAVLINK_MSG_ID_COMMAND_LONG,
    sysid: int = 250,
    compid: int = 190,
) -> Verdict:
    return check.check(buf, msg_id, sysid, compid)


# ---------------------------------------------------------------- keys
def test_64_hex_digits_are_the_key_itself_in_either_case():
    assert key_from_text(KEY.hex() + "\n") == KEY
    assert key_from_text("  " + KEY.hex().upper() + "\r\n") == KEY


def test_a_passphrase_gives_the_same_key_as_mavproxy():
    assert (
        key_from_text("correct-horse\n") == mavproxy_key("correct-horse") == hashlib.sha256(b"correct-horse").digest()
    )


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=80))
def test_any_one_word_ascii_passphrase_matches_mavproxy(passphrase):
    if len(passphrase) == 64 and all(c in "0123456789abcdefABCDEF" for c in passphrase):
        assert key_from_text(passphrase) == bytes.fromhex(passphrase)  # the hex form wins
    else:
        assert key_from_text(passphrase) == mavproxy_key(passphrase)


def test_63_or_65_hex_digits_are_a_passphrase():
    for text in (KEY.hex()[:63], KEY.hex() + "a"):
        assert key_from_text(text) == hashlib.sha256(text.encode()).digest()


def test_load_key_reads_the_file_and_errors_name_it(tmp_path):
    good = tmp_path / "good.key"
    good.write_text("correct-horse\n")
    assert load_key(good) == mavproxy_key("correct-horse")
    empty = tmp_path / "empty.key"
    empty.write_text(" \n")
    for path in (empty, tmp_path / "missing.key", tmp_path):
        with pytest.raises(SigningKeyError, match=str(path)):
            load_key(path)


# ---------------------------------------------------------------- encoder and check
def test_encoder_frames_are_accepted_by_the_check_and_by_pymavlink():
    mav = signing_encoder(KEY, 7, 250, 190)
    buf = command_frame(mav)
    assert buf[2] & mavlink.MAVLINK_IFLAG_SIGNED and buf[-13] == 7
    assert abs(frame_timestamp(buf) - signing_timestamp_now()) < 100_000 * 5  # within 5 s of the clock
    assert signature_matches(KEY, buf) and not signature_matches(OTHER_KEY, buf)
    assert judge(SignatureCheck(KEY), buf) is Verdict.ACCEPTED
    receiver = mavlink.MAVLink(None)
    receiver.signing.secret_key = KEY
    msg = receiver.parse_char(buf)
    assert msg is not None and msg.get_type() == "COMMAND_LONG" and msg.get_signed()


def test_frames_of_another_key_are_bad_signature_and_unsigned_ones_unsigned():
    check = SignatureCheck(KEY)
    assert judge(check, command_frame(signing_encoder(OTHER_KEY, 0, 250, 190))) is Verdict.BAD_SIGNATURE
    assert judge(check, command_frame(mavlink.MAVLink(None, 250, 190))) is Verdict.UNSIGNED
    v1 = mavlink.MAVLink(None, 250, 190)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    buf = bytes(v1.command_long_encode(1, 1, 176, 0, 1, 9, 0, 0, 0, 0, 0).pack(v1, force_mavlink1=True))
    assert buf[0] == mavlink.PROTOCOL_MARKER_V1 and judge(check, buf) is Verdict.UNSIGNED
    assert check.counts[Verdict.BAD_SIGNATURE] == 1 and check.counts[Verdict.UNSIGNED] == 2


def test_radio_status_is_the_only_message_accepted_unsigned():
    plain = mavlink.MAVLink(None, 51, 68)
    radio = bytes(plain.radio_status_encode(200, 190, 100, 90, 80, 0, 0).pack(plain))
    check = SignatureCheck(KEY)
    assert judge(check, radio, mavlink.MAVLINK_MSG_ID_RADIO_STATUS, 51, 68) is Verdict.ACCEPTED
    heartbeat = bytes(plain.heartbeat_encode(6, 8, 0, 0, 0).pack(plain))
    assert judge(check, heartbeat, mavlink.MAVLINK_MSG_ID_HEARTBEAT, 51, 68) is Verdict.UNSIGNED


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_any_tampered_byte_of_a_signed_frame_is_refused(data):
    mav = signing_encoder(KEY, 3, 250, 190)
    buf = command_frame(mav)
    index = data.draw(st.integers(0, len(buf) - 1), label="index")
    flip = data.draw(st.integers(1, 255), label="xor")
    tampered = bytearray(buf)
    tampered[index] ^= flip
    check = SignatureCheck(KEY)
    assert judge(check, bytes(tampered)) is not Verdict.ACCEPTED
    assert judge(check, buf) is Verdict.ACCEPTED  # the forgery did not lock the real frame out


@settings(max_examples=100, deadline=None)
@given(st.integers(2, 20), st.data())
def test_any_replayed_frame_is_refused(count, data):
    mav = signing_encoder(KEY, 1, 250, 190)
    frames = [command_frame(mav) for _ in range(count)]
    check = SignatureCheck(KEY)
    assert all(judge(check, f) is Verdict.ACCEPTED for f in frames)
    replay = data.draw(st.sampled_from(frames), label="replayed frame")
    assert judge(check, replay) is Verdict.REPLAYED
    assert check.counts[Verdict.REPLAYED] == 1


def test_timestamps_are_per_stream():
    check = SignatureCheck(KEY)
    ahead = signing_encoder(KEY, 1, 250, 190)
    ahead.signing.timestamp += 1000
    behind = signing_encoder(KEY, 2, 250, 190)  # another link id: another stream, older timestamps
    assert judge(check, command_frame(ahead)) is Verdict.ACCEPTED
    assert judge(check, command_frame(behind)) is Verdict.ACCEPTED
    other_system = signing_encoder(KEY, 1, 251, 190)
    assert judge(check, command_frame(other_system), sysid=251) is Verdict.ACCEPTED


def test_a_new_stream_more_than_a_minute_behind_is_stale():
    check = SignatureCheck(KEY)
    old = signing_encoder(KEY, 1, 250, 190)
    old.signing.timestamp = check.newest - NEW_STREAM_WINDOW - 100
    assert judge(check, command_frame(old)) is Verdict.STALE
    recent = signing_encoder(KEY, 2, 250, 190)
    recent.signing.timestamp = check.newest - NEW_STREAM_WINDOW + 100_000
    assert judge(check, command_frame(recent)) is Verdict.ACCEPTED


def test_a_forged_future_timestamp_does_not_lock_the_sender_out():
    check = SignatureCheck(KEY)
    forger = signing_encoder(OTHER_KEY, 1, 250, 190)
    forger.signing.timestamp += 10**9  # hours ahead, same stream
    assert judge(check, command_frame(forger)) is Verdict.BAD_SIGNATURE
    assert judge(check, command_frame(signing_encoder(KEY, 1, 250, 190))) is Verdict.ACCEPTED


def test_advance_makes_old_new_streams_stale_and_rekey_keeps_streams():
    check = SignatureCheck(KEY)
    mav = signing_encoder(KEY, 1, 250, 190)
    first = command_frame(mav)
    assert judge(check, first) is Verdict.ACCEPTED
    check.advance(check.newest + 2 * NEW_STREAM_WINDOW)
    assert judge(check, command_frame(signing_encoder(KEY, 9, 250, 190))) is Verdict.STALE
    check.rekey(OTHER_KEY)
    assert judge(check, command_frame(mav)) is Verdict.BAD_SIGNATURE
    check.rekey(KEY)
    assert judge(check, first) is Verdict.REPLAYED  # the stream's last timestamp survived the key changes
