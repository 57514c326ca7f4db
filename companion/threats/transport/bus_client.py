"""The client side of the bus (``companion threat``): put and delete threats on
``threats/[<source>/]<id>``, list the threats the companion(s) hold."""

from __future__ import annotations

import logging
import time
from dataclasses import replace

from companion.errors import ThreatPayloadError
from companion.threats.transport import codec
from companion.threats.model import LOCAL_SOURCE, Threat, payload_error, threat_uid

log = logging.getLogger(__name__)


class ThreatClient:
    """The client side of a ``ThreatBus`` (a part of it: it uses the bus's ``session``, ``key``,
    ``_publisher`` and ``source``)."""

    source: str | None
    _session: object

    def threat_leaf(self, threat_id: str) -> str:
        """``threats/<source>/<id>`` with this bus's ``source``, else ``threats/<id>``."""
        codec.check_id(threat_id)
        return f"threats/{threat_uid(self.source, threat_id)}"

    def wait_for_subscriber(self, timeout_s: float, threat_id: str = "probe") -> bool:
        """Wait until a subscriber of this bus's key of ``threat_id`` is known (True) or timeout."""
        pub = self._publisher(self.threat_leaf(threat_id), block=True)
        deadline = time.monotonic() + timeout_s
        while True:
            if pub.matching_status.matching:
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)

    def put_threat(self, threat: Threat) -> None:
        """PUT ``threat`` (encoded, validated) on ``uav/<sysid>/threats/[<source>/]<id>``."""
        payload = codec.encode(threat)
        self._publisher(self.threat_leaf(threat.id), block=True).put(payload)

    def republish_threat(self, threat: Threat) -> bool:
        """PUT ``threat`` on ``uav/<sysid>/threats/<id>`` for *other* processes only (a threat
        this process learnt otherwise, e.g. from ADS-B): zenoh's ``allowed_destination`` REMOTE
        keeps it from the local subscriber, and it is dropped rather than wait under congestion
        (the next report replaces it). Returns False when the session is not open."""
        import zenoh

        if self._session is None:
            return False
        self._session.put(self.key(f"threats/{threat.id}"), codec.encode(threat),
                          allowed_destination=zenoh.Locality.REMOTE,
                          congestion_control=zenoh.CongestionControl.DROP)
        self._count("republished")
        return True

    def put_raw(self, leaf: str, payload: bytes) -> None:
        """PUT an arbitrary payload on ``uav/<sysid>/threats/<leaf>`` (tests, fault injection)."""
        self.session.put(self.key(f"threats/{leaf}"), payload)

    def delete_threat(self, threat_id: str) -> None:
        """DELETE ``uav/<sysid>/threats/[<source>/]<threat_id>``."""
        self._publisher(self.threat_leaf(threat_id), block=True).delete()

    def list_threats(self, timeout_s: float = 2.0) -> list[Threat]:
        """Ask the companion(s) for the threats they hold (``serve_threats``), sorted by uid
        (``<source>/<id>``; ``source`` set from the reply's key).

        Invalid replies are logged and skipped.
        """
        out: dict[str, Threat] = {}
        replies = self.session.get(self.key("threats/**"), timeout=timeout_s)
        for reply in replies:
            sample = reply.ok
            if sample is None:
                continue
            try:
                threat = codec.decode(sample.payload.to_bytes(), received_t_s=time.monotonic())
                head, _, last = str(sample.key_expr).rpartition("/")
                source = head.rpartition("/")[2] if head != self.key("threats") else LOCAL_SOURCE
                if last != threat.id:
                    raise payload_error("id", f"{threat.id!r} does not match the key's last chunk {last!r}")
                threat = replace(threat, source=source)
            except ThreatPayloadError as exc:
                log.warning("invalid threat in a list reply on %s: %s", sample.key_expr, exc)
                continue
            out[threat.uid] = threat
        return [out[k] for k in sorted(out)]
