"""The zenoh side of threat management (DESIGN section 6): threats in; status, events, path out.

``ThreatBus`` owns one zenoh session (zenoh-python 1.x) in peer mode with multicast scouting
off and explicit endpoints (listen and/or connect; a zenoh router is reached by connecting to
it, in ``peer`` or ``client`` mode). Keys, with prefix ``uav/<sysid>``:

- ``threats/<source>/<id>`` and ``threats/<id>``: subscribed (PUT: a version-1 JSON threat,
  DELETE: remove it). ``<source>`` names who put the threat (``Threat.source``); the plain key
  ``threats/<id>`` is source ``local``. With a zenoh configuration file whose access control is
  enabled (``companion keys init``; ``companion.threats.access``), the ``<source>`` segment is
  authenticated (zenoh lets the certificate with common name ``S`` put only on
  ``threats/S/*``) and the plain key is refused; without one, ``<source>`` is only a label. Every sample
  is decoded and validated *on the zenoh thread* and handed on as a ``ThreatUpdate`` with action
  ``put``, ``delete`` or ``rejected`` (with the ``ThreatPayloadError`` naming the field).
  zenoh-python has no asyncio API: with ``loop`` given the handler runs on that loop through
  ``loop.call_soon_threadsafe``; without, it runs on the zenoh thread; with no handler the
  updates go to an unbounded queue (``get_update`` / ``drain_updates``). Nothing is ever
  dropped: there is no bounded queue, and every sample is counted (``stats``).
- ``threats/**`` queryable (``serve_threats``): answers ``companion threat list`` with the threats
  the companion currently holds, predicted to the time of the query.
- ``status``, ``events``, ``path``: JSON objects published by the companion.

The client side (``put_threat``, ``delete_threat``, ``list_threats``) is what
``companion threat`` uses; it puts on ``threats/<source>/<id>`` when the bus has a ``source``
(given, or the common name of the certificate of its zenoh configuration file). This is an I/O module: nothing numeric happens here.
"""

from __future__ import annotations

import json
import logging
import math
import queue
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from companion.errors import CompanionError, ThreatPayloadError
from companion.threats import codec
from companion.threats.model import LOCAL_SOURCE, Threat, payload_error, threat_uid
from companion.threats.settings import check_endpoint

__all__ = ["ThreatBus", "ThreatUpdate", "ThreatBusError", "session_config", "to_json_bytes"]

log = logging.getLogger(__name__)


class ThreatBusError(CompanionError):
    """The zenoh session cannot be opened or used (bad endpoint, port in use, closed)."""


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


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, (set, tuple)):
        return list(value)
    if hasattr(value, "as_dict"):
        return value.as_dict()
    return str(value)


def _finite(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return _finite(value.tolist())
    if isinstance(value, np.floating):
        return _finite(float(value))
    return value


def to_json_bytes(message: dict) -> bytes:
    """Compact JSON of ``message``; numpy arrays become lists, NaN/inf become null."""
    return json.dumps(_finite(message), separators=(",", ":"), default=_json_default,
                      allow_nan=False).encode("utf-8")


def session_config(*, mode: str = "peer", listen=(), connect=()):
    """A ``zenoh.Config``: ``mode``, multicast scouting off, explicit endpoints.

    Parameters
    ----------
    mode : str
        ``peer``, ``client`` or ``router``.
    listen, connect : sequence of str
        zenoh endpoints such as ``tcp/127.0.0.1:7447``.
    """
    import zenoh

    if mode not in ("peer", "client", "router"):
        raise ThreatBusError(f"mode: expected peer, client or router, got {mode!r}")
    listen = [check_endpoint(ep, f"listen[{i}]") for i, ep in enumerate(listen)]
    connect = [check_endpoint(ep, f"connect[{i}]") for i, ep in enumerate(connect)]
    if not listen and not connect:
        raise ThreatBusError("give at least one listen or connect endpoint")
    if mode == "client" and not connect:
        raise ThreatBusError("connect: client mode needs a router endpoint to connect to")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps(listen))
    cfg.insert_json5("connect/endpoints", json.dumps(connect))
    return cfg


