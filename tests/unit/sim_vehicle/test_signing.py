"""The vehicle's signing policy (sim_vehicle.signing): what it signs, accepts and how SETUP_SIGNING works."""

from __future__ import annotations

import hashlib
import signal

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from mavlink_signing import SignatureCheck, Verdict, frame_timestamp, signing_encoder, signing_timestamp_now
from sim_vehicle.signing import SIGNING_LINK_ID, VehicleSigning

KEY = hashlib.sha256(b"vehicle key").digest()
NEW_KEY = hashlib.sha256(b"new vehicle key").digest()
WRONG_KEY = hashlib.sha256(b"wrong key").digest()


def parsed(buf: bytes):
    """A message as the vehicle's (keyless) per-datagram parser yields it."""
    parser = mavlink.MAVLink(None, 1, 1)
    msg = parser.parse_char(bytes(buf))
    assert msg is not None and msg.get_type() != "BAD_DATA"
    return msg


def vehicle(key: bytes | None = KEY, accept_setup: bool = False) -> VehicleSigning:
    return VehicleSigning(mavlink.MAVLink(None, srcSystem=1, srcComponent=1), key, accept_setup)


def sent_by(policy: VehicleSigning) -> bytes:
    enc = policy.encoder
    return bytes(enc.heartbeat_encode(2, 3, 0, 0, 0).pack(enc))


def setup_frame(sender, key: bytes, timestamp: int):
    return parsed(sender.setup_signing_encode(1, 1, list(key), timestamp).pack(sender))


def test_with_a_key_the_vehicle_signs_on_its_link_id_and_checks_input():
    policy = vehicle()
    out = sent_by(policy)
    assert out[2] & mavlink.MAVLINK_IFLAG_SIGNED and out[-13] == SIGNING_LINK_ID
    assert SignatureCheck(KEY).check(out, 0, 1, 1) is Verdict.ACCEPTED
    gcs = signing_encoder(KEY, 1, 255, 190)
    assert policy.verdict(parsed(gcs.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs))) is Verdict.ACCEPTED
    plain = mavlink.MAVLink(None, 255, 190)
    assert policy.verdict(parsed(plain.heartbeat_encode(6, 8, 0, 0, 0).pack(plain))) is Verdict.UNSIGNED


def test_without_a_key_nothing_is_signed_and_everything_accepted():
    policy = vehicle(None)
    assert not sent_by(policy)[2] & mavlink.MAVLINK_IFLAG_SIGNED
    wrong = signing_encoder(WRONG_KEY, 1, 255, 190)
    assert policy.verdict(parsed(wrong.heartbeat_encode(6, 8, 0, 0, 0).pack(wrong))) is Verdict.ACCEPTED


def test_the_outgoing_timestamp_follows_accepted_input_and_the_clock():
    policy = vehicle()
    gcs = signing_encoder(KEY, 1, 255, 190)
    gcs.signing.timestamp += 50_000_000  # a sender 500 s ahead
    assert policy.verdict(parsed(gcs.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs))) is Verdict.ACCEPTED
    assert frame_timestamp(sent_by(policy)) > gcs.signing.timestamp - 5
    policy = vehicle()
    policy.encoder.signing.timestamp -= 10_000_000  # 100 s behind (as after few messages in a long flight)
    policy.tick()
    assert frame_timestamp(sent_by(policy)) >= signing_timestamp_now() - 100_000


def test_setup_signed_with_the_current_key_changes_it_and_moves_the_timestamp():
    policy = vehicle()
    gcs = signing_encoder(KEY, 1, 255, 190)
    future = signing_timestamp_now() + 3_000_000_000
    done, what = policy.setup(setup_frame(gcs, NEW_KEY, future))
    assert done, what
    assert frame_timestamp(sent_by(policy)) >= future
    assert SignatureCheck(NEW_KEY).check(sent_by(policy), 0, 1, 1) is Verdict.ACCEPTED
    old = signing_encoder(KEY, 2, 255, 190)
    new = signing_encoder(NEW_KEY, 3, 255, 190)
    new.signing.timestamp = future
    assert policy.verdict(parsed(old.heartbeat_encode(6, 8, 0, 0, 0).pack(old))) is Verdict.BAD_SIGNATURE
    assert policy.verdict(parsed(new.heartbeat_encode(6, 8, 0, 0, 0).pack(new))) is Verdict.ACCEPTED


def test_setup_not_signed_with_the_current_key_is_refused():
    policy = vehicle()
    for sender in (mavlink.MAVLink(None, 255, 190), signing_encoder(WRONG_KEY, 1, 255, 190)):
        done, what = policy.setup(setup_frame(sender, NEW_KEY, 0))
        assert not done and "current key" in what
    assert policy.check.key == KEY and policy.encoder.signing.secret_key == KEY


def test_all_zero_key_with_zero_timestamp_disables_signing_and_nonzero_timestamp_is_refused():
    policy = vehicle()
    gcs = signing_encoder(KEY, 1, 255, 190)
    done, _ = policy.setup(setup_frame(gcs, bytes(32), 12345))
    assert not done and policy.enabled
    done, _ = policy.setup(setup_frame(gcs, bytes(32), 0))
    assert done and not policy.enabled
    assert not sent_by(policy)[2] & mavlink.MAVLINK_IFLAG_SIGNED
    plain = mavlink.MAVLink(None, 255, 190)
    assert policy.verdict(parsed(plain.heartbeat_encode(6, 8, 0, 0, 0).pack(plain))) is Verdict.ACCEPTED
    done, what = policy.setup(setup_frame(plain, NEW_KEY, 0))  # off now, and no --accept-signing-setup
    assert not done and "accept-signing-setup" in what


def test_without_a_key_setup_needs_accept_signing_setup():
    plain = mavlink.MAVLink(None, 255, 190)
    refusing = vehicle(None)
    done, what = refusing.setup(setup_frame(plain, NEW_KEY, 0))
    assert not done and not refusing.enabled and "accept-signing-setup" in what
    accepting = vehicle(None, accept_setup=True)
    done, _ = accepting.setup(setup_frame(plain, NEW_KEY, 0))
    assert done and accepting.enabled and accepting.check.key == NEW_KEY
    assert sent_by(accepting)[2] & mavlink.MAVLINK_IFLAG_SIGNED
    assert accepting.verdict(parsed(plain.heartbeat_encode(6, 8, 0, 0, 0).pack(plain))) is Verdict.UNSIGNED


def test_a_bad_key_file_is_one_line_naming_it_and_exit_status_2(tmp_path, capsys):
    from sim_vehicle.cli import main

    empty = tmp_path / "empty.key"
    empty.write_text("\n")
    sigterm = signal.getsignal(signal.SIGTERM)  # main() installs its own
    try:
        for path in (empty, tmp_path / "missing.key"):
            assert main(["--signing-key", str(path), "--no-default-out", "--port", "0"]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and err.startswith("sim-vehicle: error: --signing-key:")
            assert str(path) in err
    finally:
        signal.signal(signal.SIGTERM, sigterm)


def test_every_drop_reason_has_a_link_counter_next_to_the_malformed_ones():
    import dataclasses

    from sim_vehicle.mavlink import LinkStats
    from sim_vehicle.signing import DROP_REASONS

    fields = {f.name for f in dataclasses.fields(LinkStats)}
    assert {reason.value for reason in DROP_REASONS} == {"unsigned", "bad_signature", "replayed", "stale"}
    assert {reason.value for reason in DROP_REASONS} <= fields and "bad_crc" in fields
