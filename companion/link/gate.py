"""The companion's MAVLink gate: MAVSDK reaches the vehicle only through it.

MAVSDK 4.x has no MAVLink 2 signing, and it takes any COMMAND_ACK or mission answer of the
vehicle as its own, even one the vehicle addressed to another sender. The gate sits between
the two on this machine (MAVSDK talks to it over loopback UDP) and does, per direction:

- **inbound** (vehicle -> MAVSDK, ``InboundFilter``): parse; with a key, drop every frame not
  correctly signed with it or whose timestamp does not move forward (``SignatureCheck``); drop
  frames addressed to another system or component (MAVLink routing: a message with
  ``target_system`` / ``target_component`` is for that system / component; 0 is broadcast);
  pass the rest on unchanged. Every frame is counted by what happened to it.
- **outbound** (MAVSDK -> vehicle, ``OutboundSigner``): with a key, re-pack each message signed
  (same system, component and sequence); without one, pass the bytes on. MAVSDK's own system and
  component ids are learned from its first HEARTBEAT, which tells the inbound side who "us" is.

The transport to the vehicle (``companion.link.transport``) follows the MAVSDK URL the user gave.
This module is pure: bytes in, bytes out; the thread and sockets are in ``GateThread``.
"""

from __future__ import annotations

import dataclasses
import logging
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import LinkError
from mavlink_signing import SignatureCheck, SigningKeyError, Verdict, load_key, signing_encoder, signing_timestamp_now
from mavlink_signing.keys import key_fingerprint

log = logging.getLogger(__name__)

#: Inbound outcomes counted besides the signature verdicts.
PASSED, NOT_FOR_US, ONBOARD, MALFORMED = "passed", "not_for_us", "onboard", "malformed"


@dataclasses.dataclass(frozen=True)
class SigningKey:
    """A signing key and where it came from (errors name the file, logs the fingerprint)."""

    key: bytes
    path: str

    @classmethod
    def from_file(cls, path) -> SigningKey | None:
        """Read a key file (``mavlink_signing.load_key``: 64 hex digits or a passphrase); None
        for an empty path; a bad file is a ``LinkError`` naming it."""
        if not path:
            return None
        try:
            return cls(load_key(path), str(path))
        except SigningKeyError as exc:
            raise LinkError(f"--signing-key: {exc}") from None

    def __str__(self) -> str:
        return f"{self.path} (key id {key_fingerprint(self.key)})"


def silence_reason(counts: dict[str, int], key: SigningKey | None) -> str:
    """Why no autopilot was heard, from what the inbound filter dropped (one line)."""
    if key is not None and counts.get(Verdict.BAD_SIGNATURE.value, 0):
        return f"{counts[Verdict.BAD_SIGNATURE.value]} frames came signed with another key than --signing-key {key}"
    if key is not None and counts.get(Verdict.UNSIGNED.value, 0):
        return (
            f"{counts[Verdict.UNSIGNED.value]} frames came unsigned although --signing-key "
            f"{key} is given: is the vehicle started with that key?"
        )
    if counts.get(MALFORMED, 0) and not counts.get(PASSED, 0):
        return f"{counts[MALFORMED]} frames arrived but none was MAVLink"
    return "is the vehicle running and sending to this address?"


@dataclasses.dataclass
class Identity:
    """MAVSDK's own MAVLink address (learned from its first HEARTBEAT)."""

    system: int | None = None
    component: int | None = None

    def addressed_elsewhere(self, msg) -> bool:
        """Is ``msg`` addressed to a system or component that is not us?"""
        target_system = getattr(msg, "target_system", 0) or 0
        target_component = getattr(msg, "target_component", 0) or 0
        if target_system == 0:
            return False
        if self.system is None or target_system != self.system:
            return True
        return target_component not in (0, self.component)


def tapped_fields(msg, arrival_s: float | None = None) -> dict:
    """A message's fields by name (text decoded), with ``_sysid``, ``_compid`` and ``_t_s``
    (monotonic arrival time: ``arrival_s``, else now): what ``VehicleLink.inbound.messages``
    yields."""
    fields = msg.to_dict()
    del fields["mavpackettype"]
    fields["_sysid"], fields["_compid"] = msg.get_srcSystem(), msg.get_srcComponent()
    fields["_t_s"] = time.monotonic() if arrival_s is None else arrival_s
    return fields


