"""Flight record: one JSON object per line (JSON Lines), written as the flight goes.

``companion run --record FILE.mcap`` writes the same content as MCAP channels instead
(``companion.view``); this format stays for ``--record FILE.jsonl`` and for old records.

A record survives a crash up to its last flushed line (every half second) and can be read
while it is written. Every line has ``type``; the fields below are the ones ``companion run``
writes (``companion.daemon``, ``companion.threats.reactor``). Times ``t_s`` are mission time
(the vehicle's seconds), positions local NED about home (m).

``header``    ``settings`` (all of them), ``seed``, ``home_lla`` (lat, lon, alt AMSL),
              ``ekf_origin_lla``, ``home_in_origin_ned_m``, ``mission`` (the file, or "from the
              vehicle") and ``waypoints_ned_m``
``world``     the mission's world as ``companion.world.io.world_to_dict``: ``world``
              (``bounds_min``, ``bounds_max``, ``margin_m``) and ``obstacles``
``plan``      one leg: ``leg``, ``seq``, ``path_id``, ``path_ned_m`` (the polyline flown),
              ``reference_ne`` (the smoothed reference, north-east, 5 samples/s), ``tree``
              (GART's ``nodes`` and ``parents``, or None) and the planner's ``summary``
``sample``    ``t_s``, ``ref_pos_ned_m``, ``ref_vel_ned_m_s``, ``pos_ned_m``, ``vel_ned_m_s``
              and ``euler_rad`` (the vehicle's roll, pitch, yaw), ``servo_us``
              (SERVO_OUTPUT_RAW, or None), ``tracking_error_m``, ``leg``, ``path_id``
``decision``  a threat-manager decision: ``kind``, ``reason``, ``label``, ``path_id``,
              ``path_ned_m`` (the new path), ``trigger``, ``latency_ms`` (threat to the first
              setpoint of the new reference), ``decide_ms``, ``plan_ms``, ``candidates``,
              ``min_clearance_m``, ``threat_id``, ``source``, ``time_to_conflict_s``, ``t_s``,
              ``pos_ned_m``, ``leg``; a rejected payload: ``kind`` "rejected", ``reason``,
              ``field``, ``threat_id``, ``source``, ``t_s``
``alternatives`` the M-GART alternatives of a leg, as refreshed: ``leg``, ``t_s``, ``paths``
``threat``    a threat as received: ``id``, ``source``, ``kind``, ``position_ned_m``,
              ``velocity_ned_m_s``, ``radius_m``, ``t_s``; its removal: ``id``, ``source``,
              ``removed``, ``known``, ``t_s``; one restored after a restart: ``restored``,
              ``expires_t_s`` (no ``source``)
``event``     anything else worth a line: ``name`` (e.g. ``planned``, ``reached``,
              ``link_lost`` / ``link_back``, ``zenoh_lost`` / ``zenoh_back``, ``hold``,
              ``landed``; at the end ``setpoint_jitter`` and ``threat_bus``, which have no
              ``t_s``), ``t_s`` and the event's own fields
``summary``   end of flight: ``FlightSummary`` (legs planned and reached, landed, RMS and
              maximum tracking error, decisions, minimum threat separation, latencies, threat
              updates, joined, resumed_at_seq, threats_restored, outcome)
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from companion.errors import CompanionError

log = logging.getLogger(__name__)


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON data: arrays as lists, floats rounded to 6 decimals, non-finite
    numbers as None."""
    kind = type(value)  # the common types first: a sample line is ~40 numbers
    if kind is float:
        return round(value, 6) if math.isfinite(value) else None
    if kind is list or kind is tuple:
        return [jsonable(v) for v in value]
    if kind is int or kind is str or value is None:
        return value
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return round(v, 6) if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
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
        self._fh.write(json.dumps({"type": line_type, **jsonable(fields)}, separators=(",", ":")))
        self._fh.write("\n")
        now = time.monotonic()
        if now - self._flushed_at >= self.flush_period_s:
            self._fh.flush()
            self._flushed_at = now

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> FlightRecorder:
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
    alerts: list[dict] = field(default_factory=list)
    summary: dict | None = None
    samples: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def has_samples(self) -> bool:
        return "t_s" in self.samples and len(self.samples["t_s"]) > 0


SAMPLE_KEYS = ("t_s", "ref_pos_ned_m", "ref_vel_ned_m_s", "pos_ned_m", "vel_ned_m_s", "servo_us", "tracking_error_m")


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
        elif kind == "alert":
            record.alerts.append(item)
    record.samples = samples_from_columns(columns)
    return record


def samples_from_columns(columns: dict[str, list]) -> dict[str, np.ndarray]:
    """Sample columns (key -> one value per sample) as arrays; empty when there is no sample."""
    if not columns.get("t_s"):
        return {}
    arrays = {key: _column(values) for key, values in columns.items()}
    return {key: column for key, column in arrays.items() if column is not None}


def _column(values: list) -> np.ndarray | None:
    """Sample values as one float array; missing values (None) become NaN rows."""
    first = next((v for v in values if v is not None), None)
    if first is None:
        return None
    blank = np.full(np.shape(first), np.nan)
    return np.asarray([blank if v is None else v for v in values], dtype=float)
