"""The report's 3D scene: the instant, the threats known then, the path flown then (issue 14)."""

from companion.record.flight_record import FlightRecorder, load_record
from companion.record.report import render_report
from companion.record.report_scene import path_at, scene_instant, threats_known_at
from tests.unit.view.test_flight_view import write_flight


def recorded(tmp_path):
    write_flight(FlightRecorder(tmp_path / "f.jsonl"))
    return load_record(tmp_path / "f.jsonl")


def test_the_instant_is_the_first_threat_decision_and_shows_what_was_known_then(tmp_path):
    record = recorded(tmp_path)
    t = scene_instant(record)
    assert t == record.decisions[0]["t_s"]
    assert set(threats_known_at(record, t)) == {"mover1"}
    assert threats_known_at(record, record.threats[0]["t_s"] - 0.01) == {}  # not yet reported
    assert threats_known_at(record, 9.5) == {}  # removed at 9 s
    assert path_at(record, t) == record.decisions[0]["path_ned_m"]
    assert path_at(record, t - 0.01) is None  # still on its leg


def test_without_decisions_the_instant_is_mid_flight_and_without_samples_there_is_none(tmp_path):
    record = recorded(tmp_path)
    record.decisions = []
    assert scene_instant(record) == record.samples["t_s"][len(record.samples["t_s"]) // 2]
    record.samples = {}
    assert scene_instant(record) is None


def test_the_report_draws_the_scene(tmp_path):
    written = {p.name for p in render_report(recorded(tmp_path), tmp_path / "report")}
    assert "scene.png" in written and (tmp_path / "report" / "scene.png").stat().st_size > 20_000


def test_the_report_gives_the_companion_s_tracking_figures_not_a_second_set(tmp_path):
    """The console (the companion's summary, over every LOCAL_POSITION_NED) and the report give
    one figure; the record's 10 Hz samples fill in only a record without a summary."""
    import json

    record = recorded(tmp_path)
    record.summary = {"outcome": "completed", "rms_tracking_error_m": 0.14, "max_tracking_error_m": 1.71}
    render_report(record, tmp_path / "with")
    got = json.loads((tmp_path / "with" / "summary.json").read_text())
    assert (got["rms_tracking_error_m"], got["max_tracking_error_m"]) == (0.14, 1.71)
    record.summary = {"outcome": "completed"}
    render_report(record, tmp_path / "without")
    got = json.loads((tmp_path / "without" / "summary.json").read_text())
    assert got["rms_tracking_error_m"] != 0.14 and got["max_tracking_error_m"] >= got["rms_tracking_error_m"] > 0
