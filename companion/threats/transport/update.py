"""``ThreatUpdate``: one threat sample as the bus received it (put, delete or rejected), and the
``rejected`` event the companion publishes for an invalid one."""

from __future__ import annotations

from dataclasses import dataclass

from companion.errors import ThreatPayloadError
from companion.threats.model import LOCAL_SOURCE, Threat, payload_error, threat_uid


@dataclass(frozen=True)
class ThreatUpdate:
    """One threat sample as received.

    Attributes
    ----------
    action : str
        ``"put"``, ``"delete"`` or ``"rejected"`` (invalid payload or key).
    threat_id : str or None
        From the key (None if the key itself is invalid).
    threat : Threat or None
        The decoded threat of a ``put`` (stamped ``received_t_s``), else None.
    error : ThreatPayloadError or None
        Why a ``rejected`` sample was rejected; ``error.field`` names the field.
    key : str
        The zenoh key the sample arrived on.
    received_t_s : float
        Receive time on the bus clock (``clock`` argument of ``ThreatBus``).
    received_mono_s : float
        ``time.monotonic()`` at receipt (for latency measurements).
    seq : int
        Receive order, from 1.
    source : str or None
        Who put it: the key's ``<source>`` segment, ``"local"`` for the plain key, None when
        the key itself is invalid.
    """

    action: str
    threat_id: str | None
    threat: Threat | None
    error: ThreatPayloadError | None
    key: str
    received_t_s: float
    received_mono_s: float
    seq: int
    source: str | None = LOCAL_SOURCE

    @property
    def uid(self) -> str | None:
        """The threat's identity in the table (``Threat.uid``), None for an invalid key."""
        return None if self.threat_id is None else threat_uid(self.source, self.threat_id)


def rejected_event(update: ThreatUpdate) -> dict:
    """The ``rejected`` event the companion publishes for an invalid sample (DESIGN 6)."""
    err = update.error or payload_error("payload", "rejected")
    return {
        "event": "rejected",
        "threat_id": update.uid,
        "source": update.source,
        "key": update.key,
        "field": getattr(err, "field", "payload"),
        "reason": str(err),
        "t_s": update.received_t_s,
    }
