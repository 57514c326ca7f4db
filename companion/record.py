"""Flight record: one JSON object per line (JSON Lines), written as the flight goes.

A record survives a crash up to its last flushed line (every half second) and can be read
while it is written. Line types:

``header``    settings, seed, home (lat, lon, alt), command line
``world``     obstacles (as ``World.to_dict()``), bounds, margin
``plan``      one leg: planner polyline, smoothed samples, tree (nodes, parents), alternatives
``sample``    time, reference pos/vel (NED), actual pos/vel (NED), attitude, actuator inputs
``decision``  a threat-manager decision: kind, reason, latency, path id, new path
``alternatives`` the M-GART alternatives of a leg, as refreshed
``threat``    a threat as received (id, kind, position, velocity, radius) or its removal
``event``     anything else worth a line (mode change, leg reached, link lost / back)
``summary``   end of flight: tracking error statistics, legs reached, minimum separation
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, IO

import numpy as np

from companion.errors import CompanionError

log = logging.getLogger(__name__)


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return round(v, 6) if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


class FlightRecorder:
    """Append-only JSON Lines writer.

    Lines are buffered and flushed at most every ``flush_period_s`` (and on ``close``), so a
    threat storm does not cost one system call per update; a crash loses at most that period.
    """

    def __init__(self, path: str | Path, flush_period_s: float = 0.5):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh: IO[str] | None = open(self.path, "w", encoding="utf-8")
        self.flush_period_s = flush_period_s
        self._flushed_at = time.monotonic()

    def write(self, line_type: str, /, **fields: Any) -> None:
        if self._fh is None:
            return
        self._fh.write(json.dumps({"type": line_type, **_jsonable(fields)}, separators=(",", ":")))
        self._fh.write("\n")
        now = time.monotonic()
        if now - self._flushed_at >= self.flush_period_s:
            self._fh.flush()
            self._flushed_at = now

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> "FlightRecorder":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class FlightRecord:
    """A record read back: lines grouped by type, samples as arrays."""

    header: dict = field(default_factory=dict)
    world: dict | None = None
    plans: list[dict] = field(default_factory=list)
    decisions: list[dict] = field(default_factory=list)
    alternatives: list[dict] = field(default_factory=list)
    threats: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    summary: dict | None = None
    samples: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def has_samples(self) -> bool:
        return "t_s" in self.samples and len(self.samples["t_s"]) > 0


SAMPLE_KEYS = ("t_s", "ref_pos_ned_m", "ref_vel_ned_m_s", "pos_ned_m", "vel_ned_m_s",
               "servo_us", "tracking_error_m")


def load_record(path: str | Path) -> FlightRecord:
    """Read a flight record; a broken line is an error naming its line number.

    A truncated last line (the flight was killed while writing) is skipped with a warning.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such flight record") from None
    record = FlightRecord()
    columns: dict[str, list] = {k: [] for k in SAMPLE_KEYS}
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
        except json.JSONDecodeError as exc:
            if number == len(lines):
                log.warning("%s: line %d is truncated, skipped", path, number)
                continue
            raise CompanionError(f"{path}:{number}: not a record line ({exc.msg})") from None
        kind = item.pop("type", None)
        if kind == "sample":
            for key in SAMPLE_KEYS:
                columns[key].append(item.get(key))
        elif kind == "header":
            record.header = item
        elif kind == "world":
            record.world = item
        elif kind == "plan":
            record.plans.append(item)
        elif kind == "decision":
            record.decisions.append(item)
        elif kind == "alternatives":
            record.alternatives.append(item)
        elif kind == "threat":
            record.threats.append(item)
        elif kind == "summary":
            record.summary = item
        elif kind == "event":
            record.events.append(item)
    if columns["t_s"]:
        for key, values in columns.items():
            column = _column(values)
            if column is not None:
                record.samples[key] = column
    return record


def _column(values: list) -> np.ndarray | None:
    """Sample values as one float array; missing values (None) become NaN rows."""
    first = next((v for v in values if v is not None), None)
    if first is None:
        return None
    blank = np.full(np.shape(first), np.nan)
    return np.asarray([blank if v is None else v for v in values], dtype=float)
