"""``companion demo``: a SITL flight with threats, in separate processes, on the defaults."""

from __future__ import annotations

import argparse

import numpy as np


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="fly the demo: SITL helicopter, companion and threats (make demo)",
        description="Start a sim-vehicle and a companion run on free ports, fly "
        "the demo mission (exclusion_zones.plan, shipped in the package) and inject threats over zenoh from this process: "
        "a threat coming head-on at 3 m/s (an evasion), a pop-up on the path once M-GART "
        "alternatives are ready (a switch) and an invalid payload (rejected). Prints the "
        "decisions, latencies, the longest way back to the mission, minimum separation and "
        "tracking error, and writes the report. A ground station on udp 14550 can watch.",
        epilog="Example: companion demo --out out/demo --speedup 4",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="out/demo", help="directory for logs, record and report")
    p.add_argument("--speedup", type=float, default=4.0, help="simulation speed-up (default 4)")
    p.add_argument("--no-gcs", action="store_true", help="do not send telemetry to udp 14550")
    p.set_defaults(func=run)


#: What the demo needs beyond a flight: its MCAP record and report, its progress on the terminal.
DEMO_NEEDS = (("view", "foxglove"), ("view", "mcap"), ("report", "matplotlib"), ("report", "rich"))


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from companion.extras import require

    for extra, module in DEMO_NEEDS:
        require(extra, module)
    from companion.demo import DEMO_RECORD, run_demo
    from companion.errors import CompanionError
    from companion.progress import FlightProgress
    from companion.record.report import render_report
    from companion.view.mcap_record import load_flight
    from companion.workers import warm_up

    if not 0.5 <= args.speedup <= 10:
        raise CompanionError(f"--speedup: between 0.5 and 10, got {args.speedup}")
    out = Path(args.out)
    seconds = warm_up()  # compiles the planners' kernels once per machine (about 20 s)
    print(f"demo: planners ready in {seconds:.1f} s; flying exclusion_zones.plan at {args.speedup:g}x; logs in {out}")
    with FlightProgress(title="demo") as progress:
        summary = run_demo(
            out, speedup=args.speedup, gcs_out=None if args.no_gcs else "127.0.0.1:14550", listener=progress
        )
    summary.pop("events")
    record = load_flight(out / DEMO_RECORD)
    ratios = detour_ratios(record)
    if ratios:
        print(f"longest way back to the mission: {max(ratios):.2f} x the direct distance ({len(ratios)} new paths)")
    print(
        f"legs reached {summary['legs_reached']}/{summary['legs_planned']}, landed {summary['landed']}, "
        f"RMS tracking error {summary['rms_tracking_error_m']:.2f} m "
        f"(max {summary['max_tracking_error_m']:.2f} m), "
        + (
            "no threat met"
            if summary["min_threat_separation_m"] is None
            else f"minimum threat separation {summary['min_threat_separation_m']:.2f} m"
        )
    )
    for path in render_report(record, out / "report"):
        print(f"  wrote {path}")
    return 0 if summary["outcome"] == "completed" else 1


def detour_ratios(record) -> list[float]:
    """Length of every new path that leads to a leg's goal (switch, replan) over the straight
    distance from its start to that goal."""
    out = []
    for d in record.decisions:
        path = d.get("path_ned_m")
        if d.get("kind") not in ("switch", "replan") or not path or len(path) < 2:
            continue
        path = np.asarray(path, dtype=float)
        direct = float(np.linalg.norm(path[-1] - path[0]))
        if direct > 1.0:
            out.append(float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))) / direct)
    return out
