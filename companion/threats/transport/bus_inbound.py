"""Threats in (``ThreatBus.inbound``): the subscription to ``uav/<sysid>/threats/**``.

Every sample is decoded and validated *on the zenoh thread* (``companion.threats.transport.codec``) and
handed on as a ``ThreatUpdate`` with action ``put``, ``delete`` or ``rejected``: to a handler on
an asyncio loop (``call_soon_threadsafe``), to a handler on the zenoh thread, or to an unbounded
queue (``drain_updates``). Nothing is ever dropped, and every sample is counted (the bus's
``BusCounters``, ``ThreatBus.stats``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import replace

from companion.errors import ThreatBusError, ThreatPayloadError
from companion.threats.model import LOCAL_SOURCE, payload_error
from companion.threats.transport import codec
from companion.threats.transport.bus_declarations import BusCounters, undeclare_all
from companion.threats.transport.update import ThreatUpdate

log = logging.getLogger(__name__)


class ThreatInbound:
    """The threat subscription of a bus (``ThreatBus.inbound``).

    Parameters
    ----------
    session : callable() -> zenoh.Session
        The bus's open session (raises ``ThreatBusError`` when it is not open).
    key : callable(leaf) -> str
        ``uav/<sysid>/<leaf>``.
    clock : callable() -> float
        Time source (s) stamped on received threats (called on the zenoh thread).
    require_source : bool
        Threats must come on ``threats/<source>/<id>`` (the bus's access control is on).
    counters : BusCounters
        Every sample is counted there.
    """

    def __init__(
        self,
        session: Callable[[], object],
        key: Callable[[str], str],
        clock: Callable[[], float],
        require_source: bool,
        counters: BusCounters,
    ) -> None:
        self._session = session
        self._key = key
        self._clock = clock
        self._require_source = bool(require_source)
        self._counters = counters
        self._subscriber = None
        self._handler: Callable[[ThreatUpdate], None] | None = None
        self._loop = None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._seq_lock = threading.Lock()
        self._seq = 0

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
        self._subscriber = self._session().declare_subscriber(self._key("threats/**"), self.on_sample)

    def unsubscribe(self) -> None:
        """Undeclare the subscription and forget its handler (``subscribe`` may be called again)."""
        undeclare_all([self._subscriber])
        self._subscriber = None
        self._handler = self._loop = None

    def on_sample(self, sample) -> None:
        """The subscription's callback (zenoh thread): decode, count, hand on. Never raises
        (zenoh would log and go on)."""
        try:
            update = self._decode_sample(sample)
            self._deliver(update)
        except Exception:  # a bug here must not kill the zenoh callback thread
            log.exception("threat sample handling failed")
            self._counters.count("handler_errors")

    def _decode_sample(self, sample) -> ThreatUpdate:
        import zenoh

        mono = time.monotonic()
        t_s = float(self._clock())
        key = str(sample.key_expr)
        with self._seq_lock:
            self._seq += 1
            seq = self._seq
        self._counters.count("received")
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
        self._counters.count(action)
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
        head = self._key("threats/")
        leaf = key[len(head) :] if key.startswith(head) else ""
        chunks = leaf.split("/")
        if len(chunks) == 2:
            return check_source(chunks[0], "key"), codec.check_id(chunks[1], "key")
        if len(chunks) == 1 and self._require_source:
            raise payload_error(
                "key",
                f"{key!r}: this companion takes threats from authenticated sources "
                f"only, on {self._key('threats/<source>/<id>')} (its zenoh access control is on)",
            )
        if len(chunks) > 2:
            raise payload_error(
                "key", f"{key!r}: expected {self._key('threats/<id>')} or {self._key('threats/<source>/<id>')}"
            )
        return LOCAL_SOURCE, codec.check_id(leaf, "key")

    def _deliver(self, update: ThreatUpdate) -> None:
        handler = self._handler
        if handler is None:
            self._queue.put(update)
            self._counters.count("delivered")
            return
        if self._loop is not None:
            try:
                self._loop.call_soon_threadsafe(self._run_handler, handler, update)
            except RuntimeError:  # the loop is closed: the service is shutting down
                self._counters.count("undeliverable")
            return
        self._run_handler(handler, update)

    def _run_handler(self, handler, update: ThreatUpdate) -> None:
        try:
            handler(update)
            self._counters.count("delivered")
        except Exception:
            log.exception("threat update handler failed on %s", update.key)
            self._counters.count("handler_errors")

    def drain_updates(self) -> list[ThreatUpdate]:
        """All queued updates (queue mode), oldest first, without waiting."""
        out = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out


def check_source(name: str, field: str) -> str:
    """A source name: a valid identity name (``companion.security.keys.check_name``)."""
    from companion.security.keys import KeyMaterialError, check_name

    try:
        return check_name(name, "source")
    except KeyMaterialError as exc:
        raise payload_error(field, str(exc)) from None
