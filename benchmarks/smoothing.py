"""Smoothing benchmark (issues 4 and 13): G1, G2, time-parameterisation and the feasibility check.

Goals: G1 and G2 of a 100-node path and its time-parameterisation <= 2 ms each; the
closed-loop feasibility check of a 60 s trajectory <= 100 ms.

Two sets of 100-node polylines, seeded (``numpy.random.default_rng(seed)``), in 2D and 3D:

- ``walk``: random walks, segments of 10-30 m, heading changes uniform in +-90 deg (3D: climb
  angles in +-20 deg);
- ``sharp``: random sharp turns, segments of 2-40 m, turn angles uniform in [0, 170] deg (2D:
  to either side; 3D: about an axis drawn uniformly around the incoming direction). With
  K_max 0.1 1/m most of their G2 corners cannot get the spiral size they need (reported in
  the curve's notes, which are formatted on first read).

Each smoother is timed ``--repeat`` times on every seed; the table gives the median and the
95th percentile of the wall time and the median of the process CPU time
(``time.process_time``: the machine may be shared, and CPU time is less sensitive to load).
``--baseline REF`` also times the smoothers of git revision REF (its ``companion`` package,
extracted to a temporary directory), alternating subprocesses of both trees, and shows both
side by side. Time-parameterisation is timed on a freshly smoothed curve each time (nothing
cached). The feasibility check includes sampling the trajectory at 50 Hz and the closed-loop
prediction on the default R-50-class model (its LQI design is done once, before timing, as
the daemon does).

Usage::

    .venv/bin/python benchmarks/smoothing.py [--quick] [--seeds N] [--repeat N] [--baseline REF]

Prints a table, writes ``out/bench/smoothing.json`` and ``docs/benchmarks/smoothing.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
# ``--tree DIR`` (used by ``--baseline``) imports ``companion`` from another checkout.
_TREE = sys.argv[sys.argv.index("--tree") + 1] if "--tree" in sys.argv[:-1] else str(REPO)
sys.path.insert(0, _TREE)

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


def sharp_turns(rng: np.random.Generator, nodes: int, dim: int, max_turn_deg: float = 170.0) -> np.ndarray:
    """A polyline of ``nodes`` nodes, segments 2-40 m, turn angles uniform in [0, max_turn_deg].

    2D turns go to either side at random; a 3D turn rotates the direction about an axis drawn
    uniformly around it (perpendicular to the incoming direction).
    """
    seg = rng.uniform(2.0, 40.0, nodes - 1)
    turn = np.radians(rng.uniform(0.0, max_turn_deg, nodes - 2))
    if dim == 2:
        heading = np.concatenate([[0.0], np.cumsum(rng.choice([-1.0, 1.0], nodes - 2) * turn)])
        direction = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    else:
        direction = np.zeros((nodes - 1, 3))
        first = rng.normal(size=3)
        direction[0] = first / np.linalg.norm(first)
        for i in range(1, nodes - 1):
            axis = rng.normal(size=3)
            axis -= axis.dot(direction[i - 1]) * direction[i - 1]
            axis /= np.linalg.norm(axis)
            direction[i] = np.cos(turn[i - 1]) * direction[i - 1] + np.sin(turn[i - 1]) * axis
    return np.vstack([np.zeros(dim), np.cumsum(seg[:, None] * direction, axis=0)])


SETS = {"walk": random_walk, "sharp": sharp_turns}
SMOOTHERS = {"g1": lambda path: smooth_g1(path), "g2": lambda path: smooth_g2(path, KAPPA_MAX_1_M)}


def timed_cpu(fn, repeat: int) -> tuple[list[float], list[float]]:
    """Wall and process CPU times (ms) of ``repeat`` calls of ``fn`` (after one warm-up call)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        c0 = time.process_time()
        t0 = time.perf_counter()
        fn()
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return wall, cpu


def time_smoothers(seeds: int, repeat: int) -> dict[str, dict[str, list[float]]]:
    """Samples {"<set>_<g1|g2>_<d>d": {"wall": [...], "cpu": [...]}} on 100-node paths."""
    out: dict[str, dict[str, list[float]]] = {}
    for set_name, make in SETS.items():
        for dim in (2, 3):
            for seed in range(seeds):
                path = make(np.random.default_rng(seed), 100, dim)
                for name, smooth in SMOOTHERS.items():
                    wall, cpu = timed_cpu(lambda: smooth(path), repeat)
                    row = out.setdefault(f"{set_name}_{name}_{dim}d", {"wall": [], "cpu": []})
                    row["wall"] += wall
                    row["cpu"] += cpu
    return out


def summarise(samples: dict[str, list[float]]) -> dict[str, float]:
    wall = np.asarray(samples["wall"])
    return {
        "median_ms": float(np.median(wall)),
        "p95_ms": float(np.percentile(wall, 95)),
        "min_ms": float(wall.min()),
        "cpu_median_ms": float(np.median(samples["cpu"])),
        "n": int(wall.size),
    }


