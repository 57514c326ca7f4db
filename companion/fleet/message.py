"""The trajectory message of ``uav/<sysid>/trajectory``: JSON, version 1 (DESIGN 6).

A companion publishes what it flies (``committed``) and, during a delay check, what it is about
to fly (``pending``), each as positions sampled every ``dt_s`` from ``t0_s`` on its own mission
clock, in metres NED about ``origin_lla``. The clock basis says which wall-clock instant
(``unix_s``) its mission time ``mission_s`` was, and how fast that clock runs (``scale``:
vehicle seconds per wall-clock second). ``echo`` returns, for each other vehicle heard from,
the send time of its last message and when it arrived, so that both can estimate their clock
offset (``companion.fleet.clock_sync``)::

    {"v": 1, "sysid": 2, "seq": 41, "rotor_radius_m": 1.6, "origin_lla": [47.3977, 8.5456, 488.0],
     "clock": {"mission_s": 812.4, "unix_s": 1764583200.25, "scale": 1.0},
     "sent_unix_s": 1764583200.40,
     "committed": {"path_id": "leg2", "t0_s": 812.4, "dt_s": 0.5, "ned_m": [[0.0, 1.0, -15.0], ...]},
     "pending": null, "echo": {"1": [1764583200.11, 1764583200.12]}}

Pure: JSON and numbers only. ``decode`` raises ``ThreatPayloadError`` naming the field at fault.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from companion.threats.model import payload_error
from companion.threats.transport.codec import finite_number, parse_json

__all__ = ["TrajectoryMessage", "SampledPath", "encode", "decode", "VERSION", "MAX_PAYLOAD_BYTES"]

VERSION = 1
MAX_PAYLOAD_BYTES = 65536
MAX_SAMPLES = 600
FIELDS = ("v", "sysid", "seq", "rotor_radius_m", "origin_lla", "clock", "sent_unix_s", "committed", "pending", "echo")


@dataclass(frozen=True)
class SampledPath:
    """Positions sampled at a fixed step.

    Attributes
    ----------
    path_id : str
    t0_s : float
        Mission time (publisher's clock) of the first sample.
    dt_s : float
        Step between samples (s), > 0.
    ned_m : ndarray, shape (K, 3)
        Metres NED about the publisher's ``origin_lla``; K >= 1 (one sample: a hover).
    """

    path_id: str
    t0_s: float
    dt_s: float
    ned_m: np.ndarray

    @property
    def times_s(self) -> np.ndarray:
        """Sample times (K,) on the publisher's mission clock."""
        return self.t0_s + self.dt_s * np.arange(len(self.ned_m))


@dataclass(frozen=True)
class TrajectoryMessage:
    """One decoded trajectory message (see the module docstring)."""

    sysid: int
    seq: int
    rotor_radius_m: float
    origin_lla: tuple
    mission_s: float
    unix_s: float
    scale: float
    sent_unix_s: float
    committed: SampledPath
    pending: SampledPath | None = None
    echo: dict | None = None


def _path_dict(path: SampledPath | None):
    if path is None:
        return None
    return {
        "path_id": path.path_id,
        "t0_s": round(float(path.t0_s), 4),
        "dt_s": float(path.dt_s),
        "ned_m": np.round(np.asarray(path.ned_m, dtype=float), 2).tolist(),
    }


def encode(msg: TrajectoryMessage) -> bytes:
    """The message as compact JSON bytes."""
    return json.dumps(
        {
            "v": VERSION,
            "sysid": msg.sysid,
            "seq": msg.seq,
            "rotor_radius_m": msg.rotor_radius_m,
            "origin_lla": list(msg.origin_lla),
            "clock": {"mission_s": round(msg.mission_s, 4), "unix_s": msg.unix_s, "scale": msg.scale},
            "sent_unix_s": msg.sent_unix_s,
            "committed": _path_dict(msg.committed),
            "pending": _path_dict(msg.pending),
            "echo": {str(k): [float(a), float(b)] for k, (a, b) in (msg.echo or {}).items()},
        },
        separators=(",", ":"),
    ).encode()


def _number(value, field: str, *, lo: float = -math.inf, hi: float = math.inf) -> float:
    value = finite_number(value, field)
    if not lo <= value <= hi:
        raise payload_error(field, f"must be in [{lo:g}, {hi:g}], got {value!r}")
    return value


def _integer(value, field: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise payload_error(field, f"expected an integer in {lo}..{hi}, got {value!r}"[:120])
    return value


def _object(value, field: str, keys: tuple) -> dict:
    if not isinstance(value, dict):
        raise payload_error(field or "payload", f"expected an object, got {type(value).__name__}")
    unknown = sorted(set(value) - set(keys))
    if unknown:
        raise payload_error(f"{field}.{unknown[0]}" if field else unknown[0], "unknown field")
    missing = [k for k in keys if k not in value]
    if missing:
        raise payload_error(f"{field}.{missing[0]}" if field else missing[0], "missing")
    return value


def _path(value, field: str) -> SampledPath | None:
    if value is None:
        return None
    d = _object(value, field, ("path_id", "t0_s", "dt_s", "ned_m"))
    if not isinstance(d["path_id"], str) or len(d["path_id"]) > 64:
        raise payload_error(f"{field}.path_id", "expected a string of at most 64 characters")
    ned = d["ned_m"]
    if not isinstance(ned, list) or not 1 <= len(ned) <= MAX_SAMPLES:
        raise payload_error(f"{field}.ned_m", f"expected a list of 1..{MAX_SAMPLES} [n, e, d] points")
    rows = []
    for i, p in enumerate(ned):
        if not isinstance(p, list) or len(p) != 3:
            raise payload_error(f"{field}.ned_m[{i}]", "expected [north, east, down] in metres")
        rows.append([_number(v, f"{field}.ned_m[{i}]", lo=-1e6, hi=1e6) for v in p])
    return SampledPath(
        d["path_id"],
        _number(d["t0_s"], f"{field}.t0_s"),
        _number(d["dt_s"], f"{field}.dt_s", lo=1e-3, hi=60.0),
        np.asarray(rows),
    )


def decode(payload: bytes) -> TrajectoryMessage:
    """Parse and validate one message (``ThreatPayloadError`` naming the field at fault)."""
    d = _object(parse_json(payload, MAX_PAYLOAD_BYTES), "", FIELDS)
    if d["v"] != VERSION:
        raise payload_error("v", f"expected {VERSION}, got {d['v']!r}")
    lla = d["origin_lla"]
    if not isinstance(lla, list) or len(lla) != 3:
        raise payload_error("origin_lla", "expected [lat_deg, lon_deg, alt_m]")
    origin = (
        _number(lla[0], "origin_lla[0]", lo=-90, hi=90),
        _number(lla[1], "origin_lla[1]", lo=-180, hi=180),
        _number(lla[2], "origin_lla[2]", lo=-1e4, hi=1e5),
    )
    clock = _object(d["clock"], "clock", ("mission_s", "unix_s", "scale"))
    echo = d["echo"]
    if not isinstance(echo, dict):
        raise payload_error("echo", "expected an object {sysid: [sent_unix_s, received_unix_s]}")
    echoes = {}
    for key, pair in echo.items():
        if not key.isdigit() or not isinstance(pair, list) or len(pair) != 2:
            raise payload_error(f"echo.{key}", "expected a sysid and [sent_unix_s, received_unix_s]")
        echoes[int(key)] = (_number(pair[0], f"echo.{key}[0]"), _number(pair[1], f"echo.{key}[1]"))
    committed = _path(d["committed"], "committed")
    if committed is None:
        raise payload_error("committed", "missing: every message carries the trajectory flown")
    return TrajectoryMessage(
        sysid=_integer(d["sysid"], "sysid", 1, 255),
        seq=_integer(d["seq"], "seq", 0, 2**53),
        rotor_radius_m=_number(d["rotor_radius_m"], "rotor_radius_m", lo=0.01, hi=50.0),
        origin_lla=origin,
        mission_s=_number(clock["mission_s"], "clock.mission_s"),
        unix_s=_number(clock["unix_s"], "clock.unix_s"),
        scale=_number(clock["scale"], "clock.scale", lo=1e-3, hi=1e3),
        sent_unix_s=_number(d["sent_unix_s"], "sent_unix_s"),
        committed=committed,
        pending=_path(d["pending"], "pending"),
        echo=echoes,
    )
