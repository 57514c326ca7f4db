"""Property-based fuzz of the threat payloads the companion receives over zenoh (issue 11).

Every sample goes through ``ThreatInbound.on_sample`` (decode on the zenoh thread, count, queue),
the path a real sample takes, with a stand-in for the zenoh sample. Inputs: any bytes, any JSON
value (hypothesis' recursive JSON), JSON objects with the threat's field names and junk values,
and valid threats with exactly one field broken (wrong type, out of range, NaN/Infinity
literal, missing, duplicated, or an unknown field added).

Properties: the bus never fails (``handler_errors`` stays 0); every sample is counted once as
``put`` or ``rejected``; a ``put`` carries a valid threat (finite numbers, 0 < radius <= 10 km,
speed components <= 300 m/s, a popup static, ttl None or in (0, 1e6], id equal to the key's last
chunk); a ``rejected`` one carries a ``ThreatPayloadError`` whose message starts with the field
it names, and for a near-valid payload that field is the broken one.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ThreatPayloadError
from companion.threats.transport import codec
from companion.threats.transport.bus import ThreatBus

zenoh = pytest.importorskip("zenoh")

KEY = "uav/1/threats/"
FIELDS = codec.REQUIRED + codec.OPTIONAL


class Payload:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


def sample(key: str, payload: bytes):
    """A stand-in for a zenoh PUT sample (the attributes ``_decode_sample`` reads)."""
    return SimpleNamespace(key_expr=key, kind=zenoh.SampleKind.PUT, payload=Payload(payload))


@pytest.fixture(scope="module")
def bus():
    """A bus that is never opened: ``inbound.on_sample`` needs no session, updates go to its queue."""
    return ThreatBus(1, listen=("tcp/127.0.0.1:7447",))


def receive(bus: ThreatBus, key: str, payload: bytes):
    """One sample through the bus; returns its update, checks the counters."""
    before = bus.stats()
    bus.inbound.on_sample(sample(key, payload))
    after = bus.stats()
    updates = bus.inbound.drain_updates()
    assert after["handler_errors"] == before["handler_errors"] == 0
    assert after["received"] == before["received"] + 1
    assert len(updates) == 1
    update = updates[0]
    assert update.action in ("put", "rejected")
    assert after[update.action] == before[update.action] + 1
    other = "rejected" if update.action == "put" else "put"
    assert after[other] == before[other]
    return update


def check_update(update, key_id: str | None) -> None:
    """A put holds a valid threat; a rejection names its field."""
    if update.action == "put":
        th = update.threat
        assert update.error is None and th is not None and th.id == key_id == update.threat_id
        assert codec.ID_PATTERN.match(th.id)
        assert th.kind in ("popup", "moving") and th.frame in ("local_ned", "global")
        assert all(math.isfinite(v) for v in (*th.position, *th.velocity_ned_m_s, th.radius_m))
        assert 0.0 < th.radius_m <= codec.MAX_RADIUS_M
        assert all(abs(v) <= codec.MAX_SPEED_M_S for v in th.velocity_ned_m_s)
        assert th.kind == "moving" or th.velocity_ned_m_s == (0.0, 0.0, 0.0)
        assert th.ttl_s is None or 0.0 < th.ttl_s <= codec.MAX_TTL_S
        if th.frame == "global":
            assert -90.0 <= th.position[0] <= 90.0 and -180.0 <= th.position[1] <= 180.0
        else:
            assert all(abs(v) <= codec.MAX_LOCAL_M for v in th.position)
        assert codec.decode(codec.encode(th), received_t_s=th.received_t_s) == th  # it round-trips
    else:
        err = update.error
        assert update.threat is None and isinstance(err, ThreatPayloadError)
        assert isinstance(err.field, str) and err.field and str(err).startswith(f"{err.field}: ")
        assert len(str(err)) > len(err.field) + 2  # a reason follows the field


# ================================================================ strategies
JSON_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
)
JSON = st.recursive(
    JSON_SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(st.one_of(st.sampled_from(FIELDS), st.text(max_size=8)), inner, max_size=6),
    ),
    max_leaves=25,
)
IDS = st.from_regex(codec.ID_PATTERN, fullmatch=True)
FINITE = st.floats(allow_nan=False, allow_infinity=False)
LOCAL = st.lists(st.floats(-1e6, 1e6), min_size=3, max_size=3)
GLOBAL = st.fixed_dictionaries({"lat": st.floats(-90, 90), "lon": st.floats(-180, 180), "alt_m": st.floats(-1e5, 1e5)})
SPEED = st.lists(st.floats(-300, 300), min_size=3, max_size=3)


@st.composite
def valid_threats(draw) -> dict:
    """A valid version-1 threat object."""
    frame = draw(st.sampled_from(["local_ned", "global"]))
    kind = draw(st.sampled_from(["popup", "moving"]))
    data = {
        "v": 1,
        "id": draw(IDS),
        "kind": kind,
        "frame": frame,
        "position": draw(LOCAL if frame == "local_ned" else GLOBAL),
        "radius_m": draw(st.floats(0.0, 1e4, exclude_min=True)),
    }
    if kind == "moving" or draw(st.booleans()):
        data["velocity_ned_m_s"] = draw(SPEED) if kind == "moving" else [0.0, 0.0, 0.0]
    if draw(st.booleans()):
        data["ttl_s"] = draw(st.one_of(st.none(), st.floats(0.0, 1e6, exclude_min=True)))
    if draw(st.booleans()):
        data["traffic"] = draw(st.sampled_from(["drone", "manned"]))
    return data


#: Values that are never valid for the field (a sub-field name is reported for nested ones).
BAD_VALUES = {
    "v": st.one_of(st.integers().filter(lambda v: v != 1), st.just(True), st.just(1.0), st.text(max_size=3)),
    "id": st.one_of(
        st.just(""),
        st.text(min_size=65, max_size=70),
        st.text(max_size=8).filter(lambda s: not codec.ID_PATTERN.match(s)),
        st.integers(),
        st.none(),
    ),
    "kind": st.one_of(
        st.text(max_size=8).filter(lambda s: s not in ("popup", "moving")), st.integers(), st.none(), st.just(["popup"])
    ),
    "frame": st.one_of(
        st.text(max_size=10).filter(lambda s: s not in ("local_ned", "global")), st.none(), st.just({"frame": "global"})
    ),
    "position": st.one_of(
        st.none(),
        st.text(max_size=5),
        st.lists(FINITE, max_size=2),
        st.lists(FINITE, min_size=4, max_size=5),
        st.just([1.0, math.nan, 2.0]),
        st.just({"lat": 91.0, "lon": 0.0, "alt_m": 0.0}),
        st.just([1e7, 0.0, 0.0]),
        st.just({"lat": 1.0, "lon": 2.0}),
        st.just([1.0, "2", 3.0]),
    ),
    "radius_m": st.one_of(
        st.floats(max_value=0.0),
        st.floats(min_value=1e4, exclude_min=True),
        st.none(),
        st.just(True),
        st.text(max_size=4),
        st.just(math.inf),
    ),
    "velocity_ned_m_s": st.one_of(
        st.none(),
        st.lists(FINITE, max_size=2),
        st.just([301.0, 0.0, 0.0]),
        st.just([0.0, -math.inf, 0.0]),
        st.just([0.0, 0.0, False]),
    ),
    "ttl_s": st.one_of(
        st.floats(max_value=0.0),
        st.floats(min_value=1e6, exclude_min=True),
        st.text(max_size=3),
        st.just(math.nan),
        st.just([1.0]),
    ),
    "traffic": st.one_of(
        st.text(max_size=8).filter(lambda s: s not in ("drone", "manned")),
        st.none(),
        st.integers(),
        st.just(["manned"]),
    ),
}


@st.composite
def near_valid(draw) -> tuple[bytes, str, str]:
    """(payload, key id, the broken field): a valid threat with one field broken."""
    data = draw(valid_threats())
    how = draw(st.sampled_from(["value", "value", "value", "missing", "unknown", "duplicate"]))
    if how == "unknown":
        field = draw(st.text(min_size=1, max_size=10).filter(lambda s: s not in FIELDS))
        data[field] = draw(JSON_SCALARS)
    elif how == "missing":
        field = draw(st.sampled_from(codec.REQUIRED))
        del data[field]
    else:
        field = draw(st.sampled_from(FIELDS))
        data[field] = draw(BAD_VALUES[field]) if how == "value" else data.get(field, 1.0)
    text = json.dumps(data, allow_nan=True)  # NaN / Infinity literals stay in the text
    if how == "duplicate":
        text = text[:-1] + f", {json.dumps(field)}: {json.dumps(data[field], allow_nan=True)}}}"
    key_id = data["id"] if isinstance(data.get("id"), str) and codec.ID_PATTERN.match(data["id"]) else "t1"
    return text.encode(), key_id, field


def named(field: str, broken: str) -> bool:
    """True if the error's field is the broken field (an odd name quoted as JSON) or one of its parts
    (``position[1]``, ``position.lat``)."""
    return field in (broken, json.dumps(broken[:64])) or field.startswith((f"{broken}[", f"{broken}."))


# ================================================================ the properties
@settings(max_examples=200, deadline=None)
@given(payload=st.binary(max_size=600), key_id=st.one_of(IDS, st.text(max_size=10)))
def test_any_bytes_on_any_key(bus, payload, key_id):
    update = receive(bus, KEY + key_id, payload)
    check_update(update, key_id)
    if not codec.ID_PATTERN.match(key_id):
        assert update.action == "rejected" and update.error.field == "key" and update.threat_id is None


@settings(max_examples=200, deadline=None)
@given(value=JSON, key_id=IDS)
def test_any_json_value(bus, value, key_id):
    update = receive(bus, KEY + key_id, json.dumps(value, allow_nan=True).encode())
    check_update(update, key_id)
    if not isinstance(value, dict):
        assert update.action == "rejected" and update.error.field == "payload"


@settings(max_examples=250, deadline=None)
@given(case=near_valid())
def test_one_broken_field_is_named(bus, case):
    payload, key_id, broken = case
    update = receive(bus, KEY + key_id, payload)
    check_update(update, key_id)
    assert update.action == "rejected", f"{payload!r} accepted with {broken!r} broken"
    field = update.error.field
    oversized = len(payload) > codec.MAX_PAYLOAD_BYTES and field == "payload"
    assert named(field, broken) or oversized, f"{broken!r} broken, {field!r} named: {update.error}"


@settings(max_examples=100, deadline=None)
@given(data=valid_threats())
def test_valid_threats_are_put(bus, data):
    payload = json.dumps(data).encode()
    update = receive(bus, KEY + data["id"], payload)
    check_update(update, data["id"])
    assert update.action == "put", update.error


def test_non_finite_literals_are_named():
    """NaN, Infinity and -Infinity literals (valid for Python's json, not for JSON) name their field."""
    for literal in ("NaN", "Infinity", "-Infinity"):
        text = (
            '{"v": 1, "id": "t1", "kind": "popup", "frame": "local_ned", "position": [1, '
            + literal
            + ', 2], "radius_m": 5}'
        )
        with pytest.raises(ThreatPayloadError) as exc:
            codec.decode(text.encode(), key_id="t1")
        assert exc.value.field == "position[1]" and literal in str(exc.value)
