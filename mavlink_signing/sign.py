"""Signing what is sent: a pymavlink encoder whose ``pack`` appends the MAVLink 2 signature."""

from __future__ import annotations

import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink

#: The signing clock's epoch (1 January 2015 UTC) in Unix seconds; its unit is 10 us.
SIGNING_EPOCH_UNIX_S = 1420070400


def signing_timestamp_now() -> int:
    """The current signing timestamp: 10 us ticks since 1 January 2015 UTC."""
    return int((max(time.time(), SIGNING_EPOCH_UNIX_S) - SIGNING_EPOCH_UNIX_S) * 100_000)


def signing_encoder(key: bytes, link_id: int, src_system: int, src_component: int) -> mavlink.MAVLink:
    """A ``MAVLink`` object that signs every message it packs with ``key`` on ``link_id``.

    Its timestamp starts at the wall clock and pymavlink moves it forward by one per message,
    so a restarted sender is never mistaken for a replay as long as the clock is right.
    """
    mav = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=src_component)
    mav.signing.secret_key = bytes(key)
    mav.signing.link_id = int(link_id) & 0xFF
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = signing_timestamp_now()
    return mav
