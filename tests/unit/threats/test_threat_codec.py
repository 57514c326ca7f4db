"""Threat payload codec (DESIGN section 6): strict validation naming the field, round trip."""

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ThreatPayloadError
from companion.threats.model import Threat
from companion.threats.transport.codec import MAX_PAYLOAD_BYTES, decode, encode

EXAMPLE = {
    "v": 1,
    "id": "t1",
    "kind": "popup",
    "frame": "local_ned",
    "position": [40.0, 42.0, -20.0],
    "velocity_ned_m_s": [0.0, 0.0, 0.0],
    "radius_m": 6.0,
    "ttl_s": 120,
}


def payload(**changes) -> bytes:
    data = dict(EXAMPLE)
    for key, value in changes.items():
        if value is ...:
            data.pop(key)
        else:
            data[key] = value
    return json.dumps(data).encode()


def field_of(raw: bytes) -> str:
    with pytest.raises(ThreatPayloadError) as info:
        decode(raw)
    assert str(info.value).startswith(info.value.field)
    return info.value.field


def test_design_example_decodes():
    threat = decode(json.dumps(EXAMPLE).encode(), received_t_s=5.0)
    assert threat == Threat("t1", "popup", "local_ned", (40.0, 42.0, -20.0), (0.0, 0.0, 0.0), 6.0, 120.0, 5.0)


def test_global_frame_decodes():
    raw = payload(frame="global", position={"lat": 47.39, "lon": 8.54, "alt_m": 520.0})
    threat = decode(raw)
    assert threat.frame == "global" and threat.position == (47.39, 8.54, 520.0)


def test_optional_fields_default():
    threat = decode(payload(velocity_ned_m_s=..., ttl_s=...))
    assert threat.velocity_ned_m_s == (0.0, 0.0, 0.0) and threat.ttl_s is None


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"v": 2}, "v"),
        ({"v": True}, "v"),
        ({"v": ...}, "v"),
        ({"id": ...}, "id"),
        ({"id": "a/b"}, "id"),
        ({"id": "a*"}, "id"),
        ({"id": ""}, "id"),
        ({"id": "x" * 65}, "id"),
        ({"id": 3}, "id"),
        ({"kind": "ufo"}, "kind"),
        ({"kind": ["popup"]}, "kind"),
        ({"frame": "enu"}, "frame"),
        ({"position": [1.0, 2.0]}, "position"),
        ({"position": "1,2,3"}, "position"),
        ({"position": [1.0, "2", 3.0]}, "position[1]"),
        ({"position": [1.0, 2.0, 1e9]}, "position[2]"),
        ({"velocity_ned_m_s": [1.0, 0.0, 0.0]}, "velocity_ned_m_s"),
        ({"kind": "moving", "velocity_ned_m_s": [0.0, True, 0.0]}, "velocity_ned_m_s[1]"),
        ({"kind": "moving", "velocity_ned_m_s": [0.0, 0.0, 1000.0]}, "velocity_ned_m_s[2]"),
        ({"radius_m": 0}, "radius_m"),
        ({"radius_m": -1.0}, "radius_m"),
        ({"radius_m": "6"}, "radius_m"),
        ({"radius_m": ...}, "radius_m"),
        ({"ttl_s": 0}, "ttl_s"),
        ({"ttl_s": -5}, "ttl_s"),
        ({"ttl_s": "long"}, "ttl_s"),
        ({"colour": "red"}, "colour"),
        ({"frame": "global"}, "position"),
        ({"frame": "global", "position": {"lat": 91.0, "lon": 0.0, "alt_m": 0.0}}, "position.lat"),
        ({"frame": "global", "position": {"lat": 0.0, "lon": 181.0, "alt_m": 0.0}}, "position.lon"),
        ({"frame": "global", "position": {"lat": 0.0, "lon": 0.0}}, "position.alt_m"),
        ({"frame": "global", "position": {"lat": 0.0, "lon": 0.0, "alt_m": 1.0, "h": 2}}, "position.h"),
    ],
)
def test_each_bad_field_is_named(changes, field):
    assert field_of(payload(**changes)) == field


@pytest.mark.parametrize(
    "raw, field",
    [
        (b"{not json", "payload"),
        (b"[1, 2]", "payload"),
        (b"\xff\xfe", "payload"),
        (b" " * (MAX_PAYLOAD_BYTES + 1), "payload"),
        (json.dumps(EXAMPLE).replace("6.0", "NaN").encode(), "radius_m"),
        (json.dumps(EXAMPLE).replace("-20.0", "-Infinity").encode(), "position[2]"),
        (json.dumps(EXAMPLE).replace('"ttl_s": 120', '"ttl_s": 120, "ttl_s": 5').encode(), "ttl_s"),
    ],
)
def test_malformed_payloads_are_named(raw, field):
    assert field_of(raw) == field


def test_key_id_must_match_payload_id():
    with pytest.raises(ThreatPayloadError, match="^id:"):
        decode(payload(), key_id="t2")
    assert decode(payload(), key_id="t1").id == "t1"


def test_encode_refuses_what_would_not_decode():
    with pytest.raises(ThreatPayloadError, match="^radius_m"):
        encode(Threat("t1", "popup", "local_ned", (0.0, 0.0, 0.0), radius_m=-1.0))


finite = st.floats(-1e4, 1e4, allow_nan=False)
ids = st.from_regex(r"\A[A-Za-z0-9_.\-]{1,64}\Z")


@st.composite
def threats(draw):
    kind = draw(st.sampled_from(["popup", "moving"]))
    frame = draw(st.sampled_from(["local_ned", "global"]))
    if frame == "global":
        position = (draw(st.floats(-90, 90)), draw(st.floats(-180, 180)), draw(st.floats(-500, 9000)))
    else:
        position = (draw(finite), draw(finite), draw(finite))
    velocity = (0.0, 0.0, 0.0) if kind == "popup" else tuple(draw(st.floats(-50, 50)) for _ in range(3))
    ttl = draw(st.none() | st.floats(0.001, 1e6))
    return Threat(draw(ids), kind, frame, position, velocity, draw(st.floats(0.01, 1e4)), ttl, 7.0)


@settings(deadline=None, max_examples=150)
@given(threats())
def test_encode_decode_round_trip(threat):
    assert decode(encode(threat), received_t_s=7.0) == threat


@settings(deadline=None, max_examples=100)
@given(st.binary(max_size=300))
def test_random_bytes_never_crash(raw):
    try:
        decode(raw)
    except ThreatPayloadError as exc:
        assert exc.field
