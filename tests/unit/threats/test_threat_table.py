"""Threat table: PUT replaces, DELETE removes, ttl expiry, constant-velocity prediction."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.errors import ThreatPayloadError
from companion.geo import LocalFrame
from companion.threats.model import Threat, ThreatTable


def threat(tid="t1", pos=(10.0, 0.0, -20.0), vel=(0.0, 0.0, 0.0), ttl=None, t=0.0, kind="popup"):
    return Threat(tid, kind, "local_ned", pos, vel, 3.0, ttl, t)


def test_put_inserts_then_replaces():
    table = ThreatTable()
    assert table.put(threat(pos=(1.0, 2.0, 3.0))) is False
    assert table.put(threat(pos=(4.0, 5.0, 6.0))) is True
    assert len(table) == 1 and table.get("t1").position == (4.0, 5.0, 6.0)
    assert table.stats()["put"] == 2 and table.stats()["replaced"] == 1


def test_delete_removes_and_reports_unknown():
    table = ThreatTable()
    table.put(threat("a"))
    table.put(threat("b"))
    assert table.delete("a") is True
    assert table.delete("a") is False
    assert [t.id for t in table.snapshot()] == ["b"]
    assert table.stats()["delete_unknown"] == 1


def test_ttl_expiry():
    table = ThreatTable()
    table.put(threat("short", ttl=5.0, t=10.0))
    table.put(threat("forever"))
    assert [t.id for t in table.snapshot(now_t_s=14.9)] == ["forever", "short"]
    assert [t.id for t in table.snapshot(now_t_s=15.0)] == ["forever"]
    assert table.expire(14.0) == []
    v = table.version
    assert table.expire(15.0) == ["short"]
    assert "short" not in table and table.version > v


def test_prediction_is_constant_velocity():
    th = threat(pos=(0.0, 0.0, -10.0), vel=(1.0, -2.0, 0.5), t=3.0, kind="moving")
    table = ThreatTable()
    table.put(th)
    np.testing.assert_allclose(table.position_at("t1", 5.0), [2.0, -4.0, -9.0])
    np.testing.assert_allclose(th.position_at(np.array([3.0, 4.0])), [[0, 0, -10], [1, -2, -9.5]])
    with pytest.raises(KeyError):
        table.position_at("nope", 1.0)


@settings(deadline=None, max_examples=60)
@given(
    st.lists(st.floats(-100, 100), min_size=3, max_size=3),
    st.lists(st.floats(-30, 30), min_size=3, max_size=3),
    st.floats(-50, 50),
    st.floats(0, 100),
)
def test_prediction_property(pos, vel, t0, dt):
    th = threat(pos=tuple(pos), vel=tuple(vel), t=t0, kind="moving")
    later = th.position_at(t0 + dt)
    np.testing.assert_allclose(later - np.asarray(pos), np.asarray(vel) * dt, atol=1e-9)


def test_global_threat_is_converted_with_home():
    home = LocalFrame(47.0, 8.0, 500.0)
    north, east, down = home.to_ned(47.0005, 8.0, 530.0)
    g = Threat("g", "popup", "global", (47.0005, 8.0, 530.0), radius_m=5.0)
    with pytest.raises(ThreatPayloadError, match="^frame"):
        ThreatTable().put(g)
    table = ThreatTable(home=home)
    table.put(g)
    stored = table.get("g")
    assert stored.frame == "local_ned"
    np.testing.assert_allclose(stored.position, [north, east, down], atol=1e-6)
    assert 55.0 < stored.position[0] < 56.0 and abs(stored.position[2] + 30.0) < 0.01
