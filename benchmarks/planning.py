"""Planning benchmark: GART and M-GART side by side with OMPL on the public worlds of ANCHORS.md.

Worlds ``2d`` and ``3d_dense`` (benchmarks/worlds.py), seeds 0-19 (``--quick``: 0-4 and shorter
budgets). For each planner, medians over the seeds of: success, time to the first path,
iterations at the first path, first cost, cost at 0.1 / 0.5 / 1 s as a percentage above the best
known cost (ANCHORS.md: 142.2 on 2d, 171.9 on 3d_dense), iterations per second; for M-GART the
wall and CPU time to eight distinct paths (median, p95 and maximum over the seeds). Costs are path lengths (``CostWeights.length_only()``, what OMPL's
planners minimise). GART's returned path is shortcut (a separate step, like OMPL's simplifier,
which the OMPL runs here do not use); the "first cost" column shows GART's raw tree path.

OMPL (PyPI ``ompl`` 2.x): RRT* (range 28.3 m, as in the anchors), Informed RRT*, BIT*, RRTConnect,
validity callback = ``World.point_free`` (Python), OMPL's default sampled motion checking
(resolution 1 % of the space extent); our planners check segments exactly. The "exact-valid"
column counts paths that pass the exact segment check.

The machine may be shared while this runs: absolute times are noisy, compare side by side.

Usage: ``python benchmarks/planning.py [--quick] [--seeds N] [--worlds 2d,3d_dense]``; prints a
table, writes ``out/bench/planning.json`` and ``docs/benchmarks/planning.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.worlds import BEST_KNOWN_COST, BenchWorld, make_world  # noqa: E402
from companion.planning import CostWeights, GartSettings, MgartSettings, gart, hausdorff_m, mgart  # noqa: E402

OMPL_PLANNERS = ("RRTstar", "InformedRRTstar", "BITstar", "RRTConnect")
OMPL_RANGE_M = 28.3
FIRST_TIMEOUT_S = 5.0
MGART_K = 8
MGART_TIMEOUT_S = 5.0
#: GART's first path without the shortcut step: OMPL's rows time ``solve`` alone (no simplifier)
RAW_ROW = "GART, tree path without shortcut (first path only)"


# ---------------------------------------------------------------------- GART / M-GART
def warm_up(settings: GartSettings) -> dict:
    """GART and M-GART runs per dimension before the measurements: the numba kernels' one-off cost.

    With ``cache=True`` the kernels compile once per machine (numba's cache, beside the modules)
    and later processes only load them; either way it happens at the first call in a process,
    which is kept out of the per-plan figures and reported here.
    """
    cpu0, t0 = time.process_time(), time.perf_counter()
    for name in ("2d", "3d_dense"):
        bw = make_world(name, 0)
        gart(
            bw.world,
            bw.start,
            bw.goal,
            rng=np.random.default_rng(0),
            stop_at_first=True,
            max_time_s=60.0,
            settings=settings,
        )  # to a path: every kernel of the call, the shortcut's too
        mgart(
            bw.world,
            bw.start,
            bw.goal,
            2,
            rng=np.random.default_rng(0),
            max_time_s=60.0,
            settings=MgartSettings(gart=settings),
        )  # and M-GART's distinctness test
    return {"cpu_ms": 1e3 * (time.process_time() - cpu0), "wall_ms": 1e3 * (time.perf_counter() - t0)}


def run_gart(bw: BenchWorld, budgets: tuple, settings: GartSettings, anytime: bool = True) -> dict:
    """First-path and anytime runs of GART on one world."""
    cpu0 = time.process_time()
    first = gart(
        bw.world,
        bw.start,
        bw.goal,
        rng=np.random.default_rng(bw.seed),
        stop_at_first=True,
        max_time_s=FIRST_TIMEOUT_S,
        settings=settings,
    )
    cpu_ms = 1e3 * (time.process_time() - cpu0)
    out = {"solved": first.solved, "exact_valid": first.solved and bw.world.path_free(first.path)}
    if first.solved:
        out.update(
            first_ms=1e3 * first.time_to_first_s,
            first_cpu_ms=cpu_ms,
            iterations_first=first.iterations,
            first_cost=first.cost_history[0][1],
            first_cost_shortcut=first.cost,
        )
    if anytime:
        for t in budgets:
            r = gart(bw.world, bw.start, bw.goal, rng=np.random.default_rng(bw.seed), max_time_s=t, settings=settings)
            out[f"cost_{t}"] = r.cost if r.solved else None
            out[f"iters_per_s_{t}"] = r.iterations / r.elapsed_s
            out["exact_valid"] = out["exact_valid"] and (not r.solved or bw.world.path_free(r.path))
    return out


def run_mgart(bw: BenchWorld, settings: MgartSettings) -> dict:
    """Time to eight distinct M-GART paths on one world."""
    cpu0 = time.process_time()
    res = mgart(
        bw.world,
        bw.start,
        bw.goal,
        MGART_K,
        rng=np.random.default_rng(bw.seed),
        max_time_s=MGART_TIMEOUT_S,
        settings=settings,
    )
    cpu_ms = 1e3 * (time.process_time() - cpu0)
    paths = [r for r in res if r.solved]
    distinct = all(
        hausdorff_m(a.path, b.path, settings.separation_sample_m) >= settings.min_separation_m
        for i, a in enumerate(paths)
        for b in paths[i + 1 :]
    )
    valid = all(bw.world.path_free(r.path) for r in paths)
    done = len(paths) == MGART_K
    return {
        "paths": len(paths),
        "distinct": distinct,
        "exact_valid": valid,
        "time_to_k_ms": 1e3 * max(r.time_to_first_s for r in paths) if done else None,
        "cpu_to_k_ms": cpu_ms if done else None,
        "iterations": res[0].iterations,
        "costs": [r.cost for r in paths],
    }


# ---------------------------------------------------------------------- OMPL
class OmplProblem:
    """One OMPL SimpleSetup per world, validity from ``World.point_free``."""

    def __init__(self, bw: BenchWorld):
        from ompl import base as ob
        from ompl import geometric as og

        self.ob, self.og, self.bw = ob, og, bw
        d = bw.world.dim
        space = ob.RealVectorStateSpace(d)
        bounds = ob.RealVectorBounds(d)
        for k in range(d):
            bounds.setLow(k, float(bw.world.bounds_min[k]))
            bounds.setHigh(k, float(bw.world.bounds_max[k]))
        space.setBounds(bounds)
        self.space = space
        self.ss = og.SimpleSetup(space)
        free = bw.world.point_free
        if d == 2:
            self.ss.setStateValidityChecker(lambda s: free((s[0], s[1])))
        else:
            self.ss.setStateValidityChecker(lambda s: free((s[0], s[1], s[2])))
        self.si = self.ss.getSpaceInformation()
        start, goal = space.allocState(), space.allocState()
        for k in range(d):
            start[k] = float(bw.start[k])
            goal[k] = float(bw.goal[k])
        self.ss.setStartAndGoalStates(start, goal)
        self._keep = (start, goal)

    def solve(self, name: str, budget_s: float, first_only: bool) -> dict:
        ob = self.ob
        planner = getattr(self.og, name)(self.si)
        if hasattr(planner, "setRange") and name != "BITstar":
            planner.setRange(OMPL_RANGE_M)
        self.ss.clear()
        self.ss.setPlanner(planner)
        objective = ob.PathLengthOptimizationObjective(self.si)
        objective.setCostThreshold(ob.Cost(math.inf if first_only else 0.0))
        self.ss.setOptimizationObjective(objective)
        self.ss.setup()
        cpu0 = time.process_time()
        t0 = time.perf_counter()
        self.ss.solve(budget_s)
        elapsed = time.perf_counter() - t0
        cpu_s = time.process_time() - cpu0
        if not self.ss.haveExactSolutionPath():
            return {"solved": False, "elapsed_s": elapsed, "cpu_s": cpu_s}
        path = self.ss.getSolutionPath()
        pts = np.array([[path.getState(i)[k] for k in range(self.bw.world.dim)] for i in range(path.getStateCount())])
        iterations = planner.numIterations() if hasattr(planner, "numIterations") else None
        return {
            "solved": True,
            "elapsed_s": elapsed,
            "cpu_s": cpu_s,
            "cost": float(path.length()),
            "iterations": iterations,
            "exact_valid": self.bw.world.path_free(pts),
        }


def run_ompl(problem: OmplProblem, name: str, budgets: tuple) -> dict:
    first = problem.solve(name, FIRST_TIMEOUT_S, first_only=True)
    out = {"solved": first["solved"], "exact_valid": first.get("exact_valid", False)}
    if first["solved"]:
        out.update(
            first_ms=1e3 * first["elapsed_s"],
            first_cpu_ms=1e3 * first["cpu_s"],
            iterations_first=first["iterations"],
            first_cost=first["cost"],
        )
    if name != "RRTConnect":
        for t in budgets:
            r = problem.solve(name, t, first_only=False)
            out[f"cost_{t}"] = r["cost"] if r["solved"] else None
            if r["solved"]:
                out["exact_valid"] = out["exact_valid"] and r["exact_valid"]
            if r.get("iterations") is not None:
                out[f"iters_per_s_{t}"] = r["iterations"] / r["elapsed_s"]
    return out


# ---------------------------------------------------------------------- world queries
def world_query_costs(quick: bool) -> list[dict]:
    """CPU microseconds per query with 30 and 1000 obstacles (same covered fraction), 2D and 3D."""
    import scipy.spatial  # noqa: F401  (imported before timing: clearance_m uses it lazily)

    from companion.world import World

    rows = []
    n_q = 3000 if quick else 20000
    for d in (2, 3):
        for n, r_lo, r_hi in ((30, 3.0, 8.0), (1000, 3.0 * (30 / 1000) ** (1 / d), 8.0 * (30 / 1000) ** (1 / d))):
            rs = np.random.RandomState(0)
            world = World.from_spheres(rs.uniform(0, 100, (n, d)), rs.uniform(r_lo, r_hi, n), [0] * d, [100] * d, 0.5)
            pts = [tuple(p) for p in rs.uniform(0, 100, (n_q, d)).tolist()]
            dirs = rs.normal(size=(n_q, d))
            ends = np.clip(np.array(pts) + 10.0 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True), 0, 100)
            ends = [tuple(p) for p in ends.tolist()]
            free, seg = world.point_free, world.segment_free
            t = time.process_time()
            for p in pts:
                free(p)
            t_point = (time.process_time() - t) / n_q
            t = time.process_time()
            for a, b in zip(pts, ends):
                seg(a, b)
            t_seg = (time.process_time() - t) / n_q
            arr = np.array(pts)
            t = time.process_time()
            world.clearance_m(arr)
            t_clear = (time.process_time() - t) / n_q
            rows.append(
                {
                    "dim": d,
                    "obstacles": n,
                    "point_us": 1e6 * t_point,
                    "segment_10m_us": 1e6 * t_seg,
                    "clearance_batch_us": 1e6 * t_clear,
                }
            )
    return rows


def world_table(rows: list[dict]) -> str:
    lines = [
        "| d | obstacles | point_free (us) | exact segment_free, 10 m (us) | clearance_m batch (us/point) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['dim']} | {r['obstacles']} | {r['point_us']:.2f} | {r['segment_10m_us']:.2f} | "
            f"{r['clearance_batch_us']:.2f} |"
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------- summary
def median_of(runs: list, key: str):
    vals = [r[key] for r in runs if r.get(key) is not None]
    return statistics.median(vals) if vals else None


def summarise(runs: list, budgets: tuple, best: float) -> dict:
    s = {
        "solved": sum(bool(r["solved"]) for r in runs),
        "runs": len(runs),
        "exact_valid": sum(bool(r.get("exact_valid")) for r in runs),
        "first_ms": median_of(runs, "first_ms"),
        "first_cpu_ms": median_of(runs, "first_cpu_ms"),
        "iterations_first": median_of(runs, "iterations_first"),
        "first_cost": median_of(runs, "first_cost"),
    }
    for t in budgets:
        c = median_of(runs, f"cost_{t}")
        s[f"cost_{t}"] = c
        s[f"pct_{t}"] = None if c is None else 100.0 * (c / best - 1.0)
    s["iters_per_s"] = median_of(runs, f"iters_per_s_{budgets[-1]}")
    return s


def fmt(v, spec: str = ".1f", none: str = "-") -> str:
    return none if v is None else format(v, spec)


def table(world: str, summary: dict, budgets: tuple, best: float) -> str:
    head = ["planner", "solved", "first path (ms)", "first path CPU (ms)", "iters at first", "first cost"]
    head += [f"cost @{t} s (% above {best})" for t in budgets] + ["iterations/s", "exact-valid"]
    lines = [f"### {world} (best known {best})", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, s in summary.items():
        row = [
            name,
            f"{s['solved']}/{s['runs']}",
            fmt(s["first_ms"], ".2f"),
            fmt(s["first_cpu_ms"], ".2f"),
            fmt(s["iterations_first"], ".0f"),
            fmt(s["first_cost"]),
        ]
        for t in budgets:
            c, p = s.get(f"cost_{t}"), s.get(f"pct_{t}")
            row.append("-" if c is None else f"{c:.1f} ({p:+.2f} %)")
        row += [fmt(s.get("iters_per_s"), ".0f"), f"{s['exact_valid']}/{s['runs']}"]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def percentile_of(runs: list, key: str, q: float):
    """The ``q`` quantile (0..1, linear interpolation) of ``key`` over ``runs``; None when empty."""
    vals = [r[key] for r in runs if r.get(key) is not None]
    return float(np.quantile(vals, q)) if vals else None


def mgart_table(results: dict) -> str:
    lines = [
        "| world | 8 distinct paths found | time to 8 paths, median / p95 / max (ms) | within 0.5 s | "
        "CPU to 8 paths, median / p95 / max (ms) | CPU within 0.5 s | median iterations | "
        "paths exact-valid and distinct |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for world, runs in results.items():
        done = [r for r in runs if r["paths"] == MGART_K]
        spread = {}
        for key in ("time_to_k_ms", "cpu_to_k_ms"):
            qs = [percentile_of(done, key, q) for q in (0.5, 0.95, 1.0)] if len(done) == len(runs) else [None] * 3
            spread[key] = " / ".join(fmt(v, ".0f") for v in qs)
        within = sum(1 for r in done if r["time_to_k_ms"] <= 500.0)
        within_cpu = sum(1 for r in done if r["cpu_to_k_ms"] <= 500.0)
        ok = sum(1 for r in runs if r["exact_valid"] and r["distinct"])
        lines.append(
            f"| {world} | {len(done)}/{len(runs)} | {spread['time_to_k_ms']} | {within}/{len(runs)} | "
            f"{spread['cpu_to_k_ms']} | {within_cpu}/{len(runs)} | "
            f"{fmt(median_of(runs, 'iterations'), '.0f')} | {ok}/{len(runs)} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="seeds 0-4 and budgets 0.1, 0.5 s")
    ap.add_argument("--seeds", type=int, default=None, help="number of seeds (default 20, quick 5)")
    ap.add_argument("--worlds", default="2d,3d_dense")
    ap.add_argument("--no-ompl", action="store_true", help="skip OMPL (when it is not installed)")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "planning.json"))
    ap.add_argument("--markdown", default=str(ROOT / "docs" / "benchmarks" / "planning.md"))
    args = ap.parse_args(argv)
    n_seeds = args.seeds or (5 if args.quick else 20)
    budgets = (0.1, 0.5) if args.quick else (0.1, 0.5, 1.0)
    worlds = [w.strip() for w in args.worlds.split(",") if w.strip()]
    gs = GartSettings(cost=CostWeights.length_only())
    plain = GartSettings(cost=CostWeights.length_only(), guidance=False)
    raw_path = dataclasses.replace(gs, simplify=dataclasses.replace(gs.simplify, enabled=False))
    ms = MgartSettings(gart=gs)
    use_ompl = not args.no_ompl
    if use_ompl:
        try:
            from ompl import util as ou

            ou.setLogLevel(ou.LogLevel.LOG_ERROR)
            ou.RNG.setSeed(1)
        except ImportError:
            print("ompl is not installed (pip install '.[bench]'): OMPL columns skipped", file=sys.stderr)
            use_ompl = False
    first_call = warm_up(gs)
    print(
        f"first GART and M-GART calls in this process (numba kernels compiled or loaded from the cache): "
        f"{first_call['cpu_ms']:.0f} ms CPU, {first_call['wall_ms']:.0f} ms wall",
        file=sys.stderr,
        flush=True,
    )
    raw: dict = {}
    summaries: dict = {}
    mg: dict = {}
    for world in worlds:
        best = BEST_KNOWN_COST[world]
        runs: dict[str, list] = {"GART": [], "GART without guidance (first path only)": [], RAW_ROW: []}
        if use_ompl:
            runs.update({f"OMPL {p}": [] for p in OMPL_PLANNERS})
        mg[world] = []
        for seed in range(n_seeds):
            bw = make_world(world, seed)
            runs["GART"].append(run_gart(bw, budgets, gs))
            runs["GART without guidance (first path only)"].append(run_gart(bw, budgets, plain, anytime=False))
            runs[RAW_ROW].append(run_gart(bw, budgets, raw_path, anytime=False))
            mg[world].append(run_mgart(bw, ms))
            if use_ompl:
                problem = OmplProblem(bw)
                for p in OMPL_PLANNERS:
                    runs[f"OMPL {p}"].append(run_ompl(problem, p, budgets))
            print(
                f"{world} seed {seed}: GART first {fmt(runs['GART'][-1].get('first_ms'), '.2f')} ms, "
                f"M-GART {mg[world][-1]['paths']} paths in {fmt(mg[world][-1]['time_to_k_ms'], '.0f')} ms "
                f"({fmt(mg[world][-1]['cpu_to_k_ms'], '.0f')} ms CPU)",
                file=sys.stderr,
                flush=True,
            )
        raw[world] = runs
        summaries[world] = {name: summarise(r, budgets, best) for name, r in runs.items()}
    text = [
        f"## Planning: GART / M-GART vs OMPL ({n_seeds} seeds, medians)",
        "",
        f"Machine: {platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores, "
        f"shared with other jobs while measured (absolute times are noisy; compare within a table; "
        f"'first path CPU' is the process CPU time of the whole call, less sensitive to load). "
        f"Run: `python benchmarks/planning.py{' --quick' if args.quick else ''}`. Costs are path lengths "
        "(m); GART's cost at a budget is its returned (shortcut) path, its first cost the raw tree path. "
        "OMPL checks motions by sampling (1 % resolution); 'exact-valid' counts seeds whose paths pass "
        "the exact segment check. GART's first path CPU covers the whole call (argument checks, set-up, "
        "search, shortcut, tree snapshot); OMPL's covers `solve` alone (set-up excluded, no simplifier); the "
        "row 'tree path without shortcut' leaves GART's shortcut step out. The first GART and M-GART calls of the process (numba kernels compiled, or loaded "
        f"from numba's cache) took {first_call['cpu_ms']:.0f} ms CPU / {first_call['wall_ms']:.0f} ms wall "
        "before the measurements and is not in the figures.",
        "",
    ]
    for world in worlds:
        text += [table(world, summaries[world], budgets, BEST_KNOWN_COST[world]), ""]
    text += ["### M-GART: eight distinct paths (Hausdorff distance >= 4 m), cheapest first", "", mgart_table(mg), ""]
    wq = world_query_costs(args.quick)
    text += [
        "### World queries: 30 vs 1000 obstacles (same covered fraction, margin 0.5 m), CPU time",
        "",
        world_table(wq),
        "",
    ]
    markdown = "\n".join(text)
    print(markdown)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(
        json.dumps(
            {
                "seeds": n_seeds,
                "budgets_s": budgets,
                "first_call": first_call,
                "summary": summaries,
                "mgart": mg,
                "world_queries": wq,
                "runs": raw,
            },
            indent=1,
            default=float,
        )
    )
    Path(args.markdown).parent.mkdir(parents=True, exist_ok=True)
    Path(args.markdown).write_text(markdown + "\n")
    if use_ompl:
        # The ompl 2.x nanobind wheel reports reference leaks at interpreter exit; they are
        # harmless here, so leave without running the interpreter's teardown.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
