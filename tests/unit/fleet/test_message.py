"""The trajectory message of ``uav/<sysid>/trajectory``: round trip, and bad input named by field."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ThreatPayloadError
from companion.fleet.message import MAX_PAYLOAD_BYTES, SampledPath, TrajectoryMessage, decode, encode

point = st.tuples(*[st.floats(-500.0, 500.0, allow_nan=False)] * 3)


def message(ned, *, pending=None, echo=None) -> TrajectoryMessage:
    path = SampledPath("leg1", 12.5, 0.5, np.asarray(ned, dtype=float))
    return TrajectoryMessage(
        3, 7, 1.6, (47.397742, 8.545594, 488.0), 12.5, 1.7e9, 1.0, 1.7e9 + 0.1, path, pending, echo or {}
    )


@settings(max_examples=100, deadline=None)
@given(
    st.lists(point, min_size=1, max_size=60),
    st.dictionaries(st.integers(1, 255), st.tuples(st.floats(0, 2e9), st.floats(0, 2e9)), max_size=4),
)
def test_a_message_survives_its_round_trip_to_the_centimetre(ned, echo):
    msg = message(ned, echo=echo)
    got = decode(encode(msg))
    assert (got.sysid, got.seq, got.origin_lla, got.echo) == (
        3,
        7,
        msg.origin_lla,
        {k: tuple(v) for k, v in echo.items()},
    )
    assert np.max(np.abs(got.committed.ned_m - np.asarray(ned))) <= 0.005 + 1e-9
    assert np.allclose(got.committed.times_s, 12.5 + 0.5 * np.arange(len(ned)))
    assert got.pending is None


def test_a_pending_trajectory_travels_with_the_committed_one():
    pending = SampledPath("replan-3", 13.0, 0.5, np.zeros((4, 3)))
    got = decode(encode(message([[0.0, 0.0, -15.0]], pending=pending)))
    assert got.pending.path_id == "replan-3" and got.pending.ned_m.shape == (4, 3)


def _edit(**changes) -> bytes:
    data = json.loads(encode(message([[0.0, 0.0, -15.0], [0.0, 4.0, -15.0]])))
    for key, value in changes.items():
        if value is KeyError:
            del data[key]
        else:
            data[key] = value
    return json.dumps(data).encode()


@pytest.mark.parametrize(
    "payload, field",
    [
        (_edit(v=2), "v"),
        (_edit(sysid=0), "sysid"),
        (_edit(sysid=True), "sysid"),
        (_edit(committed=None), "committed"),
        (_edit(committed=KeyError), "committed"),
        (_edit(extra=1), "extra"),
        (_edit(origin_lla=[95.0, 8.5, 488.0]), "origin_lla[0]"),
        (_edit(clock={"mission_s": 1.0, "unix_s": 2.0}), "clock.scale"),
        (_edit(clock={"mission_s": 1.0, "unix_s": 2.0, "scale": 0.0}), "clock.scale"),
        (_edit(committed={"path_id": "a", "t0_s": 0.0, "dt_s": 0.5, "ned_m": [[0, 0]]}), "committed.ned_m[0]"),
        (_edit(committed={"path_id": "a", "t0_s": 0.0, "dt_s": 0.5, "ned_m": []}), "committed.ned_m"),
        (_edit(committed={"path_id": "a", "t0_s": 0.0, "dt_s": -1, "ned_m": [[0, 0, 0]]}), "committed.dt_s"),
        (_edit(echo={"x": [1, 2]}), "echo.x"),
        (_edit(seq=7).replace(b'"seq": 7', b'"seq": NaN'), "seq"),
        (b"\xff\xfe", "payload"),
        (b"[1, 2]", "payload"),
        (b" " * (MAX_PAYLOAD_BYTES + 1), "payload"),
    ],
)
def test_a_bad_message_is_refused_naming_its_field(payload, field):
    with pytest.raises(ThreatPayloadError) as err:
        decode(payload)
    assert str(err.value).startswith(field), str(err.value)
