"""The companion's side of the bus: JSON objects out (``status``, ``events``, ``path``), the
``threats/**`` queryable that answers ``companion threat list``, and JSON subscriptions for the
tools and tests that watch what the companion publishes."""

from __future__ import annotations

import json
import logging
import math
from typing import Callable

import numpy as np

from companion.threats.transport import codec
from companion.threats.model import Threat

log = logging.getLogger(__name__)


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


class CompanionOutbound:
    """What the companion publishes on a ``ThreatBus`` (a part of it: it uses the bus's
    ``session``, ``key``, ``clock`` and counters)."""

    _publishers: dict
    _queryable: object

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
