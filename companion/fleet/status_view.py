"""``companion fleet status``: one row per vehicle from the companions' zenoh status and events.

Pure functions (no zenoh here; ``companion.commands.fleet`` listens and calls them):

- ``FleetView``: what was heard, by system id: each vehicle's latest ``uav/<sysid>/status``
  (DESIGN 6: ``t_s, sysid, home_lla, mode, armed, leg, legs, path_id, pos_ned_m`` about its own
  home, ...) and its ``uav/<sysid>/events`` (decisions);
- ``positions_lla`` / ``nearest_separation``: each status's position is about that vehicle's
  home; through its ``home_lla`` all go to one frame (the lowest system id's home) and each
  vehicle gets the distance to the nearest other one;
- ``vehicle_rows`` and ``format_table`` / ``rows_json``: the table.

The decisions are those heard while listening, or, with the fleet's directory at hand, every
decision of each flight record (``record_decisions``): the zenoh events are not kept anywhere.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "FleetView",
    "VehicleRow",
    "sysid_of_key",
    "record_decisions",
    "positions_lla",
    "nearest_separation",
    "vehicle_rows",
    "format_table",
    "rows_json",
]

#: Events on ``uav/<sysid>/events`` that are not decisions (``companion serve``'s commands).
NOT_DECISIONS = frozenset({"command"})
_KEY = re.compile(r"^uav/(\d+)/([A-Za-z_]+)$")


def sysid_of_key(key: str) -> int | None:
    """``uav/<sysid>/<leaf>`` -> sysid (None for any other key)."""
    m = _KEY.match(str(key))
    return int(m.group(1)) if m else None


def event_kind(event: dict) -> str | None:
    """A decision event's kind (``event``, or ``kind``), None for anything else."""
    if not isinstance(event, dict):
        return None
    kind = event.get("event", event.get("kind"))
    if not isinstance(kind, str) or kind in NOT_DECISIONS:
        return None
    return kind


@dataclass
class FleetView:
    """The latest status and the decisions of each vehicle heard (thread-safe ``on_*``)."""

    status: dict = field(default_factory=dict)  # sysid -> latest status message
    decisions: dict = field(default_factory=dict)  # sysid -> [decision events]
    samples: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def on_status(self, key: str, msg) -> None:
        sysid = sysid_of_key(key)
        if sysid is None or not isinstance(msg, dict):
            return
        with self._lock:
            self.samples += 1
            old = self.status.get(sysid)
            if old is None or _t(msg) >= _t(old):
                self.status[sysid] = msg

    def on_event(self, key: str, msg) -> None:
        sysid = sysid_of_key(key)
        if sysid is None or event_kind(msg) is None:
            return
        with self._lock:
            self.samples += 1
            self.decisions.setdefault(sysid, []).append(msg)

    def snapshot(self) -> tuple[dict, dict]:
        with self._lock:
            return dict(self.status), {k: list(v) for k, v in self.decisions.items()}