class ThreatBus:
    """One zenoh session for the threats of vehicle ``sysid`` (see the module docstring).

    Parameters
    ----------
    sysid : int
        Key prefix ``uav/<sysid>``.
    listen, connect : sequence of str, optional
        zenoh endpoints (default: listen on ``tcp/127.0.0.1:7447``, connect to none; with
        ``zenoh_config``: the file's, replaced by these when given).
    mode : str
        ``peer`` (default), ``client`` (through a router) or ``router``; with ``zenoh_config``
        the file's mode is used.
    clock : callable, optional
        Time source (s) stamped on received threats, e.g. the daemon's mission clock; default
        ``time.monotonic``. Called on the zenoh thread.
    zenoh_config : str or Path, optional
        A zenoh configuration file (JSON5), e.g. written by ``companion keys init``: TLS,
        access control, endpoints. When its access control is enabled, threats must come on
        ``threats/<source>/<id>``.
    source : str, optional
        Client side: put and delete on ``threats/<source>/<id>``. Default: the common name of
        the certificate of ``zenoh_config`` if any (but not for a configuration with access
        control, i.e. the companion's own), else the plain ``threats/<id>``.

    Examples
    --------
    >>> bus = ThreatBus(1, listen=["tcp/127.0.0.1:7448"]).open()       # doctest: +SKIP
    >>> bus.subscribe(lambda u: print(u.action, u.threat_id), loop=asyncio.get_running_loop())
    >>> bus.publish_event({"event": "replan", "reason": "...", "latency_ms": 12.0})
    >>> bus.close()
    """

    def __init__(self, sysid: int = 1, *, listen=None, connect=None, mode: str = "peer",
                 clock: Callable[[], float] | None = None, zenoh_config=None,
                 source: str | None = None) -> None:
        if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
            raise ThreatBusError(f"sysid: must be an integer in 1..255, got {sysid!r}")
        self.sysid = sysid
        self.prefix = f"uav/{sysid}"
        self.clock = clock or time.monotonic
        self.security = None
        if zenoh_config is not None:
            from companion.threats import access

            self._config, self.security = access.load_config(zenoh_config, listen=listen, connect=connect)
            self.mode = self.security.mode
            self.listen = tuple(json.loads(self._config.get_json("listen/endpoints"))
                                if listen is None else listen)
            self.connect = tuple(json.loads(self._config.get_json("connect/endpoints"))
                                 if connect is None else connect)
        else:
            self.listen = ("tcp/127.0.0.1:7447",) if listen is None else tuple(listen)
            self.connect = () if connect is None else tuple(connect)
            self.mode = mode
            self._config = session_config(mode=mode, listen=self.listen, connect=self.connect)
        #: Threats must come on ``threats/<source>/<id>`` (the configuration's ACL is on).
        self.require_source = bool(self.security is not None and self.security.acl_enabled)
        if source is None and self.security is not None and not self.require_source:
            source = self.security.identity
        if source is not None:
            source = _check_source(source, "source")
        self.source = source
        self._session = None
        self._subscriber = None
        self._queryable = None
        self._publishers: dict = {}
        self._handler = None
        self._loop = None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._seq = 0
        self._counts = {"received": 0, "put": 0, "delete": 0, "rejected": 0, "delivered": 0,
                        "handler_errors": 0, "undeliverable": 0, "queries": 0, "republished": 0}

    @classmethod
    def from_settings(cls, settings, *, clock=None) -> "ThreatBus":
        """Build from ``companion.threats.settings.ZenohSettings`` (not opened yet)."""
        if getattr(settings, "config", None):
            if settings.connect or tuple(settings.listen) != ("tcp/127.0.0.1:7447",):
                log.warning("zenoh.listen/connect ignored: the endpoints of %s are used", settings.config)
            return cls(settings.sysid, clock=clock, zenoh_config=settings.config)
        return cls(settings.sysid, listen=settings.listen, connect=settings.connect,
                   mode=settings.mode, clock=clock)

    # ------------------------------------------------------------------ session
    def open(self) -> "ThreatBus":
        """Open the zenoh session (returns self). Raises ``ThreatBusError`` on failure."""
        import zenoh

        if self._session is not None:
            return self
        try:
            self._session = zenoh.open(self._config)
        except Exception as exc:       # zenoh.ZError: port in use, unreachable router ...
            where = f", config {self.security.path}" if self.security is not None else ""
            raise ThreatBusError(f"zenoh session ({self.mode}, listen {list(self.listen)}, connect "
                                 f"{list(self.connect)}{where}): {exc}") from None
        log.info("zenoh %s session %s: listen %s connect %s, prefix %s%s", self.mode,
                 self._session.zid(), list(self.listen), list(self.connect), self.prefix,
                 "" if self.security is None else
                 f", config {self.security.path} (identity {self.security.identity}, access control "
                 f"{'on: threats from authenticated sources only' if self.require_source else 'off'})")
        return self

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        session, self._session = self._session, None
        if session is None:
            return
        for ent in [self._subscriber, self._queryable, *self._publishers.values()]:
            if ent is not None:
                try:
                    ent.undeclare()
                except Exception as exc:   # already closed by the session: nothing to do
                    log.debug("undeclare: %s", exc)
        self._subscriber = self._queryable = None
        self._publishers.clear()
        session.close()

    def __enter__(self) -> "ThreatBus":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def session(self):
        if self._session is None:
            raise ThreatBusError("the zenoh session is not open (call open())")
        return self._session

    def connected_peers(self) -> int:
        """Number of zenoh peers and routers this session is connected to."""
        info = self.session.info
        return len(list(info.peers_zid())) + len(list(info.routers_zid()))

    def key(self, leaf: str) -> str:
        """``uav/<sysid>/<leaf>``."""
        return f"{self.prefix}/{leaf}"

    # ------------------------------------------------------------------ threats in
    def subscribe(self, handler: Callable[[ThreatUpdate], None] | None = None, *, loop=None) -> None:
        """Subscribe to ``uav/<sysid>/threats/**``.

        Parameters
        ----------
        handler : callable(ThreatUpdate), optional
            Called for every sample (put, delete, rejected). Without a handler the updates go to
            the queue read by ``get_update`` / ``drain_updates``.
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
            return _check_source(chunks[0], "key"), codec.check_id(chunks[1], "key")
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

    def get_update(self, timeout_s: float | None = None) -> ThreatUpdate | None:
        """Next queued update (queue mode), or None after ``timeout_s``."""
        try:
            return self._queue.get(timeout=timeout_s)
        except queue.Empty:
            return None

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

    def serve_threats(self, snapshot: Callable[[], list]) -> None:
        """Answer queries on ``uav/<sysid>/threats/**`` (``companion threat list``).

        Parameters
        ----------
        snapshot : callable() -> iterable of Threat (or of (Threat, now_t_s))
            Called on the zenoh thread; returns the threats held (e.g. ``table.snapshot``).
            Positions are predicted to now (the bus clock, or the ``now_t_s`` given with each
            threat) and the ttl shortened accordingly.
        """
        def on_query(query) -> None:
            self._count("queries")
            try:
                for item in snapshot():
                    threat, now_t_s = item if isinstance(item, tuple) else (item, float(self.clock()))
                    pos = threat.position_at(now_t_s) if threat.frame == "local_ned" else threat.position
                    ttl = None if threat.ttl_s is None else max(threat.expires_t_s - now_t_s, 1e-3)
                    current = Threat(threat.id, threat.kind, threat.frame, tuple(float(x) for x in pos),
                                     threat.velocity_ned_m_s, threat.radius_m, ttl, now_t_s)
                    query.reply(self.key(f"threats/{threat.uid}"), codec.encode(current))
            except Exception:
                log.exception("answering a threat list query failed")

        self._queryable = self.session.declare_queryable(self.key("threats/**"), on_query)

    # ------------------------------------------------------------------ companion out
    def _publisher(self, leaf: str, block: bool):
        import zenoh

        pub = self._publishers.get(leaf)
        if pub is None:
            cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
            pub = self.session.declare_publisher(self.key(leaf), congestion_control=cc)
            self._publishers[leaf] = pub
        return pub

    def publish_status(self, status: dict) -> None:
        """PUT ``status`` (a JSON object) on ``uav/<sysid>/status``."""
        self._publisher("status", block=False).put(to_json_bytes(status))

    def publish_event(self, event: dict) -> None:
        """PUT ``event`` on ``uav/<sysid>/events`` (reliable: never dropped for congestion)."""
        self._publisher("events", block=True).put(to_json_bytes(event))

    def publish_path(self, path: dict) -> None:
        """PUT ``path`` (active path and alternatives) on ``uav/<sysid>/path``."""
        self._publisher("path", block=True).put(to_json_bytes(path))

    def subscribe_json(self, leaf: str, handler: Callable[[str, dict | None], None]):
        """Subscribe to ``uav/<sysid>/<leaf>`` and call ``handler(key, message)`` (zenoh thread).

        For tools and tests that watch ``status``, ``events`` or ``path``; ``message`` is None
        for a payload that is not JSON. Returns the zenoh subscriber (closed with the session).
        """
        def on_sample(sample) -> None:
            try:
                msg = json.loads(sample.payload.to_bytes())
            except ValueError:
                msg = None
            try:
                handler(str(sample.key_expr), msg)
            except Exception:
                log.exception("handler of %s failed", leaf)

        sub = self.session.declare_subscriber(self.key(leaf), on_sample)
        self._publishers[f"sub:{leaf}:{id(sub)}"] = sub
        return sub

    # ------------------------------------------------------------------ client side
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


def rejected_event(update: ThreatUpdate) -> dict:
    """The ``rejected`` event the companion publishes for an invalid sample (DESIGN 6)."""
    err = update.error or payload_error("payload", "rejected")
    return {"event": "rejected", "threat_id": update.uid, "source": update.source, "key": update.key,
            "field": getattr(err, "field", "payload"), "reason": str(err), "t_s": update.received_t_s}


def _check_source(name: str, field: str) -> str:
    """A source name: a valid identity name (``companion.security.keys.check_name``)."""
    from companion.security.keys import KeyMaterialError, check_name

    try:
        return check_name(name, "source")
    except KeyMaterialError as exc:
        raise payload_error(field, str(exc)) from None
