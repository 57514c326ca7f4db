"""Threat storm against a real flight (issue 6): 1000 threat updates per second for 10 s.

Separate ``sim-vehicle`` and ``companion run`` processes fly ``mission_files/exclusion_zones.plan``
at 4x; once the first leg is flown, this process PUTs threat updates over real zenoh at 1000 per
second for 10 s (50 threat ids moving well away from the path, so every update is checked
against the remaining reference but none needs a new path). Reported from the companion itself:
updates received (none may be lost), the 50 Hz setpoint stream's period jitter over the flight
(goal p99 <= 5 ms during the storm), and that the flight completes.

Usage::

    .venv/bin/python benchmarks/threat_storm.py [--quick] [--rate HZ] [--seconds S]

Prints a table, writes ``out/bench/threat_storm.json`` and ``docs/benchmarks/threat_storm.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from flight_support import DEMO_MISSION, flight_processes  # noqa: E402

from companion.demo import FlightWatcher, last_json_line  # noqa: E402
from companion.record.flight_record import load_record  # noqa: E402
from companion.threats.model import Threat  # noqa: E402
from companion.threats.transport.bus import ThreatBus  # noqa: E402

SPEEDUP = 4.0


def storm(bus: ThreatBus, rate_hz: float, seconds: float) -> int:
    """PUT ``rate_hz`` updates per second for ``seconds`` on absolute deadlines; returns the count."""
    sent, t0 = 0, time.monotonic()
    total = int(rate_hz * seconds)
    while sent < total:
        k = sent % 50
        bus.client.put_threat(
            Threat(
                f"storm{k}", "moving", "local_ned", (300.0 + k, 300.0 + 0.01 * sent, -15.0), (0.0, 1.0, 0.0), 2.0, 60.0
            )
        )
        sent += 1
        delay = t0 + sent / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return sent


def run(rate_hz: float, seconds: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="threat_storm_") as tmp:
        with flight_processes(Path(tmp), DEMO_MISSION, speedup=SPEEDUP) as flight:
            with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
                watcher = FlightWatcher(bus)
                deadline = time.monotonic() + 180
                while not (watcher.status and watcher.status["leg"] >= 1) and time.monotonic() < deadline:
                    time.sleep(0.05)
                t_start = time.monotonic()
                sent = storm(bus, rate_hz, seconds)
                achieved_hz = sent / (time.monotonic() - t_start)
                flight.companion.wait(300)
        summary = last_json_line(flight.log) or {}
        jitter = next((e for e in load_record(flight.record).events if e.get("name") == "setpoint_jitter"), {})
        return {
            "sent": sent,
            "rate_hz": round(achieved_hz, 1),
            "received": summary.get("threat_updates"),
            "lost": sent - (summary.get("threat_updates") or 0),
            "outcome": summary.get("outcome"),
            "jitter_p50_ms": jitter.get("p50_ms"),
            "jitter_p99_ms": jitter.get("p99_ms"),
            "jitter_max_ms": jitter.get("max_ms"),
            "rms_tracking_error_m": summary.get("rms_tracking_error_m"),
        }


def table(r: dict, seconds: float) -> str:
    return "\n".join(
        [
            f"Storm of {r['sent']} threat PUTs over {seconds:g} s ({r['rate_hz']} per s) into a flying "
            f"companion (real processes, zenoh on loopback TCP, SITL at {SPEEDUP:g}x); goals: none lost, "
            "setpoint jitter p99 <= 5 ms, the flight completes.",
            "",
            "| sent | received by the companion | lost | setpoint jitter p50 / p99 / max (ms) | RMS tracking error (m) | outcome |",
            "|---|---|---|---|---|---|",
            f"| {r['sent']} | {r['received']} | {r['lost']} | {r['jitter_p50_ms']:.2f} / {r['jitter_p99_ms']:.2f} / "
            f"{r['jitter_max_ms']:.2f} | {r['rms_tracking_error_m']:.3f} | {r['outcome']} |",
        ]
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s of storm instead of 10")
    parser.add_argument("--rate", type=float, default=1000.0, help="updates per second")
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    seconds = 2.0 if args.quick else args.seconds
    result = run(args.rate, seconds)
    text = table(result, seconds)
    print(text)
    bench = REPO / "out" / "bench"
    bench.mkdir(parents=True, exist_ok=True)
    (bench / "threat_storm.json").write_text(json.dumps(result, indent=2))
    (REPO / "docs" / "benchmarks" / "threat_storm.md").write_text("# Threat storm during a flight\n\n" + text + "\n")
    return 0 if result["lost"] == 0 and result["outcome"] == "completed" else 1


if __name__ == "__main__":
    sys.exit(main())
