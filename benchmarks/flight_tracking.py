"""Tracking error of full SITL flights of the sample missions (issue 5; goal RMS <= 0.3 m).

Each mission of ``mission_files/`` is flown end to end by separate ``sim-vehicle`` and
``companion run`` processes over real MAVLink (``companion.demo.fly``). The tracking error is
the companion's: the distance between the vehicle's LOCAL_POSITION_NED and the reference at the
vehicle's timestamp, over every leg. The companion's own setpoint-stream jitter of each flight
is reported beside it.

Usage::

    .venv/bin/python benchmarks/flight_tracking.py [--quick] [--speedup X]

Prints a table, writes ``out/bench/flight_tracking.json`` and
``docs/benchmarks/flight_tracking.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from flight_support import fly  # noqa: E402

from companion.record.flight_record import load_record  # noqa: E402

MISSIONS = ("exclusion_zones.plan", "square.waypoints", "paper_cluttered_100m.plan")
GOAL_RMS_M = 0.3


def stream_jitter(record_path: str) -> dict:
    record = load_record(record_path)
    for event in record.events:
        if event.get("name") == "setpoint_jitter":
            return event
    return {}


def run(missions, speedup: float) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="flight_tracking_") as tmp:
        for name in missions:
            summary = fly(Path(tmp) / name, REPO / "mission_files" / name, speedup=speedup)
            jitter = stream_jitter(summary["record"])
            rows.append(
                {
                    "mission": name,
                    "legs": summary["legs_reached"],
                    "rms_m": summary["rms_tracking_error_m"],
                    "max_m": summary["max_tracking_error_m"],
                    "jitter_p99_ms": jitter.get("p99_ms"),
                    "outcome": summary["outcome"],
                }
            )
    return rows


def table(rows: list[dict], speedup: float) -> str:
    lines = [
        f"SITL flights at {speedup:g}x, G2 smoothing, default limits (goal RMS <= {GOAL_RMS_M} m)",
        "",
        "| mission | legs | RMS error (m) | max error (m) | stream jitter p99 (ms) | outcome |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        jitter = "-" if r["jitter_p99_ms"] is None else f"{r['jitter_p99_ms']:.2f}"
        lines.append(
            f"| {r['mission']} | {r['legs']} | {r['rms_m']:.3f} | {r['max_m']:.3f} | {jitter} | {r['outcome']} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the first mission")
    parser.add_argument("--speedup", type=float, default=4.0)
    args = parser.parse_args()
    rows = run(MISSIONS[:1] if args.quick else MISSIONS, args.speedup)
    text = table(rows, args.speedup)
    print(text)
    out = REPO / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    (out / "flight_tracking.json").write_text(json.dumps({"speedup": args.speedup, "rows": rows}, indent=2))
    (REPO / "docs" / "benchmarks" / "flight_tracking.md").write_text(
        "# Tracking error of SITL flights\n\n" + text + "\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
