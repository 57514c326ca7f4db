"""companion.fleet.status_view: rows of the fleet table from status and event messages (pure)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.fleet.status_view import (
    FleetView,
    format_table,
    nearest_separation,
    positions_common,
    positions_lla,
    record_decisions,
    rows_json,
    sysid_of_key,
    vehicle_rows,
)
from heli_common.frames import LocalFrame

CENTRE = (47.397742, 8.545594, 488.0)


def status(sysid, home_lla, pos_ned_m, **extra):
    return {
        "t_s": 10.0,
        "sysid": sysid,
        "home_lla": list(home_lla),
        "mode": "GUIDED",
        "armed": True,
        "leg": 0,
        "legs": 2,
        "path_id": "leg0",
        "pos_ned_m": list(pos_ned_m),
        "tracking_error_m": 0.1,
        "outcome": "flying",
        **extra,
    }


def home_at(north_m, east_m):
    lat, lon, alt = LocalFrame(*CENTRE).to_lla(north_m, east_m, 0.0)
    return (float(lat), float(lon), float(alt))


def test_positions_about_different_homes_go_to_one_frame():
    # two vehicles with homes 100 m apart (east), each 50 m from its home towards the other:
    # they are at the same point
    statuses = {
        1: status(1, home_at(0.0, 0.0), [0.0, 50.0, -15.0]),
        2: status(2, home_at(0.0, 100.0), [0.0, -50.0, -15.0]),
        3: status(3, home_at(0.0, 100.0), [0.0, -40.0, -15.0]),
    }
    positions, home = positions_common(statuses)
    assert home == pytest.approx(home_at(0.0, 0.0))
    np.testing.assert_allclose(positions[1], [0.0, 50.0, -15.0], atol=1e-6)
    np.testing.assert_allclose(positions[2], [0.0, 50.0, -15.0], atol=0.01)
    near = nearest_separation(positions)
    assert near[1][0] == pytest.approx(0.0, abs=0.01) and near[1][1] == 2
    assert near[3] == (pytest.approx(10.0, abs=0.01), 2)
    lla = positions_lla(statuses)
    assert lla[1][2] == pytest.approx(503.0, abs=1e-3)


def test_vehicles_without_home_or_position_have_no_separation():
    statuses = {1: status(1, home_at(0, 0), [0, 0, -15]), 2: {"sysid": 2, "mode": "GUIDED", "pos_ned_m": None}}
    rows = vehicle_rows(statuses, {})
    assert [r.sysid for r in rows] == [1, 2]
    assert math.isinf(rows[0].nearest_m) and rows[0].nearest_sysid is None
    assert rows[1].pos_ned_m is None
    text = format_table(rows)
    assert "GUIDED" in text and text.count("\n") == 3


def test_rows_count_decisions_and_name_the_last():
    statuses = {2: status(2, home_at(0, 0), [1, 2, -15]), 1: status(1, home_at(0, 30), [0, 0, -15])}
    decisions = {
        2: [
            {"event": "replan", "reason": "fleet/uav1 in 4 s", "threat_id": "fleet/uav1"},
            {"event": "switch", "label": "mgart1", "reason": "conflict"},
        ]
    }
    rows = vehicle_rows(statuses, decisions)
    assert [r.sysid for r in rows] == [1, 2]
    assert rows[1].decisions == 2 and rows[1].last_decision == "switch/mgart1: conflict"
    assert rows[0].decisions == 0 and rows[0].last_decision is None
    assert rows[0].nearest_sysid == 2 and rows[0].nearest_m == pytest.approx(
        math.dist([1, -28, -15], [0, 0, -15]), abs=0.01
    )
    data = rows_json(rows)
    json.dumps(data)  # plain data
    assert data[1]["last_decision"].startswith("switch") and data[0]["leg"] == 0
    table = format_table(rows, width=10)
    assert "switch/..." in table and table.splitlines()[0].startswith("sysid")


def test_empty_table():
    assert format_table([]) == "no vehicle heard"


def test_fleet_view_keeps_the_latest_status_and_ignores_other_keys():
    view = FleetView()
    view.on_status("uav/3/status", {"t_s": 5.0, "mode": "GUIDED"})
    view.on_status("uav/3/status", {"t_s": 4.0, "mode": "LOITER"})  # older: ignored
    view.on_status("uav/x/status", {"t_s": 9.0})
    view.on_status("uav/4/status", None)  # not JSON
    view.on_event("uav/3/events", {"event": "replan"})
    view.on_event("uav/3/events", {"event": "command", "command": "start"})  # not a decision
    statuses, decisions = view.snapshot()
    assert statuses == {3: {"t_s": 5.0, "mode": "GUIDED"}}
    assert decisions == {3: [{"event": "replan"}]}
    assert sysid_of_key("uav/12/events") == 12 and sysid_of_key("uav/12/threats/x") is None


def test_record_decisions_reads_the_decision_lines(tmp_path):
    path = tmp_path / "uav1.jsonl"
    path.write_text(
        "\n".join(
            [
                json.dumps({"type": "event", "name": "frames"}),
                json.dumps({"type": "decision", "kind": "replan", "reason": "r"}),
                '{not json, "decision"',
                json.dumps({"type": "decision", "kind": "rejected", "reason": "bad"}),
            ]
        )
        + "\n"
    )
    assert [d["kind"] for d in record_decisions(path)] == ["replan", "rejected"]
    assert record_decisions(tmp_path / "missing.jsonl") == []


coords = st.floats(min_value=-200.0, max_value=200.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(coords, coords, coords), min_size=2, max_size=6))
def test_nearest_separation_is_symmetric_in_its_minimum(points):
    positions = {k + 1: np.array(p) for k, p in enumerate(points)}
    near = nearest_separation(positions)
    smallest = min(math.dist(points[i], points[j]) for i in range(len(points)) for j in range(i + 1, len(points)))
    assert min(d for d, _ in near.values()) == pytest.approx(smallest)
    for sysid, (d, other) in near.items():
        assert other != sysid
        assert d == pytest.approx(math.dist(positions[sysid], positions[other]))
