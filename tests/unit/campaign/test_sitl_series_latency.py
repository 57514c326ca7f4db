"""The campaign's SITL series reports each manoeuvre's latency from the replay's own record."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from companion.record.flight_record import FlightRecorder

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "benchmarks"))
import campaign_sitl  # noqa: E402


def test_latencies_are_read_per_kind_from_the_record_and_summarised(tmp_path):
    with FlightRecorder(tmp_path / "flight.jsonl") as rec:
        rec.write("decision", kind="evade", event="evade", latency_ms=24.0, t_s=3.0)
        rec.write("decision", kind="evade", event="evade", branch="replan", latency_ms=180.0, t_s=4.0)
        rec.write("decision", kind="hold", event="hold", latency_ms=None, t_s=5.0)  # never engaged
        rec.write("decision", kind="none", event="none", latency_ms=3.0, t_s=6.0)  # no manoeuvre
        rec.write("decision", kind="retime", event="retime", latency_ms=30.0, t_s=7.0)
    got = campaign_sitl.decision_latencies(tmp_path)
    assert got == [("evade", 24.0), ("evade after a replan", 180.0), ("retime", 30.0)]
    summary = campaign_sitl.latency_summary([{"latency_ms": got}, {"latency_ms": [("evade", 36.0)]}, {}])
    assert summary["evade"]["n"] == 2 and summary["evade"]["max"] == 36.0
    assert summary["evade"]["p50"] == pytest.approx(30.0)
    assert set(summary) == {"evade", "evade after a replan", "retime"}


def test_a_kept_track_without_its_record_has_no_latencies(tmp_path):
    assert campaign_sitl.decision_latencies(tmp_path) == []
