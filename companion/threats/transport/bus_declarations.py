"""What the parts of a ``ThreatBus`` declare on its zenoh session and count: publishers kept by
key (``Publishers``), undeclaring (``undeclare_all``) and the bus's thread-safe counters
(``BusCounters``). I/O helpers only."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable

log = logging.getLogger(__name__)

#: The counters of ``ThreatBus.stats``.
COUNTER_NAMES = (
    "received",
    "put",
    "delete",
    "rejected",
    "delivered",
    "handler_errors",
    "undeliverable",
    "queries",
    "republished",
)


def undeclare_all(entities: Iterable) -> None:
    """Undeclare each zenoh publisher, subscriber or queryable (None skipped); one the session
    already closed is no error."""
    for ent in entities:
        if ent is not None:
            try:
                ent.undeclare()
            except Exception as exc:  # already closed by the session: nothing to do
                log.debug("undeclare: %s", exc)


class BusCounters:
    """Counters of a bus, incremented from the zenoh threads and the loop (a lock)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(COUNTER_NAMES, 0)

    def count(self, name: str) -> None:
        """Add one to counter ``name`` (one of ``COUNTER_NAMES``)."""
        with self._lock:
            self._counts[name] += 1

    def snapshot(self) -> dict:
        """A copy of every counter."""
        with self._lock:
            return dict(self._counts)


class Publishers:
    """zenoh publishers of one part of a bus, declared on first use and kept by key leaf.

    Parameters
    ----------
    session : callable() -> zenoh.Session
        The bus's open session (raises ``ThreatBusError`` when it is not open).
    key : callable(leaf) -> str
        ``uav/<sysid>/<leaf>``.
    """

    def __init__(self, session: Callable[[], object], key: Callable[[str], str]) -> None:
        self._session = session
        self._key = key
        self._by_leaf: dict = {}

    def get(self, leaf: str, block: bool):
        """The publisher of ``uav/<sysid>/<leaf>`` (congestion control BLOCK or DROP)."""
        import zenoh

        pub = self._by_leaf.get(leaf)
        if pub is None:
            cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
            pub = self._session().declare_publisher(self._key(leaf), congestion_control=cc)
            self._by_leaf[leaf] = pub
        return pub

    def close(self) -> None:
        """Undeclare them all (the next ``get`` declares again)."""
        undeclare_all(self._by_leaf.values())
        self._by_leaf.clear()