def smoother_rows(seeds: int, repeat: int, baseline: str | None, rounds: int = 2) -> dict:
    """Smoother timings of this tree and, with ``baseline``, of that git revision too.

    Both trees run in subprocesses, alternately, ``rounds`` times each, so that they share the
    machine's load; without a baseline the rows are timed in this process.
    """
    if baseline is None:
        return {"current": {k: summarise(v) for k, v in time_smoothers(seeds, repeat).items()}}
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "archive", baseline, "companion", "heli_common"], cwd=REPO, check=True, capture_output=True
        ).stdout
        with tarfile.open(fileobj=__import__("io").BytesIO(archive)) as tar:
            tar.extractall(tmp, filter="data")
        pooled: dict[str, dict] = {"baseline": {}, "current": {}}
        for _ in range(rounds):
            for label, tree in (("baseline", tmp), ("current", str(REPO))):
                cmd = [
                    sys.executable,
                    __file__,
                    "--smoothers-json",
                    "--tree",
                    tree,
                    "--seeds",
                    str(seeds),
                    "--repeat",
                    str(max(1, repeat // rounds)),
                ]
                env = {**os.environ, "PYTHONPATH": tree}
                res = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout)
                for key, samples in res.items():
                    row = pooled[label].setdefault(key, {"wall": [], "cpu": []})
                    row["wall"] += samples["wall"]
                    row["cpu"] += samples["cpu"]
    return {label: {k: summarise(v) for k, v in rows.items()} for label, rows in pooled.items()}


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


def run(seeds: int, repeat: int, baseline: str | None = None) -> dict:
    smoothers = smoother_rows(seeds, repeat, baseline)
    checker = FeasibilityChecker()
    rows: dict[str, dict] = {}
    samples: dict[str, list[float]] = {}
    extra: dict[str, list[float]] = {
        "pieces_g2": [],
        "length_m": [],
        "duration_s": [],
        "traj60_s": [],
        "max_abs_delta": [],
        "max_error_m": [],
    }
    for dim in (2, 3):
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            path = random_walk(rng, 100, dim)
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
                timed(lambda: traj.sample(np.array([traj.duration_s / 3])), repeat * 10)
            )
            t3000 = np.linspace(0.0, traj.duration_s, 3000)
            samples.setdefault(f"sample3000_{dim}d", []).extend(timed(lambda: traj.sample(t3000), repeat))
            if dim == 2:
                traj60 = path_of_duration(np.random.default_rng(1000 + seed), 60.0)
                extra["traj60_s"].append(traj60.duration_s)
                samples.setdefault("feasibility_60s", []).extend(
                    timed(lambda: checker.check(traj60), max(1, repeat // 2))
                )
                report = checker.check(traj60)
                extra["max_abs_delta"].append(report.max_abs_delta)
                extra["max_error_m"].append(report.max_tracking_error_m)
    aggressive = TrajectoryLimits(speed_m_s=15.0, accel_m_s2=5.0, lat_accel_m_s2=6.0, jerk_m_s3=20.0)
    fast = time_parameterize(smooth_g2(random_walk(np.random.default_rng(7), 12, 2), KAPPA_MAX_1_M), aggressive)
    stretch = checker.check_and_stretch(fast)
    for name, vals in samples.items():
        rows[name] = {"median_ms": statistics.median(vals), "min_ms": min(vals), "n": len(vals)}
    return {
        "smoothers": smoothers,
        "baseline": baseline,
        "rows": rows,
        "extra": {k: (statistics.median(v) if v else None) for k, v in extra.items()},
        "stretch_example": {
            "initial_max_abs_delta": stretch.initial_max_abs_delta,
            "stretch": stretch.stretch,
            "attempts": stretch.attempts,
            "final_max_abs_delta": stretch.max_abs_delta,
            "feasible": stretch.feasible,
            "elapsed_ms": stretch.elapsed_s * 1e3,
            "duration_s": [fast.duration_s, stretch.trajectory.duration_s],
        },
        "seeds": seeds,
        "repeat": repeat,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }


LABELS = [
    ("timing_2d", "time_parameterize, 100-node G2 curve, 2D", "timing"),
    ("timing_3d", "time_parameterize, 100-node G2 curve, 3D", "timing"),
    ("timing_g1_2d", "time_parameterize, 100-node G1 curve, 2D (peak search)", None),
    ("feasibility_60s", "feasibility check, 60 s trajectory (50 Hz, default model)", "feasibility_60s"),
    ("sample1_2d", "Trajectory.sample, 1 time (the 50 Hz setpoint)", None),
    ("sample3000_2d", "Trajectory.sample, 3000 times", None),
]
SMOOTHER_LABELS = {"g1": "G1 (quartic midpoint)", "g2": "G2 (cubic spiral pairs)"}


def smoother_table(result: dict) -> list[str]:
    """Rows of the smoother table: set, smoother, dimension; median / p95 wall, median CPU."""
    sm = result["smoothers"]
    trees = [t for t in ("baseline", "current") if t in sm]
    names = {"baseline": f"before ({result['baseline']})", "current": "after" if len(trees) > 1 else "this tree"}
    head = (
        "| set | smoother, 100 nodes | "
        + " | ".join(f"{names[t]}: median / p95 wall, median CPU (ms)" for t in trees)
        + " | goal (ms) | met |"
    )
    lines = [head, "|" + "---|" * (4 + len(trees))]
    for key in sm["current"]:
        set_name, alg, dim = key.split("_")
        cells = [
            f"{sm[t][key]['median_ms']:.3f} / {sm[t][key]['p95_ms']:.3f}, {sm[t][key]['cpu_median_ms']:.3f}"
            for t in trees
        ]
        cur = sm["current"][key]
        met = (
            "yes"
            if max(cur["median_ms"], cur["cpu_median_ms"]) <= GOALS_MS[alg]
            else ("CPU only" if cur["cpu_median_ms"] <= GOALS_MS[alg] else "no")
        )
        lines.append(
            f"| {set_name} | {SMOOTHER_LABELS[alg]}, {dim.upper()} | "
            + " | ".join(cells)
            + f" | <= {GOALS_MS[alg]:g} | {met} |"
        )
    return lines


def table(result: dict) -> str:
    rows = result["rows"]
    ex = result["extra"]
    n = result["smoothers"]["current"]["walk_g1_2d"]["n"]
    lines = [
        f"Smoothers, K_max {KAPPA_MAX_1_M} 1/m (G2); sets `walk` (heading changes within +-90 deg, "
        f"segments 10-30 m) and `sharp` (turns uniform in [0, 170] deg, segments 2-40 m); "
        f"{result['seeds']} seeds x 2D/3D, {n} timed calls per row and tree",
        "",
    ]
    lines += smoother_table(result)
    if result.get("baseline"):
        lines += [
            "",
            f"`before` is revision {result['baseline']}, `after` this tree; both were timed in the same "
            "run, in subprocesses that alternate (two rounds each), on the same paths. 'met' asks for "
            "the median wall and CPU times of `after` within the goal ('CPU only': the wall time "
            "was not, under the machine's load).",
        ]
    lines += [
        "",
        f"Time-parameterisation and checks, default limits; {result['seeds']} seeds x "
        f"{result['repeat']} repeats (median / min over all runs)",
        "",
        "| operation | median (ms) | min (ms) | goal (ms) |",
        "|---|---|---|---|",
    ]
    for key, label, goal in LABELS:
        if key in rows:
            r = rows[key]
            g = f"<= {GOALS_MS[goal]:g}" if goal else "-"
            lines.append(f"| {label} | {r['median_ms']:.3f} | {r['min_ms']:.3f} | {g} |")
    st = result["stretch_example"]
    lines += [
        "",
        f"100-node `walk` paths: {ex['length_m']:.0f} m, {ex['pieces_g2']:.0f} G2 pieces, "
        f"{ex['duration_s']:.0f} s at the default limits (medians).",
        f"60 s trajectories ({ex['traj60_s']:.1f} s): max |delta| {ex['max_abs_delta']:.2f}, max "
        f"tracking error {ex['max_error_m']:.2f} m (medians; feasible below 0.8 and 2 m).",
        f"Aggressive limits (15 m/s, 5 m/s^2, 6 m/s^2 lateral, 20 m/s^3): max |delta| "
        f"{st['initial_max_abs_delta']:.2f} (saturated); stretched x{st['stretch']:.2f} in "
        f"{st['attempts']} simulations ({st['elapsed_ms']:.0f} ms) to max |delta| "
        f"{st['final_max_abs_delta']:.2f}, {st['duration_s'][0]:.1f} s -> {st['duration_s'][1]:.1f} s.",
        f"Machine load (1-min average) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the end "
        f"of the run; Python {result['python']}.",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 seeds, 5 repeats")
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--repeat", type=int, default=None)
    ap.add_argument(
        "--baseline", default=None, metavar="REF", help="also time the smoothers of git revision REF, side by side"
    )
    ap.add_argument("--tree", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--smoothers-json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    seeds = args.seeds or (2 if args.quick else 5)
    repeat = args.repeat or (5 if args.quick else 20)
    if args.smoothers_json:  # one tree's raw smoother samples, for --baseline
        print(json.dumps(time_smoothers(seeds, repeat)))
        return 0
    result = run(seeds, repeat, args.baseline)
    text = table(result)
    print(text)
    out = REPO / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing.json").write_text(json.dumps(result, indent=2))
    doc = REPO / "docs" / "benchmarks" / "smoothing.md"
    doc.parent.mkdir(parents=True, exist_ok=True)
    cmd = "`.venv/bin/python benchmarks/smoothing.py" + (f" --baseline {args.baseline}`" if args.baseline else "`")
    doc.write_text("# Smoothing benchmark\n\n" + cmd + "\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
