"""The client side of the bus (``ThreatBus.client``, what ``companion threat`` uses): put and
delete threats on ``threats/[<source>/]<id>``, list the threats the companion(s) hold. It has
its own publishers; nothing of the companion's side is needed."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace

from companion.errors import ThreatPayloadError
from companion.threats.model import LOCAL_SOURCE, Threat, payload_error, threat_uid
from companion.threats.transport import codec
from companion.threats.transport.bus_declarations import Publishers

log = logging.getLogger(__name__)


class ThreatClient:
    """The client side of a bus (``ThreatBus.client``).

    Parameters
    ----------
    session : callable() -> zenoh.Session
        The bus's open session (raises ``ThreatBusError`` when it is not open).
    key : callable(leaf) -> str
        ``uav/<sysid>/<leaf>``.
    source : str or None
        Put and delete on ``threats/<source>/<id>`` (None: the plain ``threats/<id>``); checked
        by the bus.
    """

    def __init__(self, session: Callable[[], object], key: Callable[[str], str], source: str | None) -> None:
        self._session = session
        self._key = key
        self.source = source
        self._publishers = Publishers(session, key)

    def threat_leaf(self, threat_id: str) -> str:
        """``threats/<source>/<id>`` with this bus's ``source``, else ``threats/<id>``."""
        codec.check_id(threat_id)
        return f"threats/{threat_uid(self.source, threat_id)}"

    def wait_for_subscriber(self, timeout_s: float, threat_id: str = "probe") -> bool:
        """Wait until a subscriber of this bus's key of ``threat_id`` is known (True) or timeout."""
        pub = self._publishers.get(self.threat_leaf(threat_id), block=True)
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
        self._publishers.get(self.threat_leaf(threat.id), block=True).put(payload)

    def put_raw(self, leaf: str, payload: bytes) -> None:
        """PUT an arbitrary payload on ``uav/<sysid>/threats/<leaf>`` (tests, fault injection)."""
        self._session().put(self._key(f"threats/{leaf}"), payload)

    def delete_threat(self, threat_id: str) -> None:
        """DELETE ``uav/<sysid>/threats/[<source>/]<threat_id>``."""
        self._publishers.get(self.threat_leaf(threat_id), block=True).delete()

    def close(self) -> None:
        """Undeclare the publishers (the session is closing)."""
        self._publishers.close()

    def list_threats(self, timeout_s: float = 2.0) -> list[Threat]:
        """Ask the companion(s) for the threats they hold (``serve_threats``), sorted by uid
        (``<source>/<id>``; ``source`` set from the reply's key).

        Invalid replies are logged and skipped.
        """
        out: dict[str, Threat] = {}
        replies = self._session().get(self._key("threats/**"), timeout=timeout_s)
        for reply in replies:
            sample = reply.ok
            if sample is None:
                continue
            try:
                threat = codec.decode(sample.payload.to_bytes(), received_t_s=time.monotonic())
                head, _, last = str(sample.key_expr).rpartition("/")
                source = head.rpartition("/")[2] if head != self._key("threats") else LOCAL_SOURCE
                if last != threat.id:
                    raise payload_error("id", f"{threat.id!r} does not match the key's last chunk {last!r}")
                threat = replace(threat, source=source)
            except ThreatPayloadError as exc:
                log.warning("invalid threat in a list reply on %s: %s", sample.key_expr, exc)
                continue
            out[threat.uid] = threat
        return [out[k] for k in sorted(out)]