def record_decisions(path) -> list[dict]:
    """The decisions of a JSON Lines flight record (``companion run --record X.jsonl``): its
    ``decision`` lines, in order (empty when the file is missing or not JSON Lines)."""
    import json
    from pathlib import Path

    out = []
    try:
        with open(Path(path), encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if '"decision"' not in line:
                    continue
                try:
                    msg = json.loads(line)
                except ValueError:
                    continue
                if isinstance(msg, dict) and msg.get("type") == "decision" and event_kind(msg) is not None:
                    out.append(msg)
    except OSError:
        return []
    return out


def _t(msg: dict) -> float:
    t = msg.get("t_s")
    return float(t) if isinstance(t, (int, float)) and math.isfinite(t) else -math.inf


def _vector(value, size: int = 3) -> np.ndarray | None:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        return None
    if arr.shape != (size,) or not np.all(np.isfinite(arr)):
        return None
    return arr


def positions_lla(statuses: dict) -> dict:
    """Each status's position as (lat deg, lon deg, alt m AMSL), by sysid: its ``pos_ned_m``
    about its own ``home_lla``. Vehicles without both are left out."""
    from heli_common.frames import GeoError, LocalFrame

    out = {}
    for sysid, msg in statuses.items():
        if not isinstance(msg, dict):
            continue
        home, pos = _vector(msg.get("home_lla")), _vector(msg.get("pos_ned_m"))
        if home is None or pos is None:
            continue
        try:
            lat, lon, alt = LocalFrame(*home).to_lla(*pos)
        except GeoError:
            continue
        out[sysid] = (float(lat), float(lon), float(alt))
    return out


def positions_common(statuses: dict) -> tuple[dict, tuple | None]:
    """Positions (NED m) of every vehicle in one frame, the home of the lowest system id;
    returns ``(sysid -> ndarray (3,), that home)``."""
    from heli_common.frames import LocalFrame

    lla = positions_lla(statuses)
    if not lla:
        return {}, None
    ref = min(lla)
    home = tuple(float(v) for v in _vector(statuses[ref]["home_lla"]))
    frame = LocalFrame(*home)
    return {s: frame.to_ned_array(np.array([p]))[0] for s, p in lla.items()}, home


def nearest_separation(positions: dict) -> dict:
    """For each vehicle (sysid -> position (3,) in one frame), the distance (m, 3D) to the
    nearest other vehicle and which it is: ``sysid -> (distance, other sysid)``; a vehicle alone
    gets ``(inf, None)``."""
    ids = sorted(positions)
    out = {}
    for a in ids:
        best, who = math.inf, None
        for b in ids:
            if b == a:
                continue
            d = float(np.linalg.norm(np.asarray(positions[a], float) - np.asarray(positions[b], float)))
            if d < best:
                best, who = d, b
        out[a] = (best, who)
    return out


@dataclass(frozen=True)
class VehicleRow:
    """One row of the fleet table."""

    sysid: int
    mode: str | None
    armed: bool | None
    leg: int | None
    legs: int | None
    outcome: str | None
    pos_ned_m: tuple | None  # in the common frame (the lowest sysid's home)
    nearest_m: float
    nearest_sysid: int | None
    decisions: int
    last_decision: str | None
    t_s: float | None

    def as_dict(self) -> dict:
        return {
            "sysid": self.sysid,
            "mode": self.mode,
            "armed": self.armed,
            "leg": self.leg,
            "legs": self.legs,
            "outcome": self.outcome,
            "pos_ned_m": None if self.pos_ned_m is None else list(self.pos_ned_m),
            "nearest_m": None if not math.isfinite(self.nearest_m) else self.nearest_m,
            "nearest_sysid": self.nearest_sysid,
            "decisions": self.decisions,
            "last_decision": self.last_decision,
            "t_s": self.t_s,
        }


def describe_decision(event: dict) -> str:
    """``"replan (threat t1): reason"``, short."""
    kind = event_kind(event) or "?"
    label = event.get("label")
    text = kind if not label or label == kind else f"{kind}/{label}"
    if event.get("threat_id"):
        text += f" ({event['threat_id']})"
    reason = event.get("reason")
    if reason:
        text += f": {reason}"
    return text


def vehicle_rows(statuses: dict, decisions: dict | None = None) -> list[VehicleRow]:
    """The table's rows, by system id, from the latest status and the decisions of each vehicle
    heard (a vehicle heard only by its events has an empty status)."""
    decisions = decisions or {}
    positions, _ = positions_common(statuses)
    nearest = nearest_separation(positions)
    rows = []
    for sysid in sorted(set(statuses) | set(decisions)):
        st = statuses.get(sysid) or {}
        evs = decisions.get(sysid) or []
        pos = positions.get(sysid)
        dist, other = nearest.get(sysid, (math.inf, None))
        leg = st.get("leg")
        rows.append(
            VehicleRow(
                sysid=sysid,
                mode=st.get("mode"),
                armed=st.get("armed"),
                leg=leg if isinstance(leg, int) else None,
                legs=st.get("legs") if isinstance(st.get("legs"), int) else None,
                outcome=st.get("outcome"),
                pos_ned_m=None if pos is None else tuple(round(float(v), 1) for v in pos),
                nearest_m=dist,
                nearest_sysid=other,
                decisions=len(evs),
                last_decision=describe_decision(evs[-1]) if evs else None,
                t_s=st.get("t_s") if isinstance(st.get("t_s"), (int, float)) else None,
            )
        )
    return rows


def _cell(value, fmt: str = "{}") -> str:
    return "-" if value is None else fmt.format(value)


def format_table(rows, *, width: int = 60) -> str:
    """The rows as a fixed-width text table (``last decision`` cut to ``width`` characters);
    "no vehicle heard" when empty."""
    rows = list(rows)
    if not rows:
        return "no vehicle heard"
    head = ["sysid", "mode", "leg", "outcome", "position N,E,D (m)", "nearest (m)", "decisions", "last decision"]
    body = []
    for r in rows:
        leg = "-" if r.leg is None else f"{r.leg}/{_cell(r.legs)}"  # the companion's leg index
        pos = "-" if r.pos_ned_m is None else ",".join(f"{v:.1f}" for v in r.pos_ned_m)
        near = "-" if not math.isfinite(r.nearest_m) else f"{r.nearest_m:.1f} (#{r.nearest_sysid})"
        last = r.last_decision or "-"
        if len(last) > width:
            last = last[: width - 3] + "..."
        body.append([str(r.sysid), _cell(r.mode), leg, _cell(r.outcome), pos, near, str(r.decisions), last])
    widths = [max(len(line[k]) for line in [head] + body) for k in range(len(head))]
    fmt = lambda line: "  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip()  # noqa: E731
    return "\n".join([fmt(head), fmt(["-" * w for w in widths])] + [fmt(line) for line in body])


def rows_json(rows) -> list[dict]:
    """The rows as plain data (``--json``)."""
    return [r.as_dict() for r in rows]
