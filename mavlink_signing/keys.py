"""The signing key file: 64 hex digits (the 32-byte secret key) or a passphrase.

A passphrase becomes the key by SHA-256, as MAVProxy's ``signing setup PASSPHRASE`` /
``signing key PASSPHRASE`` do, so MAVProxy and this project agree on the key for the same text.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

KEY_BYTES = 32
_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}")


class SigningKeyError(ValueError):
    """The key file is missing, unreadable or empty (the message names the file)."""


def key_from_text(text: str) -> bytes:
    """The 32-byte secret key: ``text`` itself if it is 64 hex digits, else SHA-256 of it.

    Surrounding white space (a trailing newline) is not part of the key or passphrase.
    """
    text = text.strip()
    if not text:
        raise SigningKeyError("the signing key is empty")
    if _HEX_KEY.fullmatch(text):
        return bytes.fromhex(text)
    return hashlib.sha256(text.encode("utf-8")).digest()


def load_key(path) -> bytes:
    """Read the key file ``path`` (see ``key_from_text``); errors name the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SigningKeyError(f"signing key file {path}: cannot read it ({exc})") from None
    try:
        return key_from_text(text)
    except SigningKeyError:
        raise SigningKeyError(f"signing key file {path}: it is empty") from None


def key_fingerprint(key: bytes) -> str:
    """A short public name for a key in logs (first 4 bytes of its SHA-256), never the key."""
    return hashlib.sha256(key).hexdigest()[:8]
