"""Run every benchmark, one after the other, and rebuild ``docs/BENCHMARKS.md``.

Each benchmark prints its table, writes ``out/bench/<name>.json`` and its markdown table to
``docs/benchmarks/<name>.md``; this script runs them in sequence (never in parallel: they
measure time) and concatenates the tables, with the machine they ran on, into
``docs/BENCHMARKS.md``, and rewrites the README's "Benchmarks at a glance" from them
(``benchmarks/headlines.py``).

Usage::

    make bench                                    # everything (tens of minutes)
    .venv/bin/python benchmarks/run_all.py --quick
    .venv/bin/python benchmarks/run_all.py --only planning smoothing
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path

import headlines
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

REPO = Path(__file__).resolve().parents[1]

#: name -> extra arguments; the order is the order of docs/BENCHMARKS.md.
BENCHMARKS = {
    "planning": [],
    "smoothing": [],
    "sitl_realtime": [],
    "setpoint_jitter": ["--sitl"],
    "view_lag": [],
    "companion_cpu": ["--speedup", "1"],
    "flight_tracking": [],
    "threats": [],
    "threats_sitl": [],
    "threat_storm": [],
    "soak": [],
    "fleet": [],
}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def run(name: str, quick: bool) -> bool:
    cmd = [sys.executable, str(REPO / "benchmarks" / f"{name}.py"), *BENCHMARKS[name]]
    if quick:
        cmd.append("--quick")
    print(f"\n=== {name}: {' '.join(cmd[1:])}", flush=True)
    return subprocess.run(cmd, cwd=str(REPO)).returncode == 0


def assemble() -> str:
    parts = [
        "# Benchmarks",
        "",
        f"Latest run: {datetime.date.today().isoformat()} on {machine()}. Every table compares "
        "side by side in one run; absolute times drift between machines. Regenerate with "
        "`make bench` (or `.venv/bin/python benchmarks/run_all.py`).",
        "",
    ]
    for name in BENCHMARKS:
        path = REPO / "docs" / "benchmarks" / f"{name}.md"
        if path.exists():
            text = path.read_text().strip()
            if text.startswith("# "):
                text = "#" + text  # one level down
            parts += [text, ""]
        notes = REPO / "docs" / "benchmarks" / f"{name}.notes.md"  # hand-written: analysis, history
        if notes.exists():
            parts += [notes.read_text().strip(), ""]
    return "\n".join(parts)


def main() -> int:
    parser = argparse.ArgumentParser(description="Run the benchmarks and rebuild docs/BENCHMARKS.md")
    parser.add_argument("--quick", action="store_true", help="the fast version of each benchmark")
    parser.add_argument("--only", nargs="+", choices=sorted(BENCHMARKS), help="run only these")
    parser.add_argument(
        "--assemble-only",
        action="store_true",
        help="only rebuild docs/BENCHMARKS.md and the README's figures from docs/benchmarks/*.md",
    )
    args = parser.parse_args()
    failed = []
    if not args.assemble_only:
        names = args.only or list(BENCHMARKS)
        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=Console(stderr=True),
        ) as progress:
            task = progress.add_task("benchmarks", total=len(names))
            for name in names:
                progress.update(task, description=f"benchmark {name}")
                if not run(name, args.quick):
                    failed.append(name)
                progress.advance(task)
    (REPO / "docs" / "BENCHMARKS.md").write_text(assemble())
    headlines.write_readme()
    print(f"\nwrote docs/BENCHMARKS.md and README.md's figures{'; failed: ' + ', '.join(failed) if failed else ''}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
