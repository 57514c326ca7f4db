"""The published JSON Schema of the threat payload says what the codec accepts."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ThreatPayloadError
from companion.threats.transport import codec
from companion.threats.transport.schema import payload_schema

ROOT = Path(__file__).resolve().parents[3]
VALIDATOR = jsonschema.Draft202012Validator(payload_schema())


def test_the_published_schema_is_the_generated_one():
    """Regenerate: .venv/bin/python -m companion.threats.transport.schema > docs/threat.schema.json"""
    assert json.loads((ROOT / "docs" / "threat.schema.json").read_text()) == payload_schema()


def test_the_schema_is_a_valid_draft_2020_12_schema():
    jsonschema.Draft202012Validator.check_schema(payload_schema())


numbers = st.one_of(st.floats(-2e6, 2e6, allow_nan=False), st.integers(-400, 400), st.sampled_from([0, 0.0, 1e-9]))
vector = st.lists(numbers, min_size=2, max_size=4)
global_pos = st.dictionaries(st.sampled_from(["lat", "lon", "alt_m", "x"]), numbers, min_size=2, max_size=4)
fields = {
    "v": st.sampled_from([1, 2, 0, "1", None]),
    "id": st.one_of(st.from_regex(r"\A[A-Za-z0-9_.\-]{1,64}\Z"), st.sampled_from(["", "a/b", "x" * 65, 3])),
    "kind": st.sampled_from(["popup", "moving", "static", 1]),
    "frame": st.sampled_from(["local_ned", "global", "ned"]),
    "position": st.one_of(vector, global_pos, st.just("here")),
    "radius_m": st.one_of(numbers, st.just(None), st.just(True)),
    "velocity_ned_m_s": st.one_of(st.just([0, 0, 0]), st.just([0.0, -0.0, 0.0]), vector),
    "ttl_s": st.one_of(st.none(), numbers),
    "traffic": st.sampled_from(["drone", "manned", "boat"]),
    "extra": st.integers(),
}


finite = st.floats(-1e3, 1e3, allow_nan=False)


@st.composite
def valid_payloads(draw):
    kind, frame = draw(st.sampled_from(["popup", "moving"])), draw(st.sampled_from(["local_ned", "global"]))
    position = (
        draw(st.lists(finite, min_size=3, max_size=3))
        if frame == "local_ned"
        else {"lat": draw(st.floats(-90, 90)), "lon": draw(st.floats(-180, 180)), "alt_m": draw(finite)}
    )
    data = {
        "v": 1,
        "id": draw(st.from_regex(r"\A[A-Za-z0-9_.\-]{1,64}\Z")),
        "kind": kind,
        "frame": frame,
        "position": position,
        "radius_m": draw(st.floats(0.1, 1e4)),
    }
    if kind == "moving" or draw(st.booleans()):
        data["velocity_ned_m_s"] = (
            [0.0, 0.0, 0.0] if kind == "popup" else draw(st.lists(st.floats(-300, 300), min_size=3, max_size=3))
        )
    if draw(st.booleans()):
        data["ttl_s"] = draw(st.one_of(st.none(), st.floats(0.5, 1e6)))
    if draw(st.booleans()):
        data["traffic"] = draw(st.sampled_from(["drone", "manned"]))
    return data


@st.composite
def payloads(draw):
    """A valid payload, or one with one field replaced, removed or added."""
    data = draw(valid_payloads())
    change = draw(st.sampled_from(["none", "replace", "remove", "add"]))
    name = draw(st.sampled_from(sorted(fields)))
    if change == "replace":
        data[name] = draw(fields[name])
    elif change == "remove":
        data.pop(name, None)
    elif change == "add":
        data.setdefault(name, draw(fields[name]))
    return data


@settings(max_examples=600, deadline=None)
@given(payloads())
def test_the_codec_accepts_exactly_what_the_schema_allows(data):
    raw = json.dumps(data).encode()
    allowed = VALIDATOR.is_valid(data)
    try:
        codec.decode(raw, received_t_s=0.0)
        decoded = True
    except ThreatPayloadError:
        decoded = False
    assert decoded == allowed, (data, [e.message for e in VALIDATOR.iter_errors(data)])


def test_an_encoded_threat_is_valid_against_the_schema():
    from companion.threats.model import Threat

    for threat in (
        Threat("m1", "moving", "local_ned", (44.0, 30.0, -20.0), (-1.0, 1.0, 0.0), 3.0, 120.0),
        Threat("g1", "popup", "global", (47.39, 8.54, 520.0), (0.0, 0.0, 0.0), 6.0, None),
    ):
        VALIDATOR.validate(json.loads(codec.encode(threat)))
