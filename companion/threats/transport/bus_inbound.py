"""Threats in: the bus's subscription to ``uav/<sysid>/threats/**``.

Every sample is decoded and validated *on the zenoh thread* (``companion.threats.transport.codec``) and
handed on as a ``ThreatUpdate`` with action ``put``, ``delete`` or ``rejected``: to a handler on
an asyncio loop (``call_soon_threadsafe``), to a handler on the zenoh thread, or to an unbounded
queue (``drain_updates``). Nothing is ever dropped, and every sample is counted (``stats``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import replace
from typing import Callable

from companion.errors import ThreatBusError, ThreatPayloadError
from companion.threats.transport import codec
from companion.threats.model import LOCAL_SOURCE, payload_error
from companion.threats.transport.update import ThreatUpdate

log = logging.getLogger(__name__)


class ThreatInbound:
    """The threat subscription of a ``ThreatBus`` (a part of it: it uses the bus's ``session``,
    ``key``, ``clock`` and ``require_source``)."""

    prefix: str
    require_source: bool
    clock: Callable[[], float]
    _subscriber: object
    _handler: Callable[[ThreatUpdate], None] | None
    _loop: object
    _queue: queue.SimpleQueue
    _lock: threading.Lock
    _seq: int
    _counts: dict

    def subscribe(self, handler: Callable[[ThreatUpdate], None] | None = None, *, loop=None) -> None:
        """Subscribe to ``uav/<sysid>/threats/**``.

        Parameters
        ----------
        handler : callable(ThreatUpdate), optional
            Called for every sample (put, delete, rejected). Without a handler the updates go to
            the queue read by ``drain_updates``.
        loop : asyncio event loop, optional
            Run ``handler`` on this loop (``call_soon_threadsafe``); otherwise on the zenoh
            thread (keep it short and thread-safe).
        """
        if self._subscriber is not None:
            raise ThreatBusError("already subscribed")
        self._handler = handler
        self._loop = loop
        self._subscriber = self.session.declare_subscriber(self.key("threats/**"), self._on_sample)

    def _on_sample(self, sample) -> None:
        """zenoh thread: decode, count, hand on. Never raises (zenoh would log and go on)."""
        try:
            update = self._decode_sample(sample)
            self._deliver(update)
        except Exception:          # a bug here must not kill the zenoh callback thread
            log.exception("threat sample handling failed")
            with self._lock:
                self._counts["handler_errors"] += 1

    def _decode_sample(self, sample) -> ThreatUpdate:
        import zenoh

        mono = time.monotonic()
        t_s = float(self.clock())
        key = str(sample.key_expr)
        with self._lock:
            self._seq += 1
            seq = self._seq
            self._counts["received"] += 1
        threat_id, source, threat, error = None, None, None, None
        try:
            source, threat_id = self.parse_key(key)
            if sample.kind == zenoh.SampleKind.DELETE:
                action = "delete"
            else:
                action = "put"
                threat = codec.decode(sample.payload.to_bytes(), received_t_s=t_s, key_id=threat_id)
                if source != LOCAL_SOURCE:
                    threat = replace(threat, source=source)
        except ThreatPayloadError as exc:
            action, error, threat = "rejected", exc, None
        with self._lock:
            self._counts[action] += 1
        return ThreatUpdate(action, threat_id, threat, error, key, t_s, mono, seq, source)

    def parse_key(self, key: str) -> tuple[str, str]:
        """``(source, threat_id)`` of a threat key.

        ``uav/<sysid>/threats/<source>/<id>`` or, unless ``require_source``,
        ``uav/<sysid>/threats/<id>`` (source ``"local"``).

        Raises
        ------
        ThreatPayloadError
            With ``field`` ``"key"``.
        """
        head = self.key("threats/")
        leaf = key[len(head):] if key.startswith(head) else ""
        chunks = leaf.split("/")
        if len(chunks) == 2:
            return check_source(chunks[0], "key"), codec.check_id(chunks[1], "key")
        if len(chunks) == 1 and self.require_source:
            raise payload_error("key", f"{key!r}: this companion takes threats from authenticated sources "
                                f"only, on {self.prefix}/threats/<source>/<id> (its zenoh access control is on)")
        if len(chunks) > 2:
            raise payload_error("key", f"{key!r}: expected {self.prefix}/threats/<id> or "
                                f"{self.prefix}/threats/<source>/<id>")
        return LOCAL_SOURCE, codec.check_id(leaf, "key")

    def _deliver(self, update: ThreatUpdate) -> None:
        handler = self._handler
        if handler is None:
            self._queue.put(update)
            self._count("delivered")
            return
        if self._loop is not None:
            try:
                self._loop.call_soon_threadsafe(self._run_handler, handler, update)
            except RuntimeError:       # the loop is closed: the service is shutting down
                self._count("undeliverable")
            return
        self._run_handler(handler, update)

    def _run_handler(self, handler, update: ThreatUpdate) -> None:
        try:
            handler(update)
            self._count("delivered")
        except Exception:
            log.exception("threat update handler failed on %s", update.key)
            self._count("handler_errors")

    def _count(self, name: str) -> None:
        with self._lock:
            self._counts[name] += 1

    def drain_updates(self) -> list[ThreatUpdate]:
        """All queued updates (queue mode), oldest first, without waiting."""
        out = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out

    def stats(self) -> dict:
        """Counters: received, put, delete, rejected, delivered, handler_errors, undeliverable, queries."""
        with self._lock:
            return dict(self._counts)


def check_source(name: str, field: str) -> str:
    """A source name: a valid identity name (``companion.security.keys.check_name``)."""
    from companion.security.keys import KeyMaterialError, check_name

    try:
        return check_name(name, "source")
    except KeyMaterialError as exc:
        raise payload_error(field, str(exc)) from None
