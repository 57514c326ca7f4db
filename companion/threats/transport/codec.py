"""The threat payload of ``uav/<sysid>/threats/<id>``: JSON, version 1 (DESIGN section 6).

Example (local frame)::

    {"v": 1, "id": "t1", "kind": "popup", "frame": "local_ned",
     "position": [40.0, 42.0, -20.0], "velocity_ned_m_s": [0.0, 0.0, 0.0],
     "radius_m": 6.0, "ttl_s": 120}

Global frame: ``"frame": "global", "position": {"lat": 47.39, "lon": 8.54, "alt_m": 520.0}``
(degrees, WGS-84, altitude AMSL in metres).

Fields: ``v`` (must be 1), ``id`` (1-64 characters of ``A-Z a-z 0-9 _ - .``, a valid zenoh
key chunk), ``kind`` (``popup``: static, its velocity must be zero; ``moving``), ``frame``,
``position``, ``radius_m`` (0 < r <= 10 000) are required; ``velocity_ned_m_s`` (default
zero, each component at most 300 m/s) and ``ttl_s`` (0 < ttl <= 1e6, or null or absent: until
deleted) and ``traffic`` (``drone``, the default, or ``manned``: manned traffic, judged
with the aviation volumes; ADS-B reports of manned aircraft are republished with it) are
optional. Unknown or duplicate fields, wrong types, NaN/inf, a payload over 4096
bytes or not UTF-8 JSON are rejected with a ``ThreatPayloadError`` whose message starts with
the field at fault (and whose ``field`` attribute names it; an unknown or duplicate field whose
name is not plain ``A-Z a-z 0-9 _`` is named quoted as JSON, e.g. ``""`` for an empty name).
"""

from __future__ import annotations

import json
import math
import re
import time

from companion.threats.model import FRAMES, KINDS, TRAFFIC, Threat, payload_error

__all__ = ["decode", "encode", "to_dict", "MAX_PAYLOAD_BYTES", "check_id", "VERSION", "finite_number", "parse_json"]

VERSION = 1
MAX_PAYLOAD_BYTES = 4096
MAX_RADIUS_M = 10_000.0
MAX_SPEED_M_S = 300.0
MAX_TTL_S = 1e6
MAX_LOCAL_M = 1e6
ID_PATTERN = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
NAME_PATTERN = re.compile(r"^[A-Za-z0-9_]{1,64}$")
REQUIRED = ("v", "id", "kind", "frame", "position", "radius_m")
OPTIONAL = ("velocity_ned_m_s", "ttl_s", "traffic")
GLOBAL_KEYS = ("lat", "lon", "alt_m")


class _NonFinite:
    """Stands for a NaN/Infinity literal so that the field holding it can be named."""

    def __init__(self, text: str) -> None:
        self.text = text


def check_id(threat_id, field: str = "id") -> str:
    """Return ``threat_id`` if it is a valid threat id (a zenoh key chunk), else raise."""
    if not isinstance(threat_id, str):
        raise payload_error(field, f"expected a string, got {_type_name(threat_id)}")
    if not ID_PATTERN.match(threat_id):
        raise payload_error(
            field, f"must be 1-64 characters of A-Z a-z 0-9 _ - . (a zenoh key chunk), got {threat_id[:80]!r}"
        )
    return threat_id


def _type_name(value) -> str:
    if isinstance(value, _NonFinite):
        return value.text
    if value is None:
        return "null"
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        dict: "an object",
    }.get(type(value), type(value).__name__)


def _key_name(key: str) -> str:
    """How an unknown or duplicate field is named: as it is if it is a plain name, else quoted
    as JSON (at most 64 characters), so that an empty or odd name is still visible."""
    return key if NAME_PATTERN.match(key) else json.dumps(key[:64])


