"""Threats and the threat table: PUT / DELETE / expiry and constant-velocity prediction.

DESIGN section 6 (the zenoh contract) and 7 (threats move at constant velocity until told
otherwise); paper section 3.3 (pop-up and moving threats, Fig. 8).

A ``Threat`` is an immutable record of one threat as received: its position refers to the time
``received_t_s`` (seconds on the clock of the process that keeps the table, e.g. the mission
clock of the daemon). ``ThreatTable`` keeps the threats currently known, in the local NED frame;
a ``global`` threat is converted with the home position when it is put.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, replace

import numpy as np

from companion.errors import ThreatPayloadError

__all__ = ["Threat", "ThreatTable", "KINDS", "TRAFFIC", "FRAMES", "LOCAL_SOURCE", "payload_error", "threat_uid"]

KINDS = ("popup", "moving")
#: What a threat is, for its volumes (``companion.threats.alerts``): drone scale, or manned traffic.
TRAFFIC = ("drone", "manned")
#: Source of a threat put on the plain key ``uav/<sysid>/threats/<id>`` (unauthenticated).
LOCAL_SOURCE = "local"
FRAMES = ("local_ned", "global")


def payload_error(field: str, message: str) -> ThreatPayloadError:
    """A ``ThreatPayloadError`` whose message starts with, and whose ``field`` attribute is, ``field``."""
    exc = ThreatPayloadError(f"{field}: {message}")
    exc.field = field
    return exc


def threat_uid(source: str | None, threat_id: str) -> str:
    """``threat_id`` for the local source, else ``<source>/<threat_id>`` (``Threat.uid``)."""
    return threat_id if source in (None, LOCAL_SOURCE) else f"{source}/{threat_id}"


@dataclass(frozen=True)
class Threat:
    """One pop-up or moving threat (a sphere moving at constant velocity).

    Parameters
    ----------
    id : str
        Threat id, also the last chunk of its zenoh key ``uav/<sysid>/threats/<id>``.
    kind : str
        ``"popup"`` (static) or ``"moving"``.
    frame : str
        ``"local_ned"``: ``position`` is (north, east, down) in metres about home;
        ``"global"``: ``position`` is (lat_deg, lon_deg, alt_m) (WGS-84, altitude AMSL).
    position : tuple of 3 float
        See ``frame``; at time ``received_t_s``.
    velocity_ned_m_s : tuple of 3 float
        Constant velocity, NED (m/s).
    radius_m : float
        Radius of the threat sphere (m), > 0 (not inflated).
    ttl_s : float or None
        Lifetime after ``received_t_s`` (s); None: until deleted.
    received_t_s : float
        Time the position refers to (the receiver's clock, s).
    source : str
        Who put the threat: the ``<source>`` segment of an authenticated key
        ``uav/<sysid>/threats/<source>/<id>``, or ``"local"`` (the plain key
        ``uav/<sysid>/threats/<id>``, or learnt by the companion itself, e.g. ADS-B).
    traffic : str
        ``"drone"`` (drone-scale volumes about the sphere, the default) or ``"manned"`` (manned
        traffic, ADS-B: the aviation volumes, 2000 ft / 250 ft well clear).
    """

    id: str
    kind: str
    frame: str
    position: tuple
    velocity_ned_m_s: tuple = (0.0, 0.0, 0.0)
    radius_m: float = 1.0
    ttl_s: float | None = None
    received_t_s: float = 0.0
    source: str = LOCAL_SOURCE
    traffic: str = "drone"

    @property
    def uid(self) -> str:
        """Identity in the table: ``id`` for a local threat, ``<source>/<id>`` otherwise (two
        sources may use the same id; neither can replace or delete the other's threat)."""
        return threat_uid(self.source, self.id)

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position (3,) NED metres at ``received_t_s`` (local-frame threats only)."""
        if self.frame != "local_ned":
            raise payload_error(
                "frame",
                "a global threat has no local position until converted "
                "with the home position (ThreatTable(home=...) or to_local)",
            )
        return np.asarray(self.position, dtype=float)

    @property
    def expires_t_s(self) -> float:
        """Time at which the threat expires (inf without ttl)."""
        return math.inf if self.ttl_s is None else self.received_t_s + self.ttl_s

    def position_at(self, t_s) -> np.ndarray:
        """Predicted position at time(s) ``t_s`` (constant velocity).

        Parameters
        ----------
        t_s : float or array_like, shape (K,)

        Returns
        -------
        ndarray, shape (3,) or (K, 3)
            NED metres.
        """
        t = np.asarray(t_s, dtype=float)
        p0 = self.pos_ned_m
        v = np.asarray(self.velocity_ned_m_s, dtype=float)
        if t.ndim == 0:
            return p0 + v * (float(t) - self.received_t_s)
        return p0[None, :] + (t.reshape(-1, 1) - self.received_t_s) * v[None, :]

    def to_local(self, home) -> Threat:
        """This threat in the local NED frame.

        Parameters
        ----------
        home : companion.geo.LocalFrame
            The home position (the origin of the local frame).
        """
        if self.frame == "local_ned":
            return self
        lat, lon, alt = self.position
        north, east, down = home.to_ned(lat, lon, alt)
        return replace(self, frame="local_ned", position=(float(north), float(east), float(down)))

    def with_time(self, received_t_s: float) -> Threat:
        """The same threat stamped with another receive time."""
        return replace(self, received_t_s=float(received_t_s))


class ThreatTable:
    """The threats currently known, by ``Threat.uid``, in the local NED frame (thread-safe).

    PUT inserts or replaces, DELETE removes, and a threat whose ttl has run out is removed by
    ``expire``. Counters of every operation are kept (``stats``).

    Parameters
    ----------
    home : companion.geo.LocalFrame, optional
        Converts ``global`` threats to local NED. Without it a global threat is rejected.
    """

    def __init__(self, home=None) -> None:
        self._home = home
        self._lock = threading.Lock()
        self._threats: dict[str, Threat] = {}
        self._version = 0
        self._counts = {"put": 0, "replaced": 0, "deleted": 0, "delete_unknown": 0, "expired": 0}

    @property
    def home(self):
        return self._home

    def set_home(self, home) -> None:
        """Set the home position used to convert global threats."""
        self._home = home

    # ------------------------------------------------------------------ mutations
    def put(self, threat: Threat) -> bool:
        """Insert or replace ``threat``; returns True when it replaced one with the same id.

        Raises
        ------
        ThreatPayloadError
            ``frame`` for a global threat without a home position.
        """
        if threat.frame == "global":
            if self._home is None:
                raise payload_error("frame", "global threat received before the home position is known")
            threat = threat.to_local(self._home)
        with self._lock:
            replaced = threat.uid in self._threats
            self._threats[threat.uid] = threat
            self._version += 1
            self._counts["put"] += 1
            self._counts["replaced"] += int(replaced)
        return replaced

    def delete(self, threat_id: str) -> bool:
        """Remove the threat ``threat_id`` (its ``uid``); returns False if it was not known."""
        with self._lock:
            known = self._threats.pop(threat_id, None) is not None
            if known:
                self._version += 1
                self._counts["deleted"] += 1
            else:
                self._counts["delete_unknown"] += 1
        return known

    def expire(self, now_t_s: float) -> list[str]:
        """Remove the threats whose ttl has run out at ``now_t_s``; returns their ids."""
        with self._lock:
            gone = [tid for tid, t in self._threats.items() if t.expires_t_s <= now_t_s]
            for tid in gone:
                del self._threats[tid]
            if gone:
                self._version += 1
                self._counts["expired"] += len(gone)
        return gone

    def clear(self) -> None:
        """Remove every threat."""
        with self._lock:
            if self._threats:
                self._version += 1
            self._threats.clear()

    # ------------------------------------------------------------------ queries
    def snapshot(self, now_t_s: float | None = None) -> tuple[Threat, ...]:
        """The threats known (not yet expired at ``now_t_s`` if given), sorted by uid."""
        with self._lock:
            items = sorted(self._threats.values(), key=lambda t: t.uid)
        if now_t_s is None:
            return tuple(items)
        return tuple(t for t in items if t.expires_t_s > now_t_s)

    def get(self, threat_id: str) -> Threat | None:
        with self._lock:
            return self._threats.get(threat_id)

    def position_at(self, threat_id: str, t_s) -> np.ndarray:
        """Predicted position (3,) or (K, 3) of threat ``threat_id`` at ``t_s``.

        Raises
        ------
        KeyError
            If the threat is not in the table.
        """
        threat = self.get(threat_id)
        if threat is None:
            raise KeyError(threat_id)
        return threat.position_at(t_s)

    @property
    def version(self) -> int:
        """Incremented on every change (put, delete of a known id, expiry)."""
        return self._version

    def stats(self) -> dict:
        """Counters: put, replaced, deleted, delete_unknown, expired; and ``active``."""
        with self._lock:
            out = dict(self._counts)
            out["active"] = len(self._threats)
        return out

    def __len__(self) -> int:
        with self._lock:
            return len(self._threats)

    def __contains__(self, threat_id: object) -> bool:
        with self._lock:
            return threat_id in self._threats
