"""The companion's side of the bus (``ThreatBus.outbound``): JSON objects out (``status``,
``events``, ``path``), the ``threats/**`` queryable that answers ``companion threat list``, and
the threats this process learnt otherwise (ADS-B) put for the other processes."""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable

import numpy as np

from companion.errors import ThreatBusError
from companion.threats.model import Threat
from companion.threats.transport import codec
from companion.threats.transport.bus_declarations import BusCounters, Publishers, undeclare_all

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
    return json.dumps(_finite(message), separators=(",", ":"), default=_json_default, allow_nan=False).encode("utf-8")


class CompanionOutbound:
    """What the companion publishes on a bus (``ThreatBus.outbound``).

    Parameters
    ----------
    session : callable() -> zenoh.Session
        The bus's open session (raises ``ThreatBusError`` when it is not open).
    key : callable(leaf) -> str
        ``uav/<sysid>/<leaf>``.
    clock : callable() -> float
        The bus clock (s): threats listed are predicted to its now.
    counters : BusCounters
        Queries answered and threats republished are counted there.
    """

    def __init__(
        self,
        session: Callable[[], object],
        key: Callable[[str], str],
        clock: Callable[[], float],
        counters: BusCounters,
    ) -> None:
        self._session = session
        self._key = key
        self._clock = clock
        self._counters = counters
        self._publishers = Publishers(session, key)
        self._queryable = None

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
            self._counters.count("queries")
            try:
                for item in snapshot():
                    threat, now_t_s = item if isinstance(item, tuple) else (item, float(self._clock()))
                    pos = threat.position_at(now_t_s) if threat.frame == "local_ned" else threat.position
                    ttl = None if threat.ttl_s is None else max(threat.expires_t_s - now_t_s, 1e-3)
                    current = Threat(
                        threat.id,
                        threat.kind,
                        threat.frame,
                        tuple(float(x) for x in pos),
                        threat.velocity_ned_m_s,
                        threat.radius_m,
                        ttl,
                        now_t_s,
                    )
                    query.reply(self._key(f"threats/{threat.uid}"), codec.encode(current))
            except Exception:
                log.exception("answering a threat list query failed")

        self._queryable = self._session().declare_queryable(self._key("threats/**"), on_query)

    def stop_serving(self) -> None:
        """Undeclare the threat list queryable (``serve_threats`` may be called again)."""
        undeclare_all([self._queryable])
        self._queryable = None

    def close(self) -> None:
        """Undeclare the queryable and the publishers (the session is closing)."""
        self.stop_serving()
        self._publishers.close()

    def publish_status(self, status: dict) -> None:
        """PUT ``status`` (a JSON object) on ``uav/<sysid>/status``."""
        self._publishers.get("status", block=False).put(to_json_bytes(status))

    def publish_event(self, event: dict) -> None:
        """PUT ``event`` on ``uav/<sysid>/events`` (reliable: never dropped for congestion)."""
        self._publishers.get("events", block=True).put(to_json_bytes(event))

    def publish_path(self, path: dict) -> None:
        """PUT ``path`` (active path and alternatives) on ``uav/<sysid>/path``."""
        self._publishers.get("path", block=True).put(to_json_bytes(path))

    def republish_threat(self, threat: Threat) -> bool:
        """PUT ``threat`` on ``uav/<sysid>/threats/<id>`` for *other* processes only (a threat
        this process learnt otherwise, e.g. from ADS-B): zenoh's ``allowed_destination`` REMOTE
        keeps it from the local subscriber, and it is dropped rather than wait under congestion
        (the next report replaces it). Returns False when the session is not open."""
        import zenoh

        try:
            session = self._session()
        except ThreatBusError:
            return False
        session.put(
            self._key(f"threats/{threat.id}"),
            codec.encode(threat),
            allowed_destination=zenoh.Locality.REMOTE,
            congestion_control=zenoh.CongestionControl.DROP,
        )
        self._counters.count("republished")
        return True
