"""MAVLink 2 message signing shared by ``sim-vehicle`` and the companion (pymavlink underneath).

- ``keys``: the key file (64 hex digits, or a passphrase whose SHA-256 is the key, as MAVProxy's
  ``signing`` commands take it), and a new one (``new_passphrase``, ``write_key_file``);
- ``verify``: the incoming check (signature, then a timestamp that moves forward per stream);
- ``sign``: a pymavlink ``MAVLink`` encoder that signs what it packs.
"""

from mavlink_signing.keys import SigningKeyError, key_from_text, load_key, new_passphrase, write_key_file
from mavlink_signing.sign import signing_encoder, signing_timestamp_now
from mavlink_signing.verify import SignatureCheck, Verdict, frame_timestamp, signature_matches

__all__ = [
    "SigningKeyError",
    "key_from_text",
    "load_key",
    "new_passphrase",
    "write_key_file",
    "signing_encoder",
    "signing_timestamp_now",
    "SignatureCheck",
    "Verdict",
    "frame_timestamp",
    "signature_matches",
]