#: Telemetry the link reads itself (``VehicleLink.inbound.messages``) and MAVSDK has no use for
#: (the companion creates no MAVSDK Telemetry plugin): the gate does not forward it to MAVSDK (a
#: wake-up of its threads for each of about 30 frames a second). The tlog still has every frame.
LINK_ONLY_MESSAGES = frozenset(
    {"LOCAL_POSITION_NED", "ATTITUDE", "GLOBAL_POSITION_INT", "SERVO_OUTPUT_RAW", "RPM", "ADSB_VEHICLE"}
)


def new_parser() -> mavlink.MAVLink:
    """A pymavlink parser that returns BAD_DATA for garbage instead of raising."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    return parser


class InboundFilter:
    """Frames from the vehicle: which of them MAVSDK may see.

    Parameters
    ----------
    identity : Identity
        Who we are (shared with the outbound side, which learns it).
    check : SignatureCheck or None
        With a signing key: the signature and timestamp check.
    stream : bool
        The vehicle link is a byte stream (TCP, serial): a frame may span two reads, so the
        parser keeps what is left. A datagram link parses each datagram on its own, so a
        truncated datagram can never swallow the start of the next.

    Attributes
    ----------
    onboard : OnboardComponent, optional
        The companion's own component: commands addressed to it are answered by it (the
        answers wait in ``replies``) and never reach MAVSDK.
    kinds : list of str
        The message types of the frames the last ``filter`` returned, in the same order.
    tapped : set of str
        Message types the link reads itself (``VehicleLink.inbound.messages``): each admitted
        one is also kept in ``taps`` as ``(type, fields)`` (``tapped_fields``) for the gate to hand over.
    listeners : dict of str to list of callable
        Message type -> callables given each admitted message's fields at once, on the gate's
        thread (``VehicleLink.inbound.listen``: the live view, which must not wait for the
        hand-over). A listener that raises is logged; the frame goes on.
    counts : dict of str to int
        ``passed``, ``not_for_us``, ``onboard``, ``malformed`` and, with a key, each refused
        ``Verdict`` value (``unsigned``, ``bad_signature``, ``replayed``, ``stale``).
    """

    def __init__(
        self, identity: Identity, check: SignatureCheck | None = None, stream: bool = False, onboard=None
    ) -> None:
        self.identity = identity
        self.check = check
        self.stream = stream
        self.onboard = onboard  # companion.link.onboard.OnboardComponent or None
        self.replies: list[bytes] = []  # its answers, for the gate to send
        self.tapped: set[str] = set()  # message types the link reads (``taps``)
        self.taps: list[tuple[str, dict]] = []  # admitted messages of those types, as fields
        self.listeners: dict[str, list] = {}  # message type -> callables on the gate's thread
        self.parser = new_parser()
        self.autopilot_heard = False
        self._arrival_s: float | None = None
        self.kinds: list[str] = []
        self.counts: dict[str, int] = {PASSED: 0, NOT_FOR_US: 0, ONBOARD: 0, MALFORMED: 0}
        if check is not None:
            self.counts.update({v.value: 0 for v in Verdict if v is not Verdict.ACCEPTED})

    def filter(self, data: bytes, arrival_s: float | None = None) -> list[bytes]:
        """The complete frames of ``data`` (a datagram, or a piece of a byte stream: partial
        frames wait for the next call) that MAVSDK may see, in order; ``arrival_s``: when
        ``data`` arrived (monotonic; None: now), the ``_t_s`` of the messages tapped.

        ``autopilot_heard`` tells whether an accepted frame of ``data`` was an autopilot's
        HEARTBEAT (the gate answers only such a sender on a listening link)."""
        self.autopilot_heard = False
        self._arrival_s = arrival_s
        if not self.stream:
            self.parser = new_parser()
        try:
            messages = self.parser.parse_buffer(bytes(data)) or []
        except Exception:  # pymavlink raises odd errors on some garbage: drop, never stop
            self.parser = new_parser()
            self._count(MALFORMED)
            self.kinds = []
            return []
        if not self.stream and self.parser.buf_len() > 0:
            self._count(MALFORMED)  # a datagram that ends inside a frame
        admitted = [msg for msg in messages if self._admits(msg)]
        self.kinds = [msg.get_type() for msg in admitted]
        return [bytes(msg.get_msgbuf()) for msg in admitted]

    def _admits(self, msg) -> bool:
        if msg.get_type() == "BAD_DATA" or isinstance(msg, mavlink.MAVLink_unknown):
            return self._count(MALFORMED)
        if self.check is not None:
            verdict = self.check.check(msg.get_msgbuf(), msg.get_msgId(), msg.get_srcSystem(), msg.get_srcComponent())
            if verdict is not Verdict.ACCEPTED:
                return self._count(verdict.value)
        if self.onboard is not None and self.onboard.addressed_to_us(msg):
            self.replies.append(self.onboard.handle(msg))
            return self._count(ONBOARD)
        if self.identity.addressed_elsewhere(msg):
            return self._count(NOT_FOR_US)
        self.counts[PASSED] += 1
        kind = msg.get_type()
        self.autopilot_heard |= kind == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID
        if kind in self.tapped or kind in self.listeners:
            self._tap(kind, tapped_fields(msg, self._arrival_s))
        return True

    def _tap(self, kind: str, fields: dict) -> None:
        """Keep the message for the hand-over (``taps``) and give it to its ``listeners`` now."""
        if kind in self.tapped:
            self.taps.append((kind, fields))
        for listener in self.listeners.get(kind, ()):
            try:
                listener(fields)
            except Exception:  # a listener's bug never costs the link a frame
                log.exception("listener of %s failed", kind)

    def _count(self, outcome: str) -> bool:
        """Count a dropped frame; log the first of each kind, then every 1000th."""
        n = self.counts[outcome] = self.counts[outcome] + 1
        if outcome not in (NOT_FOR_US, ONBOARD) and (n == 1 or n % 1000 == 0):
            log.warning("dropping frames from the vehicle link: %s (%d so far)", outcome, n)
        return False


class OutboundSigner:
    """Frames from MAVSDK to the vehicle: learn who we are; sign them with a key.

    Parameters
    ----------
    identity : Identity
        Filled in from MAVSDK's first HEARTBEAT.
    key : bytes or None
        The 32-byte signing key (None: frames pass unchanged).
    link_id : int
        The signing link id of this link.
    """

    def __init__(self, identity: Identity, key: bytes | None = None, link_id: int = 0) -> None:
        self.identity = identity
        self.encoder = None if key is None else signing_encoder(key, link_id, 0, 0)
        self.unsignable = 0
        self._own_encoder = mavlink.MAVLink(None)  # our own messages without a key
        self._own_seq = 0

    def pack_own(self, msg) -> bytes | None:
        """Our own message ``msg`` (a pymavlink message object, e.g. a setpoint) as a frame from
        MAVSDK's address with a sequence of our own, signed when there is a key; None until
        MAVSDK's address is known."""
        if self.identity.system is None:
            return None
        enc = self.encoder if self.encoder is not None else self._own_encoder
        enc.srcSystem, enc.srcComponent, enc.seq = self.identity.system, self.identity.component, self._own_seq
        self._own_seq = (self._own_seq + 1) % 256
        if enc.signing.sign_outgoing:
            enc.signing.timestamp = max(enc.signing.timestamp, signing_timestamp_now())
        return bytes(msg.pack(enc))

    def convert(self, data: bytes) -> list[bytes]:
        """The frames to send to the vehicle for the datagram MAVSDK sent."""
        try:
            messages = new_parser().parse_buffer(bytes(data)) or []
        except Exception:
            messages = []
        known = [m for m in messages if m.get_type() != "BAD_DATA"]
        for msg in known:
            self._learn_identity(msg)
        if self.encoder is None:
            return [bytes(data)] if known else []
        return [frame for frame in map(self._signed, known) if frame is not None]

    def sign(self, frame: bytes) -> bytes | None:
        """One frame of our own (not MAVSDK's: it teaches nothing about who MAVSDK is), signed
        when there is a key."""
        if self.encoder is None:
            return frame
        messages = [m for m in new_parser().parse_buffer(frame) or [] if m.get_type() != "BAD_DATA"]
        return self._signed(messages[0]) if len(messages) == 1 else None

    def _learn_identity(self, msg) -> None:
        if self.identity.system is None and msg.get_type() == "HEARTBEAT":
            self.identity.component = msg.get_srcComponent()
            self.identity.system = msg.get_srcSystem()
            log.debug("MAVSDK speaks as system %d component %d", self.identity.system, self.identity.component)

    def _signed(self, msg) -> bytes | None:
        if isinstance(msg, mavlink.MAVLink_unknown):
            self.unsignable += 1
            if self.unsignable <= 10:
                log.warning("cannot sign message id %d from MAVSDK (not in the dialect): dropped", msg.get_msgId())
            return None
        enc = self.encoder
        enc.srcSystem, enc.srcComponent, enc.seq = msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq()
        # pymavlink adds one tick (10 us) per frame: keep up with the wall clock, so a receiver
        # that meets this link later never finds it a minute behind (stale)
        enc.signing.timestamp = max(enc.signing.timestamp, signing_timestamp_now())
        return bytes(msg.pack(enc))
