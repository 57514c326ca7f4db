"""The vehicle's MAVLink 2 signing policy: sign what it sends, accept only what is signed, SETUP_SIGNING.

With a key (``sim-vehicle --signing-key FILE``) the vehicle signs every message it packs on its
one UDP link (link id ``SIGNING_LINK_ID``) and accepts a message only when it is signed with the
key and its timestamp moves forward on its stream (:class:`mavlink_signing.SignatureCheck`);
RADIO_STATUS is the only message accepted unsigned, as in ArduPilot. The server drops everything
else before dispatch and before routing, and counts it by reason (:class:`Verdict`).

SETUP_SIGNING (https://mavlink.io/en/guide/message_signing.html) changes the key only when it
arrives signed with the current key (which the check has already established by the time it is
dispatched); an all-zero key with a zero initial timestamp switches signing off. A vehicle
without a key takes SETUP_SIGNING only when started with ``--accept-signing-setup`` (ArduPilot
takes it unsigned over USB only). As in ArduPilot's SITL without storage, the key is not written
anywhere: a restarted vehicle uses ``--signing-key`` again.
"""

from __future__ import annotations

import logging
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from mavlink_signing import SignatureCheck, Verdict, signature_matches, signing_timestamp_now
from mavlink_signing.keys import KEY_BYTES, key_fingerprint

log = logging.getLogger(__name__)

SIGNING_LINK_ID = 0
"""The link id in every signature the vehicle sends (its one UDP link; ArduPilot's is the channel number)."""
DROP_REASONS = tuple(v for v in Verdict if v is not Verdict.ACCEPTED)
"""Reasons an incoming message is dropped; their ``value`` names the server's counters."""
DISABLE_KEY = bytes(KEY_BYTES)


class VehicleSigning:
    """Signing state of one vehicle link: the outgoing encoder's key and the incoming check.

    Parameters
    ----------
    encoder : pymavlink MAVLink
        The vehicle's encoder (every message it sends is packed by it); signing is set on it.
    key : bytes, optional
        The 32-byte secret key; None starts without signing.
    accept_setup : bool
        Take SETUP_SIGNING while there is no key (``--accept-signing-setup``).
    link_id : int
        Link id of the outgoing signatures.
    """

    def __init__(
        self, encoder: Any, key: bytes | None = None, accept_setup: bool = False, link_id: int = SIGNING_LINK_ID
    ) -> None:
        self.encoder = encoder
        self.accept_setup = bool(accept_setup)
        self.link_id = int(link_id) & 0xFF
        self.check: SignatureCheck | None = None
        if key is not None:
            self._enable(bytes(key), signing_timestamp_now())

    @property
    def enabled(self) -> bool:
        """True while the vehicle signs and checks signatures."""
        return self.check is not None

    @property
    def fingerprint(self) -> str:
        """A short public name of the current key for logs ("off" without one)."""
        return key_fingerprint(self.check.key) if self.check is not None else "off"

    # ------------------------------------------------------------------ incoming
    def verdict(self, msg: Any) -> Verdict:
        """Judge one parsed incoming message: ``Verdict.ACCEPTED`` or the reason to drop it."""
        if self.check is None:
            return Verdict.ACCEPTED
        verdict = self.check.check(msg.get_msgbuf(), msg.get_msgId(), msg.get_srcSystem(), msg.get_srcComponent())
        if verdict is Verdict.ACCEPTED:
            self._follow(self.check.newest)
        return verdict

    def tick(self) -> None:
        """Move both timestamps up to the wall clock (about once a second, as ArduPilot does).

        pymavlink adds one tick per message sent, far slower than the clock; without this a
        client connecting later would find the vehicle's stream more than a minute old.
        """
        if self.check is None:
            return
        now = signing_timestamp_now()
        self.check.advance(now)
        self._follow(now)

    # ------------------------------------------------------------------ SETUP_SIGNING
    def setup(self, msg: Any) -> tuple[bool, str]:
        """Apply a SETUP_SIGNING message (already accepted by :meth:`verdict`); returns (done, what).

        With a key the frame must be signed with it (checked again here, whatever the caller
        did); without one it is taken only if ``accept_setup``.
        """
        refusal = self._setup_refusal(msg)
        if refusal:
            return False, refusal
        key, timestamp = bytes(msg.secret_key), int(msg.initial_timestamp)
        if key == DISABLE_KEY:
            self._disable()
            return True, "signing disabled"
        if self.check is None:
            self._enable(key, max(signing_timestamp_now(), timestamp))
        else:
            self.check.rekey(key, timestamp)
            self._set_encoder_key(key, timestamp)
        return True, f"signing key {self.fingerprint}"

    def _setup_refusal(self, msg: Any) -> str:
        """Why ``msg`` may not change the key ("" if it may)."""
        key = bytes(msg.secret_key)
        if len(key) != KEY_BYTES:
            return f"secret_key has {len(key)} bytes, not {KEY_BYTES}"
        if key == DISABLE_KEY and int(msg.initial_timestamp) != 0:
            return "an all-zero key only disables signing, with initial_timestamp 0"
        if self.check is None:
            return "" if self.accept_setup else "no signing key and no --accept-signing-setup"
        if not (
            msg.get_msgbuf()[2] & mavlink.MAVLINK_IFLAG_SIGNED and signature_matches(self.check.key, msg.get_msgbuf())
        ):
            return "not signed with the current key"
        return ""

    # ------------------------------------------------------------------ state
    def _enable(self, key: bytes, timestamp: int) -> None:
        self.check = SignatureCheck(key)
        self.check.advance(timestamp)
        self._set_encoder_key(key, self.check.newest)

    def _set_encoder_key(self, key: bytes, timestamp: int) -> None:
        signing = self.encoder.signing
        signing.secret_key = bytes(key)
        signing.link_id = self.link_id
        signing.sign_outgoing = True
        self._follow(timestamp)

    def _disable(self) -> None:
        self.check = None
        signing = self.encoder.signing
        signing.secret_key = None
        signing.sign_outgoing = False

    def _follow(self, timestamp: int) -> None:
        """The outgoing timestamp never falls behind ``timestamp`` (the newest one known)."""
        self.encoder.signing.timestamp = max(int(self.encoder.signing.timestamp), int(timestamp))


__all__ = ["VehicleSigning", "SIGNING_LINK_ID", "DROP_REASONS", "Verdict"]
