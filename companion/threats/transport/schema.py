"""The JSON Schema of the threat payload, generated from the codec's own definition.

``companion.threats.transport.codec`` is the one definition of the version-1 payload: its
fields, patterns and limits. ``payload_schema`` states the same rules as a JSON Schema (draft
2020-12), so that producers in other languages can validate what they send before they send
it; ``docs/threat.schema.json`` is its output, and a test fails when the two differ.

Two rules of the codec are not expressible in a schema and are only the codec's: a payload is at
most ``MAX_PAYLOAD_BYTES`` of UTF-8, and no field appears twice.

Usage::

    .venv/bin/python -m companion.threats.transport.schema > docs/threat.schema.json
"""

from __future__ import annotations

import json
import sys

from companion.threats.model import FRAMES, KINDS, TRAFFIC
from companion.threats.transport.codec import (
    GLOBAL_KEYS,
    ID_PATTERN,
    MAX_LOCAL_M,
    MAX_PAYLOAD_BYTES,
    MAX_RADIUS_M,
    MAX_SPEED_M_S,
    MAX_TTL_S,
    OPTIONAL,
    REQUIRED,
    VERSION,
)

__all__ = ["payload_schema", "SCHEMA_ID"]

SCHEMA_ID = "urn:heli-companion:threat-payload:1"


def _vector3(limit: float, description: str) -> dict:
    return {
        "type": "array",
        "minItems": 3,
        "maxItems": 3,
        "description": description,
        "items": {"type": "number", "minimum": -limit, "maximum": limit},
    }


def _global_position() -> dict:
    ranges = {
        "lat": (-90.0, 90.0, "degrees, WGS-84"),
        "lon": (-180.0, 180.0, "degrees, WGS-84"),
        "alt_m": (-100_000.0, 100_000.0, "metres above mean sea level"),
    }
    assert tuple(ranges) == GLOBAL_KEYS
    return {
        "type": "object",
        "additionalProperties": False,
        "required": list(GLOBAL_KEYS),
        "properties": {
            k: {"type": "number", "minimum": lo, "maximum": hi, "description": d} for k, (lo, hi, d) in ranges.items()
        },
    }


def _properties() -> dict:
    props = {
        "v": {"type": "integer", "const": VERSION, "description": "payload version"},
        "id": {
            "type": "string",
            "pattern": ID_PATTERN.pattern,
            "description": "threat id, a zenoh key chunk; equals the key's last chunk",
        },
        "kind": {"enum": list(KINDS), "description": "popup: static (zero velocity); moving"},
        "frame": {"enum": list(FRAMES), "description": "local_ned: metres from home; global: lat/lon/alt"},
        "position": {"description": "[north, east, down] m (local_ned) or {lat, lon, alt_m} (global)"},
        "radius_m": {
            "type": "number",
            "exclusiveMinimum": 0.0,
            "maximum": MAX_RADIUS_M,
            "description": "radius of the threat's sphere, m",
        },
        "velocity_ned_m_s": _vector3(MAX_SPEED_M_S, "velocity, north-east-down m/s (default zero)"),
        "ttl_s": {
            "type": ["number", "null"],
            "exclusiveMinimum": 0.0,
            "maximum": MAX_TTL_S,
            "description": "time to live from receipt, s; null or absent: until deleted",
        },
        "traffic": {
            "enum": list(TRAFFIC),
            "default": "drone",
            "description": "manned: judged with the aviation volumes (ADS-B reports)",
        },
    }
    assert set(props) == set(REQUIRED) | set(OPTIONAL)
    return props


def payload_schema() -> dict:
    """The version-1 threat payload as a JSON Schema (draft 2020-12)."""
    local = {"properties": {"frame": {"const": "local_ned"}}}
    popup = {"properties": {"kind": {"const": "popup"}}, "required": ["kind"]}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "heli-companion threat payload, version 1",
        "description": (
            f"The JSON payload of a PUT on uav/<sysid>/threats/<id> (DESIGN section 6). Also: at most "
            f"{MAX_PAYLOAD_BYTES} bytes of UTF-8, and no duplicate field (the codec's rules a schema "
            "cannot state)."
        ),
        "type": "object",
        "additionalProperties": False,
        "required": list(REQUIRED),
        "properties": _properties(),
        "allOf": [
            {
                "if": local,
                "then": {"properties": {"position": _vector3(MAX_LOCAL_M, "north, east, down, m")}},
                "else": {"properties": {"position": _global_position()}},
            },
            {"if": popup, "then": {"properties": {"velocity_ned_m_s": {"items": {"const": 0}}}}},
        ],
    }


def main() -> int:
    sys.stdout.write(json.dumps(payload_schema(), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
