"""The zenoh side of threat management (DESIGN section 6): threats in; status, events, path out.

``ThreatBus`` owns one zenoh session (zenoh-python 1.x) in peer mode with multicast scouting
off and explicit endpoints (listen and/or connect; a zenoh router is reached by connecting to
it, in ``peer`` or ``client`` mode). Keys, with prefix ``uav/<sysid>``:

- ``threats/<source>/<id>`` and ``threats/<id>``: subscribed (PUT: a version-1 JSON threat,
  DELETE: remove it). ``<source>`` names who put the threat (``Threat.source``); the plain key
  ``threats/<id>`` is source ``local``. With a zenoh configuration file whose access control is
  enabled (``companion keys init``; ``companion.threats.transport.access``), the ``<source>`` segment is
  authenticated (zenoh lets the certificate with common name ``S`` put only on
  ``threats/S/*``) and the plain key is refused; without one, ``<source>`` is only a label. Every sample
  is decoded and validated *on the zenoh thread* and handed on as a ``ThreatUpdate`` with action
  ``put``, ``delete`` or ``rejected`` (with the ``ThreatPayloadError`` naming the field).
  zenoh-python has no asyncio API: with ``loop`` given the handler runs on that loop through
  ``loop.call_soon_threadsafe``; without, it runs on the zenoh thread; with no handler the
  updates go to an unbounded queue (``inbound.drain_updates``). Nothing is ever
  dropped: there is no bounded queue, and every sample is counted (``stats``).
- ``threats/**`` queryable (``outbound.serve_threats``): answers ``companion threat list`` with
  the threats the companion currently holds, predicted to the time of the query.
- ``status``, ``events``, ``path``: JSON objects published by the companion (``outbound``).

The client side (``client.put_threat``, ``delete_threat``, ``list_threats``) is what
``companion threat`` uses; it puts on ``threats/<source>/<id>`` when the bus has a ``source``
(given, or the common name of the certificate of its zenoh configuration file).

``ThreatBus`` (this module) owns the zenoh session and its lifecycle (``open``, ``unsubscribe``,
``close``), the bus clock and counters, and holds one part per job as a member, each given the
session, the key space and what else it uses: ``inbound`` (``bus_inbound.ThreatInbound``:
threats in), ``outbound`` (``bus_outbound.CompanionOutbound``: what the companion publishes,
and the threat list it serves) and ``client`` (``bus_client.ThreatClient``: ``companion
threat``); ``bus_declarations`` has the publishers and counters they share the pattern of.
These are I/O modules: nothing numeric happens here.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable

from companion.errors import ThreatBusError
from companion.threats.settings import check_endpoint, default_listen
from companion.threats.transport.bus_client import ThreatClient
from companion.threats.transport.bus_declarations import BusCounters, undeclare_all
from companion.threats.transport.bus_inbound import ThreatInbound, check_source
from companion.threats.transport.bus_outbound import CompanionOutbound
from companion.threats.transport.update import ThreatUpdate

__all__ = ["ThreatBus", "ThreatUpdate", "ThreatBusError", "session_config"]

log = logging.getLogger(__name__)


#: zenoh ``connect/retry``: how a lost connection is retried (ms; README "Faults").
CONNECT_RETRY = {"period_init_ms": 500, "period_max_ms": 2000, "period_increase_factor": 2}


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
    # a lost router or peer is retried every 0.5 s at first, then every 2 s at most; the
    # subscriptions and queryables are redeclared on reconnection (zenoh 1.x)
    cfg.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    return cfg


class ThreatBus:
    """One zenoh session for the threats of vehicle ``sysid`` (see the module docstring).

    Parameters
    ----------
    sysid : int
        Key prefix ``uav/<sysid>``.
    listen, connect : sequence of str, optional
        zenoh endpoints (default: listen on ``default_listen(sysid)``, loopback port 7447 + sysid,
        connect to none; with
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

    Attributes
    ----------
    inbound : ThreatInbound
        Threats in (``subscribe``, ``parse_key``, ``drain_updates``).
    outbound : CompanionOutbound
        The companion's publications (``publish_status``, ``publish_event``, ``publish_path``,
        ``serve_threats``, ``republish_threat``).
    client : ThreatClient
        ``companion threat``'s side (``put_threat``, ``delete_threat``, ``list_threats``,
        ``wait_for_subscriber``, ``source``).
    clock : callable() -> float
        The bus clock (may be replaced, e.g. by the reactor's mission clock).

    Examples
    --------
    >>> bus = ThreatBus(1, listen=["tcp/127.0.0.1:7448"]).open()       # doctest: +SKIP
    >>> bus.inbound.subscribe(lambda u: print(u.action, u.threat_id), loop=asyncio.get_running_loop())
    >>> bus.outbound.publish_event({"event": "replan", "reason": "...", "latency_ms": 12.0})
    >>> bus.close()
    """

    def __init__(
        self,
        sysid: int = 1,
        *,
        listen=None,
        connect=None,
        mode: str = "peer",
        clock: Callable[[], float] | None = None,
        zenoh_config=None,
        source: str | None = None,
    ) -> None:
        if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
            raise ThreatBusError(f"sysid: must be an integer in 1..255, got {sysid!r}")
        self.sysid = sysid
        self.prefix = f"uav/{sysid}"
        self.clock = clock or time.monotonic
        self.security = None
        if zenoh_config is not None:
            from companion.threats.transport import access

            self._config, self.security = access.load_config(zenoh_config, listen=listen, connect=connect)
            self.mode = self.security.mode
            self.listen = tuple(json.loads(self._config.get_json("listen/endpoints")) if listen is None else listen)
            self.connect = tuple(json.loads(self._config.get_json("connect/endpoints")) if connect is None else connect)
        else:
            self.listen = default_listen(sysid) if listen is None else tuple(listen)
            self.connect = () if connect is None else tuple(connect)
            self.mode = mode
            self._config = session_config(mode=mode, listen=self.listen, connect=self.connect)
        #: Threats must come on ``threats/<source>/<id>`` (the configuration's ACL is on).
        self.require_source = bool(self.security is not None and self.security.acl_enabled)
        if source is None and self.security is not None and not self.require_source:
            source = self.security.identity
        if source is not None:
            source = check_source(source, "source")
        self._session = None
        self._json_subscribers: list = []
        self._counters = BusCounters()
        session, clock = (lambda: self.session), (lambda: self.clock())
        self.inbound = ThreatInbound(session, self.key, clock, self.require_source, self._counters)
        self.outbound = CompanionOutbound(session, self.key, clock, self._counters)
        self.client = ThreatClient(session, self.key, source)

    @classmethod
    def from_settings(cls, settings, *, clock=None) -> ThreatBus:
        """Build from ``companion.threats.settings.ZenohSettings`` (not opened yet)."""
        if getattr(settings, "config", None):
            if settings.connect or settings.listen is not None:
                log.warning("zenoh.listen/connect ignored: the endpoints of %s are used", settings.config)
            return cls(settings.prefix_sysid, clock=clock, zenoh_config=settings.config)
        return cls(
            settings.prefix_sysid,
            listen=settings.listen_endpoints,
            connect=settings.connect,
            mode=settings.mode,
            clock=clock,
        )

    # ------------------------------------------------------------------ session
    def open(self) -> ThreatBus:
        """Open the zenoh session (returns self). Raises ``ThreatBusError`` on failure."""
        import zenoh

        if self._session is not None:
            return self
        try:
            self._session = zenoh.open(self._config)
        except Exception as exc:  # zenoh.ZError: port in use, unreachable router ...
            where = f", config {self.security.path}" if self.security is not None else ""
            raise ThreatBusError(
                f"zenoh session ({self.mode}, listen {list(self.listen)}, connect {list(self.connect)}{where}): {exc}"
            ) from None
        log.info(
            "zenoh %s session %s: listen %s connect %s, prefix %s%s",
            self.mode,
            self._session.zid(),
            list(self.listen),
            list(self.connect),
            self.prefix,
            ""
            if self.security is None
            else f", config {self.security.path} (identity {self.security.identity}, access control "
            f"{'on: threats from authenticated sources only' if self.require_source else 'off'})",
        )
        return self

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        if self._session is None:
            return
        self.unsubscribe()
        self.outbound.close()
        self.client.close()
        undeclare_all(self._json_subscribers)
        self._json_subscribers.clear()
        session, self._session = self._session, None
        session.close()

    def unsubscribe(self) -> None:
        """Undeclare the threat subscription and the threat list (``inbound.subscribe``,
        ``outbound.serve_threats``); the session stays open for the next flight's."""
        self.inbound.unsubscribe()
        self.outbound.stop_serving()

    def __enter__(self) -> ThreatBus:
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

    def stats(self) -> dict:
        """Counters: received, put, delete, rejected, delivered, handler_errors, undeliverable,
        queries, republished."""
        return self._counters.snapshot()

    def subscribe_json(self, leaf: str, handler: Callable[[str, dict | None], None]):
        """Subscribe to ``uav/<sysid>/<leaf>`` and call ``handler(key, message)`` (zenoh thread).

        For the tools and tests that watch ``status``, ``events`` or ``path``, and the service's
        ``command``; ``message`` is None for a payload that is not JSON. Returns the zenoh
        subscriber (undeclared by ``close``).
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
        self._json_subscribers.append(sub)
        return sub
