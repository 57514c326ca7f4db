"""Checking what is received: the MAVLink 2 signature first, then a forward-moving timestamp.

The order matters. pymavlink's own check records a stream's timestamp before it compares the
signature, so one forged frame with a far-future timestamp would lock the real sender out;
this check records a timestamp only for a frame whose signature is right (as ArduPilot does).

A stream is (link id, system id, component id). A frame is accepted when it is signed with the
key, its timestamp is newer than the stream's last, and, for a stream not seen before, no more
than ``NEW_STREAM_WINDOW`` (one minute) behind the newest timestamp known. RADIO_STATUS may come
unsigned (a radio cannot sign), as in ArduPilot.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from mavlink_signing.sign import signing_timestamp_now

SIGNATURE_BYTES = 13
#: A new stream may start at most this far (10 us ticks: one minute) behind the newest timestamp.
NEW_STREAM_WINDOW = 6_000_000
#: Messages accepted unsigned (ArduPilot accepts RADIO_STATUS from radios that cannot sign).
UNSIGNED_ALLOWED = frozenset({mavlink.MAVLINK_MSG_ID_RADIO_STATUS})


class Verdict(enum.Enum):
    """What the check says of one frame (``ACCEPTED`` or the reason it is dropped)."""

    ACCEPTED = "accepted"
    UNSIGNED = "unsigned"
    BAD_SIGNATURE = "bad_signature"
    REPLAYED = "replayed"
    STALE = "stale"


class SignatureCheck:
    """Per-receiver signing state: the key, the newest timestamp and each stream's last one.

    Parameters
    ----------
    key : bytes
        The 32-byte secret key.
    """

    def __init__(self, key: bytes) -> None:
        self.key = bytes(key)
        self.newest = signing_timestamp_now()
        self.streams: dict[tuple[int, int, int], int] = {}
        self.counts = {verdict: 0 for verdict in Verdict}

    def check(self, msgbuf: bytes, msg_id: int, src_system: int, src_component: int) -> Verdict:
        """Judge one complete frame ``msgbuf`` (header to signature) and count the verdict."""
        verdict = self._judge(bytes(msgbuf), msg_id, src_system, src_component)
        self.counts[verdict] += 1
        return verdict

    def advance(self, timestamp: int) -> None:
        """Move the newest known timestamp forward to ``timestamp`` (e.g. the wall clock, once a second).

        A stream not seen before must then start no more than ``NEW_STREAM_WINDOW`` behind it,
        so frames recorded long ago stay stale however quiet the link has been.
        """
        self.newest = max(self.newest, int(timestamp))

    def rekey(self, key: bytes, timestamp: int = 0) -> None:
        """Check with ``key`` from now on; the newest timestamp becomes at least ``timestamp``.

        The streams' last timestamps are kept: a frame recorded before the change stays a replay.
        """
        self.key = bytes(key)
        self.advance(timestamp)

    def _judge(self, buf: bytes, msg_id: int, src_system: int, src_component: int) -> Verdict:
        signed = len(buf) > SIGNATURE_BYTES and buf[0] == mavlink.PROTOCOL_MARKER_V2 and buf[2] & 0x01
        if not signed:
            return Verdict.ACCEPTED if msg_id in UNSIGNED_ALLOWED else Verdict.UNSIGNED
        if not signature_matches(self.key, buf):
            return Verdict.BAD_SIGNATURE
        link_id = buf[-SIGNATURE_BYTES]
        timestamp = frame_timestamp(buf)
        stream = (link_id, src_system, src_component)
        last = self.streams.get(stream)
        if last is not None and timestamp <= last:
            return Verdict.REPLAYED
        if last is None and timestamp + NEW_STREAM_WINDOW < self.newest:
            return Verdict.STALE
        self.streams[stream] = timestamp
        self.newest = max(self.newest, timestamp)
        return Verdict.ACCEPTED


def signature_matches(key: bytes, buf: bytes) -> bool:
    """True if the signed MAVLink 2 frame ``buf`` carries the signature of ``key``.

    The signature is the first 6 bytes of SHA-256 over the key, then the frame from its header
    to the link id and timestamp (everything but the signature itself).
    """
    buf = bytes(buf)
    if len(buf) <= SIGNATURE_BYTES:
        return False
    return hmac.compare_digest(hashlib.sha256(bytes(key) + buf[:-6]).digest()[:6], buf[-6:])


def frame_timestamp(buf: bytes) -> int:
    """The 48-bit signing timestamp (10 us ticks since 2015) of the signed frame ``buf``."""
    low, high = struct.unpack("<IH", bytes(buf)[-12:-6])
    return low + (high << 32)
