"""companion.progress: the demo's live view of a flight (issue 14, item 5)."""

import io

from rich.console import Console

from companion.progress import FlightProgress, event_text, status_text


def test_a_status_is_one_line_with_mode_leg_path_time_and_error():
    line = status_text(
        {
            "t_s": 65.61,
            "mode": "GUIDED",
            "armed": True,
            "leg": 1,
            "legs": 5,
            "path_id": "alt2-14",
            "tracking_error_m": 0.123,
            "link": True,
        }
    )
    assert line == "GUIDED · leg 2/5 · alt2-14 · t 65.6 s · error 0.12 m"
    assert status_text({"mode": None, "link": False}) == "? · LINK LOST"


def test_decisions_are_lines_and_no_change_is_silent():
    assert (
        event_text({"event": "evade", "latency_ms": 73.3, "source": "radar1", "reason": "mover1 in 2.0 s: evade"})
        == "evade (73 ms) [radar1]: mover1 in 2.0 s: evade"
    )
    assert event_text({"event": "none", "reason": "clear"}) is None
    assert event_text({"event": "rejected", "reason": "frame: missing"}) == "rejected: frame: missing"


def test_new_legs_modes_and_decisions_are_printed_as_they_come():
    out = io.StringIO()
    with FlightProgress(Console(file=out, force_terminal=False, width=200), title="demo") as progress:
        progress.on_status({"mode": "GUIDED", "leg": -1, "legs": 3, "t_s": 0.5})  # taking off
        progress.on_status({"mode": "GUIDED", "leg": 0, "legs": 3, "t_s": 1.0})
        progress.on_status({"mode": "GUIDED", "leg": 0, "legs": 3, "t_s": 1.5})
        progress.on_event({"event": "switch", "reason": "back to the mission", "latency_ms": 250.0, "source": "demo"})
        progress.on_status({"mode": "GUIDED", "leg": 1, "legs": 3, "t_s": 9.0})
        progress.on_status({"mode": "LAND", "leg": 2, "legs": 3, "t_s": 30.0})
    lines = out.getvalue().splitlines()
    assert lines == [
        "demo: mode GUIDED",
        "demo: leg 1/3",
        "demo: switch (250 ms) [demo]: back to the mission",
        "demo: leg 2/3",
        "demo: mode LAND",
        "demo: leg 3/3",
    ]
