"""Smoothing benchmark (issue 4): G1, G2, time-parameterisation and the feasibility check.

Goals: G1 and G2 of a 100-node path and its time-parameterisation <= 2 ms each; the
closed-loop feasibility check of a 60 s trajectory <= 100 ms.

Paths are seeded random walks (``numpy.random.default_rng(seed)``): segments of 10-30 m,
heading changes uniform in +-90 deg (3D: climb angles in +-20 deg). Each operation is timed
``--repeat`` times on every seed; the table gives the median and the minimum (the machine may
be shared: the minimum is the cost without interference). Time-parameterisation is timed on a
freshly smoothed curve each time (nothing cached). The feasibility check includes sampling the
trajectory at 50 Hz and the closed-loop prediction on the default R-50-class model (its LQI
design is done once, before timing, as the daemon does).

Usage::

    .venv/bin/python benchmarks/smoothing.py [--quick] [--seeds N] [--repeat N]

Prints a table, writes ``out/bench/smoothing.json`` and ``docs/benchmarks/smoothing.md``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from companion.smoothing import TrajectoryLimits, smooth_g1, smooth_g2, time_parameterize  # noqa: E402
from companion.smoothing.feasibility import FeasibilityChecker  # noqa: E402

KAPPA_MAX_1_M = 0.1
GOALS_MS = {"g1": 2.0, "g2": 2.0, "timing": 2.0, "feasibility_60s": 100.0}


def random_walk(rng: np.random.Generator, nodes: int, dim: int) -> np.ndarray:
    """A polyline of ``nodes`` nodes, segments 10-30 m, turns within +-90 deg."""
    pts = [np.zeros(dim)]
    heading = 0.0
    for _ in range(nodes - 1):
        heading += rng.uniform(-np.pi / 2, np.pi / 2)
        length = rng.uniform(10.0, 30.0)
        step = np.zeros(dim)
        if dim == 3:
            climb = rng.uniform(-np.radians(20), np.radians(20))
            step[:] = [np.cos(heading) * np.cos(climb), np.sin(heading) * np.cos(climb), -np.sin(climb)]
        else:
            step[:] = [np.cos(heading), np.sin(heading)]
        pts.append(pts[-1] + length * step)
    return np.array(pts)


def path_of_duration(rng: np.random.Generator, target_s: float, dim: int = 2):
    """A G2 trajectory of about ``target_s`` seconds at the default limits."""
    nodes = 4
    while True:
        traj = time_parameterize(smooth_g2(random_walk(rng, nodes, dim), KAPPA_MAX_1_M))
        if traj.duration_s >= target_s:
            return traj
        nodes += 1


def timed(fn, repeat: int) -> list[float]:
    fn()
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def run(seeds: int, repeat: int) -> dict:
    checker = FeasibilityChecker()
    rows: dict[str, dict] = {}
    samples: dict[str, list[float]] = {}
    extra: dict[str, list[float]] = {"pieces_g2": [], "length_m": [], "duration_s": [], "traj60_s": [],
                                     "max_abs_delta": [], "max_error_m": []}
    for dim in (2, 3):
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            path = random_walk(rng, 100, dim)
            samples.setdefault(f"g1_{dim}d", []).extend(timed(lambda: smooth_g1(path), repeat))
            samples.setdefault(f"g2_{dim}d", []).extend(timed(lambda: smooth_g2(path, KAPPA_MAX_1_M), repeat))
            curves = [smooth_g2(path, KAPPA_MAX_1_M) for _ in range(repeat + 1)]
            it = iter(curves)
            samples.setdefault(f"timing_{dim}d", []).extend(timed(lambda: time_parameterize(next(it)), repeat))
            g1_curves = [smooth_g1(path) for _ in range(repeat + 1)]
            it1 = iter(g1_curves)
            samples.setdefault(f"timing_g1_{dim}d", []).extend(timed(lambda: time_parameterize(next(it1)), repeat))
            traj = time_parameterize(curves[0])
            extra["pieces_g2"].append(len(curves[0].pieces))
            extra["length_m"].append(curves[0].length_m)
            extra["duration_s"].append(traj.duration_s)
            samples.setdefault(f"sample1_{dim}d", []).extend(
                timed(lambda: traj.sample(np.array([traj.duration_s / 3])), repeat * 10))
            t3000 = np.linspace(0.0, traj.duration_s, 3000)
            samples.setdefault(f"sample3000_{dim}d", []).extend(timed(lambda: traj.sample(t3000), repeat))
            if dim == 2:
                traj60 = path_of_duration(np.random.default_rng(1000 + seed), 60.0)
                extra["traj60_s"].append(traj60.duration_s)
                samples.setdefault("feasibility_60s", []).extend(timed(lambda: checker.check(traj60),
                                                                       max(1, repeat // 2)))
                report = checker.check(traj60)
                extra["max_abs_delta"].append(report.max_abs_delta)
                extra["max_error_m"].append(report.max_tracking_error_m)
    aggressive = TrajectoryLimits(speed_m_s=15.0, accel_m_s2=5.0, lat_accel_m_s2=6.0, jerk_m_s3=20.0)
    fast = time_parameterize(smooth_g2(random_walk(np.random.default_rng(7), 12, 2), KAPPA_MAX_1_M), aggressive)
    stretch = checker.check_and_stretch(fast)
    for name, vals in samples.items():
        rows[name] = {"median_ms": statistics.median(vals), "min_ms": min(vals), "n": len(vals)}
    return {"rows": rows, "extra": {k: (statistics.median(v) if v else None) for k, v in extra.items()},
            "stretch_example": {"initial_max_abs_delta": stretch.initial_max_abs_delta,
                                "stretch": stretch.stretch, "attempts": stretch.attempts,
                                "final_max_abs_delta": stretch.max_abs_delta, "feasible": stretch.feasible,
                                "elapsed_ms": stretch.elapsed_s * 1e3,
                                "duration_s": [fast.duration_s, stretch.trajectory.duration_s]},
            "seeds": seeds, "repeat": repeat, "python": platform.python_version(),
            "machine": platform.machine()}


LABELS = [
    ("g1_2d", "G1 (quartic midpoint), 100 nodes, 2D", "g1"),
    ("g1_3d", "G1, 100 nodes, 3D", "g1"),
    ("g2_2d", "G2 (cubic spiral pairs), 100 nodes, 2D", "g2"),
    ("g2_3d", "G2, 100 nodes, 3D", "g2"),
    ("timing_2d", "time_parameterize, 100-node G2 curve, 2D", "timing"),
    ("timing_3d", "time_parameterize, 100-node G2 curve, 3D", "timing"),
    ("timing_g1_2d", "time_parameterize, 100-node G1 curve, 2D (peak search)", None),
    ("feasibility_60s", "feasibility check, 60 s trajectory (50 Hz, default model)", "feasibility_60s"),
    ("sample1_2d", "Trajectory.sample, 1 time (the 50 Hz setpoint)", None),
    ("sample3000_2d", "Trajectory.sample, 3000 times", None),
]


def table(result: dict) -> str:
    rows = result["rows"]
    ex = result["extra"]
    lines = [f"Smoothing and timing, K_max {KAPPA_MAX_1_M} 1/m, default limits; {result['seeds']} seeds x "
             f"{result['repeat']} repeats (median / min over all runs)", "",
             "| operation | median (ms) | min (ms) | goal (ms) |", "|---|---|---|---|"]
    for key, label, goal in LABELS:
        if key in rows:
            r = rows[key]
            g = f"<= {GOALS_MS[goal]:g}" if goal else "-"
            lines.append(f"| {label} | {r['median_ms']:.3f} | {r['min_ms']:.3f} | {g} |")
    st = result["stretch_example"]
    lines += ["",
              f"100-node paths: {ex['length_m']:.0f} m, {ex['pieces_g2']:.0f} G2 pieces, "
              f"{ex['duration_s']:.0f} s at the default limits (medians).",
              f"60 s trajectories ({ex['traj60_s']:.1f} s): max |delta| {ex['max_abs_delta']:.2f}, max "
              f"tracking error {ex['max_error_m']:.2f} m (medians; feasible below 0.8 and 2 m).",
              f"Aggressive limits (15 m/s, 5 m/s^2, 6 m/s^2 lateral, 20 m/s^3): max |delta| "
              f"{st['initial_max_abs_delta']:.2f} (saturated); stretched x{st['stretch']:.2f} in "
              f"{st['attempts']} simulations ({st['elapsed_ms']:.0f} ms) to max |delta| "
              f"{st['final_max_abs_delta']:.2f}, {st['duration_s'][0]:.1f} s -> {st['duration_s'][1]:.1f} s."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 seeds, 5 repeats")
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--repeat", type=int, default=None)
    args = ap.parse_args(argv)
    seeds = args.seeds or (2 if args.quick else 5)
    repeat = args.repeat or (5 if args.quick else 20)
    result = run(seeds, repeat)
    text = table(result)
    print(text)
    out = REPO / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing.json").write_text(json.dumps(result, indent=2))
    doc = REPO / "docs" / "benchmarks" / "smoothing.md"
    doc.parent.mkdir(parents=True, exist_ok=True)
    doc.write_text("# Smoothing benchmark\n\n`.venv/bin/python benchmarks/smoothing.py`\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
