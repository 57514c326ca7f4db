"""``companion report RECORD --out DIR``: render a flight record as PNG plots."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="render a flight record as plots",
        description="Render a flight record (JSON Lines written by 'companion run --record') "
        "as PNG plots: flown path over obstacles with trees and alternatives, tracking error, "
        "actuator inputs; and a summary.json.",
        epilog="Example: companion report out/flight.jsonl --out out/report",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("record", help="flight record file (.mcap, or the JSON Lines .jsonl)")
    p.add_argument("--out", required=True, help="output directory for the plots")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from companion.extras import require
    from companion.record.report import render_report
    from companion.view.mcap_record import load_flight

    require("report", "matplotlib")  # before reading the record

    for path in render_report(load_flight(args.record), args.out):
        print(path)
        if path.name == "summary.txt":
            print(path.read_text(), end="")
    return 0