def finite_number(value, field: str) -> float:
    """``value`` as a float, or a ``ThreatPayloadError`` naming ``field`` (also for NaN/inf literals)."""
    if isinstance(value, _NonFinite):
        raise payload_error(field, f"must be a finite number, got {value.text}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise payload_error(field, f"expected a number, got {_type_name(value)}")
    out = float(value)
    if not math.isfinite(out):
        raise payload_error(field, f"must be a finite number, got {value!r}")
    return out


def _vector3(value, field: str, limit: float) -> tuple:
    if not isinstance(value, list):
        raise payload_error(field, f"expected a list of 3 numbers, got {_type_name(value)}")
    if len(value) != 3:
        raise payload_error(field, f"expected 3 numbers, got {len(value)}")
    out = tuple(finite_number(v, f"{field}[{i}]") for i, v in enumerate(value))
    for i, v in enumerate(out):
        if abs(v) > limit:
            raise payload_error(f"{field}[{i}]", f"magnitude must be <= {limit:g}, got {v!r}")
    return out


def _global_position(value) -> tuple:
    if not isinstance(value, dict):
        raise payload_error(
            "position", f'expected an object {{"lat", "lon", "alt_m"}} for frame \'global\', got {_type_name(value)}'
        )
    for key in value:
        if key not in GLOBAL_KEYS:
            raise payload_error(f"position.{_key_name(key)}", "unknown field (expected lat, lon, alt_m)")
    for key in GLOBAL_KEYS:
        if key not in value:
            raise payload_error(f"position.{key}", "missing")
    lat = finite_number(value["lat"], "position.lat")
    lon = finite_number(value["lon"], "position.lon")
    alt = finite_number(value["alt_m"], "position.alt_m")
    if not -90.0 <= lat <= 90.0:
        raise payload_error("position.lat", f"must be in [-90, 90] degrees, got {lat!r}")
    if not -180.0 <= lon <= 180.0:
        raise payload_error("position.lon", f"must be in [-180, 180] degrees, got {lon!r}")
    if abs(alt) > 100_000.0:
        raise payload_error("position.alt_m", f"magnitude must be <= 100000 m, got {alt!r}")
    return (lat, lon, alt)


def _pairs_hook(pairs: list) -> dict:
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise payload_error(_key_name(key), "duplicate field")
        out[key] = value
    return out


def parse_json(payload, max_bytes: int = MAX_PAYLOAD_BYTES) -> dict:
    """A JSON object from ``payload`` (bytes or str): at most ``max_bytes``, UTF-8, no duplicate
    field; a ``ThreatPayloadError`` naming ``payload`` (or the duplicate field) otherwise."""
    if isinstance(payload, str):
        payload = payload.encode("utf-8")
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise payload_error("payload", f"expected bytes, got {type(payload).__name__}")
    raw = bytes(payload)
    if len(raw) > max_bytes:
        raise payload_error("payload", f"too large: {len(raw)} bytes (at most {max_bytes})")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise payload_error("payload", f"not UTF-8 ({exc.reason} at byte {exc.start})") from None
    try:
        data = json.loads(text, object_pairs_hook=_pairs_hook, parse_constant=_NonFinite)
    except json.JSONDecodeError as exc:
        raise payload_error("payload", f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise payload_error("payload", "not valid JSON: nested too deeply") from None
    if not isinstance(data, dict):
        raise payload_error("payload", f"expected a JSON object, got {_type_name(data)}")
    return data


def check_envelope(data: dict) -> None:
    """Every field known, every required one present, the version this service speaks
    (``ThreatPayloadError`` naming the field otherwise)."""
    for key in data:
        if key not in REQUIRED and key not in OPTIONAL:
            raise payload_error(_key_name(key), f"unknown field (known: {', '.join(REQUIRED + OPTIONAL)})")
    for key in REQUIRED:
        if key not in data:
            raise payload_error(key, "missing")
    version = data["v"]
    if isinstance(version, bool) or not isinstance(version, int) or version != VERSION:
        raise payload_error("v", f"unsupported version {version!r} (this service speaks {VERSION})")


def _ttl(ttl) -> float | None:
    """``ttl_s``: None (until deleted) or a number in (0, ``MAX_TTL_S``]."""
    if ttl is None:
        return None
    ttl = finite_number(ttl, "ttl_s")
    if not 0.0 < ttl <= MAX_TTL_S:
        raise payload_error("ttl_s", f"must be > 0 and <= {MAX_TTL_S:g} (or null: until deleted), got {ttl!r}")
    return ttl


def decode(payload, *, received_t_s: float | None = None, key_id: str | None = None) -> Threat:
    """Validate and decode one threat payload.

    Parameters
    ----------
    payload : bytes (or str)
        The JSON payload of a PUT on ``uav/<sysid>/threats/<id>``.
    received_t_s : float, optional
        Receive time stamped on the threat (default ``time.monotonic()``).
    key_id : str, optional
        The last chunk of the key the payload arrived on; the payload's ``id`` must equal it.

    Returns
    -------
    Threat
        In the payload's frame (a global threat is converted by ``ThreatTable.put``).

    Raises
    ------
    ThreatPayloadError
        The message starts with the field at fault (``payload``, ``v``, ``id``, ``kind``,
        ``frame``, ``position[1]``, ``position.lat``, ``velocity_ned_m_s[0]``, ``radius_m``,
        ``ttl_s`` or the unknown field's name); ``exc.field`` holds it.
    """
    data = parse_json(payload)
    check_envelope(data)
    threat_id = check_id(data["id"])
    if key_id is not None and threat_id != key_id:
        raise payload_error("id", f"{threat_id!r} does not match the key's last chunk {key_id!r}")
    kind = data["kind"]
    if kind not in KINDS or not isinstance(kind, str):
        raise payload_error("kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
    frame = data["frame"]
    if frame not in FRAMES or not isinstance(frame, str):
        raise payload_error("frame", f"expected one of {', '.join(FRAMES)}, got {frame!r}")
    if frame == "local_ned":
        position = _vector3(data["position"], "position", MAX_LOCAL_M)
    else:
        position = _global_position(data["position"])
    velocity = (0.0, 0.0, 0.0)
    if "velocity_ned_m_s" in data:
        velocity = _vector3(data["velocity_ned_m_s"], "velocity_ned_m_s", MAX_SPEED_M_S)
    if kind == "popup" and any(v != 0.0 for v in velocity):
        raise payload_error(
            "velocity_ned_m_s", "a popup threat is static (all zero); use kind 'moving' for a moving threat"
        )
    radius = finite_number(data["radius_m"], "radius_m")
    if not 0.0 < radius <= MAX_RADIUS_M:
        raise payload_error("radius_m", f"must be > 0 and <= {MAX_RADIUS_M:g}, got {radius!r}")
    ttl = _ttl(data.get("ttl_s"))
    traffic = data.get("traffic", "drone")
    if not isinstance(traffic, str) or traffic not in TRAFFIC:
        raise payload_error("traffic", f"expected one of {', '.join(TRAFFIC)}, got {traffic!r}")
    stamp = time.monotonic() if received_t_s is None else float(received_t_s)
    return Threat(
        id=threat_id,
        kind=kind,
        frame=frame,
        position=position,
        velocity_ned_m_s=velocity,
        radius_m=radius,
        ttl_s=ttl,
        received_t_s=stamp,
        traffic=traffic,
    )


def to_dict(threat: Threat) -> dict:
    """The version-1 JSON object of ``threat`` (field order as in DESIGN section 6)."""
    if threat.frame == "global":
        lat, lon, alt = threat.position
        position = {"lat": float(lat), "lon": float(lon), "alt_m": float(alt)}
    else:
        position = [float(x) for x in threat.position]
    out = {
        "v": VERSION,
        "id": threat.id,
        "kind": threat.kind,
        "frame": threat.frame,
        "position": position,
        "velocity_ned_m_s": [float(x) for x in threat.velocity_ned_m_s],
        "radius_m": float(threat.radius_m),
        "ttl_s": None if threat.ttl_s is None else float(threat.ttl_s),
    }
    if threat.traffic != "drone":
        out["traffic"] = threat.traffic
    return out


def encode(threat: Threat) -> bytes:
    """The version-1 JSON payload of ``threat`` (UTF-8 bytes).

    Raises
    ------
    ThreatPayloadError
        If the threat would not decode (bad id, radius, NaN ...): what is sent always decodes.
    """
    data = to_dict(threat)
    try:
        raw = json.dumps(data, separators=(",", ":"), allow_nan=False).encode("utf-8")
    except ValueError:
        raise payload_error("payload", "NaN or infinite value in the threat") from None
    decode(raw, received_t_s=0.0)
    return raw
