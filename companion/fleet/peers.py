"""The other vehicles: their latest trajectory messages, turned into threats on our clock and in
our frame (DESIGN 6, 7.1).

``PeerTable.receive`` keeps, per system id, the newest message (a lower ``seq`` arriving late is
dropped), the clock offset estimated from the echoes (``clock_sync``) and the delays measured on
its messages. ``PeerTable.threats`` maps each one to our mission clock and local frame:

- time: the publisher's mission time tau was wall-clock ``unix_s + (tau - mission_s) / scale`` on
  its clock, ``offset_s`` ahead of ours; our mission time of that instant follows from ours now;
- space: its samples are NED about its own origin; ours are about our home: the origins differ
  by ``LocalFrame.to_ned`` of its origin (a flat offset: well under 0.1 m within 1 km);
- the tube's radius is its rotor radius plus ``tracking_m`` plus ``margin_m`` (the threat layer
  adds ``threats.inflation_m``), growing with the message's age at ``growth_m_s``; not heard from
  for ``stale_after_s``, at ``stale_growth_m_s``; after ``forget_after_s`` the vehicle is dropped;
- priorities: against a vehicle with a higher system id (it gives way) the tube ends
  ``yield_s`` from now, and its pending trajectory is not ours to avoid; a lower one's pending
  trajectory (in its delay check) is avoided as well as its committed one.

Thread-safe: ``receive`` runs on the zenoh thread, the rest on the loop.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from companion.fleet.clock_sync import ClockOffset
from companion.fleet.message import SampledPath, TrajectoryMessage
from companion.fleet.settings import FleetSettings
from companion.geo import LocalFrame
from companion.threats.decision.prediction import TrajectoryTube, along_samples

__all__ = ["PeerTable", "VehicleThreat", "FLEET_SOURCE"]

#: ``source`` of the threats that stand for other vehicles.
FLEET_SOURCE = "fleet"
#: Delays measured over this long (wall s) count for the delay check.
DELAY_WINDOW_S = 10.0


@dataclass(frozen=True)
class VehicleThreat:
    """Another vehicle along one of its trajectories, in our frame and on our clock.

    Quacks like ``companion.threats.model.Threat`` where the policy needs it (``uid``,
    ``frame``, ``position_at``, ``radius_m``, ``expires_t_s``) and gives its own tube.
    """

    id: str
    sysid: int
    times_s: np.ndarray
    ned_m: np.ndarray
    radius_m: float
    received_t_s: float
    growth_m_s: float
    growth_max_m: float
    expires_t_s: float = math.inf
    kind: str = "vehicle"
    frame: str = "local_ned"
    source: str = FLEET_SOURCE

    @property
    def uid(self) -> str:
        return f"{FLEET_SOURCE}/{self.id}"

    def position_at(self, t_s) -> np.ndarray:
        """Position (3,) or (K, 3) at clock time(s) ``t_s``."""
        pos = along_samples(self.times_s, self.ned_m, t_s)
        return pos[0] if np.ndim(t_s) == 0 else pos

    def tube(self, inflation_m: float) -> TrajectoryTube:
        """Its tube, ``inflation_m`` wider, plus ``bend_m``: the check treats the centre as linear
        between its own times, which may straddle a sample (a corner of the polyline)."""
        return TrajectoryTube(
            self.uid,
            self.times_s,
            self.ned_m,
            self.radius_m + inflation_m + self.bend_m,
            self.radius_m,
            self.received_t_s,
            self.growth_m_s,
            self.growth_max_m,
            self.expires_t_s,
        )

    @property
    def bend_m(self) -> float:
        """Largest distance from the chord of an interval no longer than one sample step (m):
        |change of velocity at a corner| x step / 4."""
        if len(self.times_s) < 3:
            return 0.0
        dt = np.diff(self.times_s)
        vel = np.diff(self.ned_m, axis=0) / dt[:, None]
        return float(np.linalg.norm(np.diff(vel, axis=0), axis=1).max() * dt.max() / 4.0)


@dataclass
class _Peer:
    msg: TrajectoryMessage
    received_unix_s: float
    clock: ClockOffset = field(default_factory=ClockOffset)
    delays: deque = field(default_factory=deque)  # (received_unix_s, delay_s)


class PeerTable:
    """The latest trajectory of every other vehicle (see the module docstring).

    Parameters
    ----------
    sysid : int
        Our system id (our own messages are ignored).
    settings : FleetSettings
    home_lla : tuple of 3 float
        Our local frame's origin.
    """

    def __init__(self, sysid: int, settings: FleetSettings, home_lla) -> None:
        self.sysid = sysid
        self.settings = settings
        self.frame = LocalFrame(*home_lla)
        self._peers: dict[int, _Peer] = {}
        self._lock = threading.Lock()
        self._shifts: dict[tuple, np.ndarray] = {}
        self.counts = {"received": 0, "out_of_order": 0}

    # ------------------------------------------------------------------ in
    def receive(self, msg: TrajectoryMessage, received_unix_s: float) -> None:
        """Take one decoded message that arrived at ``received_unix_s`` (our wall clock)."""
        if msg.sysid == self.sysid:
            return
        with self._lock:
            self.counts["received"] += 1
            peer = self._peers.get(msg.sysid)
            if peer is None:
                peer = self._peers[msg.sysid] = _Peer(msg, received_unix_s)
            elif msg.seq <= peer.msg.seq:
                self.counts["out_of_order"] += 1
                return
            if msg.echo and self.sysid in msg.echo:
                t1, t2 = msg.echo[self.sysid]
                peer.clock.observe(t1, t2, msg.sent_unix_s, received_unix_s)
            peer.msg, peer.received_unix_s = msg, received_unix_s
            peer.delays.append((received_unix_s, received_unix_s - (msg.unix_s - peer.clock.offset_s)))
            while peer.delays and peer.delays[0][0] < received_unix_s - DELAY_WINDOW_S:
                peer.delays.popleft()

    # ------------------------------------------------------------------ out
    def echo(self) -> dict:
        """``{sysid: (its sent_unix_s, our received_unix_s)}`` of the last message of each."""
        with self._lock:
            return {s: (p.msg.sent_unix_s, p.received_unix_s) for s, p in self._peers.items()}

    def max_delay_s(self) -> float:
        """Largest delay (commit to arrival, wall s) measured over the last ``DELAY_WINDOW_S``."""
        with self._lock:
            return max((d for p in self._peers.values() for _, d in p.delays), default=0.0)

    def summary(self, now_unix_s: float) -> list[dict]:
        """Per vehicle: its age, clock offset and bound, largest delay (for the record)."""
        with self._lock:
            return [
                {
                    "sysid": s,
                    "seq": p.msg.seq,
                    "age_s": round(now_unix_s - p.received_unix_s, 3),
                    "offset_s": round(p.clock.offset_s, 6),
                    "offset_bound_s": None if math.isinf(p.clock.bound_s) else round(p.clock.bound_s, 6),
                    "max_delay_s": round(max((d for _, d in p.delays), default=0.0), 4),
                }
                for s, p in sorted(self._peers.items())
            ]

    def threats(self, now_t_s: float, now_unix_s: float, scale: float) -> list[VehicleThreat]:
        """Every vehicle still remembered as threats (committed, and a lower id's pending)."""
        s = self.settings
        with self._lock:
            for sysid in [k for k, p in self._peers.items() if now_unix_s - p.received_unix_s > s.forget_after_s]:
                del self._peers[sysid]
            peers = [(sysid, p.msg, p.received_unix_s, p.clock.offset_s) for sysid, p in self._peers.items()]
        out = []
        for sysid, msg, received, offset in peers:

            def to_ours(tau, msg=msg, offset=offset):
                their_unix = msg.unix_s + (np.asarray(tau) - msg.mission_s) / msg.scale
                return now_t_s + scale * (their_unix - offset - now_unix_s)

            stale = now_unix_s - received > s.stale_after_s
            growth = (s.stale_growth_m_s, s.stale_max_m) if stale else (s.growth_m_s, s.growth_max_m)
            expires = now_t_s + s.yield_s if sysid > self.sysid else math.inf
            shift = self._origin_shift(msg.origin_lla)
            radius = msg.rotor_radius_m + s.tracking_m + s.margin_m
            paths = [("", msg.committed)] + ([("-pending", msg.pending)] if msg.pending and sysid < self.sysid else [])
            for suffix, path in paths:
                out.append(
                    _threat(
                        f"uav{sysid}{suffix}",
                        sysid,
                        path,
                        to_ours,
                        shift,
                        radius,
                        float(to_ours(msg.mission_s)),
                        growth,
                        expires,
                    )
                )
        return out

    def _origin_shift(self, origin_lla) -> np.ndarray:
        """Another origin in our frame (3,), NED metres (cached)."""
        key = tuple(origin_lla)
        if key not in self._shifts:
            self._shifts[key] = self.frame.to_ned_array([key])[0]
        return self._shifts[key]

    def __len__(self) -> int:
        with self._lock:
            return len(self._peers)


def _threat(
    name: str,
    sysid: int,
    path: SampledPath,
    to_ours,
    shift: np.ndarray,
    radius_m: float,
    message_t_s: float,
    growth: tuple,
    expires_t_s: float,
) -> VehicleThreat:
    return VehicleThreat(
        name,
        sysid,
        np.asarray(to_ours(path.times_s), dtype=float),
        np.asarray(path.ned_m, dtype=float) + shift[None, :],
        radius_m,
        message_t_s,
        growth[0],
        growth[1],
        expires_t_s,
    )
