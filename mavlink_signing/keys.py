"""The signing key file: 64 hex digits (the 32-byte secret key) or a passphrase.

A passphrase becomes the key by SHA-256, as MAVProxy's ``signing setup PASSPHRASE`` /
``signing key PASSPHRASE`` do, so MAVProxy and this project agree on the key for the same text.
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
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


def new_passphrase() -> str:
    """A random passphrase for a new key file: 43 URL-safe characters (256 random bits).

    A passphrase rather than 64 hex digits, so that MAVProxy's ``signing setup PASSPHRASE``
    (which hashes what it is given) gives the flight controller the same key as this file.

    Returns
    -------
    str
        The passphrase (never 64 hex digits, so always taken as a passphrase).
    """
    return secrets.token_urlsafe(KEY_BYTES)


def write_key_file(path, text: str) -> Path:
    """Write a key file readable by its owner only (mode 0600, also when it existed).

    Parameters
    ----------
    path : str or Path
        The file.
    text : str
        Its content (a passphrase or 64 hex digits); a newline is added.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    SigningKeyError
        ``text`` is empty, or the file cannot be written (the message names it).
    """
    key_from_text(text)
    path = Path(path)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.fchmod(fd, 0o600)
            os.write(fd, (text.strip() + "\n").encode("utf-8"))
        finally:
            os.close(fd)
    except OSError as exc:
        raise SigningKeyError(f"signing key file {path}: cannot write it ({exc.strerror or exc})") from None
    return path
