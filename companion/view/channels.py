"""The flight's channels: topic names and the JSON schemas of the companion's own messages.

Foxglove's well-known schemas (SceneUpdate, FrameTransform, LocationFix, Log) carry the 3D
scene, the map and the log panel; the flight record's content goes on JSON channels with a
JSON schema each, one per record line type, the ``sample`` line split into the vehicle's state,
the reference, the tracking error and the actuator inputs. ``companion report`` reads the JSON
channels back (``companion.view.mcap_record``). ``TELEMETRY`` is the live view's vehicle state,
published as each LOCAL_POSITION_NED arrives (``companion.view.live``), with the vehicle's own
time stamp.
"""

from __future__ import annotations

__all__ = [
    "RECORD_TOPICS",
    "SAMPLE_TOPICS",
    "TELEMETRY",
    "TELEMETRY_PROPERTIES",
    "SCENE_WORLD",
    "SCENE_PATHS",
    "SCENE_THREATS",
    "SCENE_VEHICLE",
    "TRANSFORMS",
    "LOCATION",
    "LOG",
    "json_schema",
]

_NUM = {"type": "number"}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_PATH = {"type": "array", "items": _VEC3}
_STR = {"type": "string"}
_INT = {"type": "integer"}
_ANY: dict = {}

#: record line type -> (topic, properties of its JSON messages). Lines may carry more fields.
RECORD_TOPICS: dict[str, tuple[str, dict]] = {
    "header": (
        "/flight/header",
        {"settings": {"type": "object"}, "seed": _INT, "home_lla": _VEC3, "mission": _STR, "waypoints_ned_m": _PATH},
    ),
    "world": ("/flight/world", {"world": {"type": "object"}, "obstacles": {"type": "array"}}),
    "plan": (
        "/flight/plan",
        {
            "leg": _INT,
            "seq": _INT,
            "path_id": _STR,
            "path_ned_m": _PATH,
            "reference_ne": {"type": "array"},
            "tree": _ANY,
            "summary": _ANY,
            "feasibility": _ANY,
        },
    ),
    "alternatives": ("/flight/alternatives", {"leg": _INT, "t_s": _NUM, "paths": {"type": "array", "items": _PATH}}),
    "threat": (
        "/flight/threat",
        {
            "id": _STR,
            "source": _STR,
            "kind": _STR,
            "position_ned_m": _VEC3,
            "velocity_ned_m_s": _VEC3,
            "radius_m": _NUM,
            "t_s": _NUM,
            "removed": {"type": "boolean"},
        },
    ),
    "decision": (
        "/flight/decision",
        {
            "kind": _STR,
            "reason": _STR,
            "label": _STR,
            "path_id": _STR,
            "path_ned_m": _PATH,
            "trigger": _STR,
            "latency_ms": _NUM,
            "decide_ms": _NUM,
            "min_clearance_m": _NUM,
            "threat_id": _STR,
            "t_s": _NUM,
            "leg": _INT,
        },
    ),
    "alert": (
        "/flight/alert",
        {
            "t_s": _NUM,
            "threat_id": _STR,
            "traffic": _STR,
            "level": _STR,
            "action": _INT,
            "time_to_cpa_s": _NUM,
            "horizontal_m": _NUM,
            "vertical_m": _NUM,
            "time_to_lowc_s": _NUM,
            "text": _STR,
        },
    ),
    "event": ("/flight/event", {"name": _STR, "t_s": _NUM}),
    "summary": (
        "/flight/summary",
        {
            "legs_planned": _INT,
            "legs_reached": _INT,
            "landed": {"type": "boolean"},
            "rms_tracking_error_m": _NUM,
            "max_tracking_error_m": _NUM,
            "outcome": _STR,
        },
    ),
}
#: The ``sample`` line, split: topic -> the sample keys it carries (``t_s`` on each).
SAMPLE_TOPICS: dict[str, dict] = {
    "/vehicle/state": {"t_s": _NUM, "pos_ned_m": _VEC3, "vel_ned_m_s": _VEC3, "euler_rad": _VEC3},
    "/vehicle/reference": {"t_s": _NUM, "ref_pos_ned_m": _VEC3, "ref_vel_ned_m_s": _VEC3, "leg": _INT, "path_id": _STR},
    "/vehicle/tracking_error": {"t_s": _NUM, "tracking_error_m": _NUM},
    "/vehicle/actuators": {"t_s": _NUM, "servo_us": {"type": ["array", "null"], "items": _INT}},
}
#: The vehicle's state as its telemetry reports it, one message per LOCAL_POSITION_NED.
TELEMETRY = "/vehicle/telemetry"
TELEMETRY_PROPERTIES: dict = {
    "time_boot_ms": _INT,
    "t_s": _NUM,
    "seq": _INT,
    "pos_ned_m": _VEC3,
    "vel_ned_m_s": _VEC3,
    "euler_rad": {"type": ["array", "null"], "items": _NUM},
    "frame": {"type": "string", "enum": ["home", "vehicle_local"]},
}
SCENE_WORLD = "/scene/world"
SCENE_PATHS = "/scene/paths"
SCENE_THREATS = "/scene/threats"
SCENE_VEHICLE = "/scene/vehicle"
TRANSFORMS = "/tf"
LOCATION = "/vehicle/location"
LOG = "/log"


def json_schema(topic: str, properties: dict) -> dict:
    """The JSON schema of a topic's messages (extra fields allowed)."""
    title = "companion" + topic.replace("/", ".")
    return {"title": title, "type": "object", "properties": properties}
