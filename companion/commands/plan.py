"""``companion plan``: plan (GART / M-GART) on a world file, optionally smooth, summarise, plot.

A smoothed path is also timed (speed profile under the vehicle's limits, ``--speed``,
``--accel``, ``--jerk``) and checked on the helicopter's closed loop, as ``companion run`` does
with every leg (``companion.smoothing.feasibility``): where the timing would saturate a rotor
input or track too far off it is stretched; the summary and ``--json`` carry the figures (peak
actuator use, predicted tracking error, stretch). ``--no-feasibility`` skips the check.

Paper Fig. 6a (GART tree and path), Fig. 6b/6c (smoothed path and its curvature) and Fig. 7
(M-GART's several paths). The numerics live in ``companion.world``, ``companion.planning`` and
``companion.smoothing``, smoothed, timed and checked by ``companion.flight.pipeline`` (as the
legs of ``companion run``); this module only parses, prints, writes JSON and draws.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from companion.errors import PlanningError

EPILOG = """\
Examples:
  companion plan --world mission_files/worlds/paper_2d.toml --start 0,0 --goal 99,99 --plot out/plan.png
  companion plan --world mission_files/worlds/city_3d.toml --planner mgart -k 4 --smooth g2 \\
      --kappa-max 0.1 --json out/plan.json --plot out/plan3d.png
  companion plan --world mission_files/sites/cmac/buildings.geojson --smooth g2 --plot out/cmac.png
Start and goal are local NED metres (north,east[,down]); when omitted, the world file's
[world] start/goal are used. A map file (.geojson, .kml) is converted about --home LAT,LON,ALT
(default: its companion.home); start and goal are then metres about that home."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "plan",
        help="plan paths with GART / M-GART on a world file",
        description="Plan a collision-free path (GART) or several distinct ones (M-GART) through "
        "the obstacles of a world file; optionally smooth it (G1/G2 Bezier), write JSON and plot.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--world",
        required=True,
        help="world file (.toml or .json in local NED; .geojson or .kml map in longitude/latitude)",
    )
    p.add_argument(
        "--home",
        type=home_lla,
        metavar="LAT,LON,ALT",
        help="home of a map world (degrees, metres AMSL): the origin of local NED and of "
        "--start/--goal (default: the file's companion.home)",
    )
    p.add_argument("--start", help="start N,E[,D] in metres (default: the world file's start)")
    p.add_argument("--goal", help="goal N,E[,D] in metres (default: the world file's goal)")
    p.add_argument("--planner", choices=("gart", "mgart"), default="gart", help="planner (default gart)")
    p.add_argument("-k", type=int, default=8, help="number of M-GART paths (default 8)")
    p.add_argument(
        "--smooth",
        choices=("none", "g1", "g2"),
        default="none",
        help="smooth the path(s): G1 quartic or G2 cubic-spiral Bezier (default none)",
    )
    p.add_argument(
        "--kappa-max",
        type=float,
        default=None,
        dest="kappa_max",
        help="vehicle K_max in 1/m: limits corners in the planner and bounds G2 (default 0.1 with g2)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--budget",
        type=float,
        default=None,
        help="planning time budget in s (default: 1.0 for gart; 3.0 for mgart, which stops as soon as it has k paths)",
    )
    p.add_argument("--step", type=float, default=None, help="steering step in m (default 20)")
    p.add_argument(
        "--speed", type=float, default=None, help="cruise speed limit of the timing of smoothed paths, m/s (default 8)"
    )
    p.add_argument(
        "--accel", type=float, default=None, help="longitudinal acceleration limit of the timing, m/s^2 (default 2)"
    )
    p.add_argument("--jerk", type=float, default=None, help="jerk limit of the timing, m/s^3 (default 3)")
    p.add_argument(
        "--no-feasibility",
        action="store_true",
        dest="no_feasibility",
        help="do not check the timed smoothed paths on the helicopter's closed loop",
    )
    p.add_argument("--json", dest="json_out", help="write the result as JSON to this file")
    p.add_argument("--plot", help="draw tree, obstacles and paths to this PNG file")
    p.set_defaults(func=run)


def home_lla(text: str) -> tuple[float, float, float]:
    """``"LAT,LON,ALT"`` -> degrees, degrees, metres AMSL (``sim-vehicle --origin``'s rules)."""
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT, got {text!r}")
    try:
        lat, lon, alt = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers LAT,LON,ALT, got {text!r}") from None
    if not all(math.isfinite(v) for v in (lat, lon, alt)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    if not -90.0 <= lat <= 90.0 or not -180.0 <= lon <= 180.0:
        raise argparse.ArgumentTypeError(f"latitude must be -90..90 and longitude -180..180, got {text!r}")
    if not -500.0 <= alt <= 9000.0:
        raise argparse.ArgumentTypeError(f"altitude must be -500..9000 m AMSL, got {alt:g}")
    return lat, lon, alt


def parse_point(text: str | None, default, dim: int, option: str) -> tuple:
    """``"N,E[,D]"`` -> tuple of ``dim`` floats, or the world file's ``default``."""
    if text is None:
        if default is None:
            raise PlanningError(
                f"{option}: missing (give {option} N,E{',D' if dim == 3 else ''} or set it in the world file)"
            )
        return tuple(default)
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise PlanningError(f"{option}: expected numbers N,E{',D' if dim == 3 else ''}, got {text!r}") from None
    if len(values) != dim:
        raise PlanningError(f"{option}: expected {dim} comma-separated numbers for a {dim}D world, got {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise PlanningError(f"{option}: coordinates must be finite, got {text!r}")
    return values


def build_settings(args):
    from companion.planning import GartSettings, MgartSettings

    kappa = args.kappa_max
    if kappa is not None and not (math.isfinite(kappa) and kappa > 0):
        raise PlanningError(f"--kappa-max: must be a positive number (1/m), got {kappa}")
    if kappa is None and args.smooth == "g2":
        kappa = 0.1
    if args.budget is not None and not (math.isfinite(args.budget) and args.budget > 0):
        raise PlanningError(f"--budget: must be a positive number of seconds, got {args.budget}")
    if args.step is not None and not (math.isfinite(args.step) and args.step > 0):
        raise PlanningError(f"--step: must be a positive number of metres, got {args.step}")
    if args.planner == "mgart" and args.k < 1:
        raise PlanningError(f"-k: must be at least 1, got {args.k}")
    extra = {"kappa_max_1_m": kappa}
    if args.step is not None:
        extra["step_m"] = args.step
    gs = GartSettings(**extra)
    return gs, MgartSettings(gart=gs), kappa


def timing_limits(args):
    """The vehicle's limits (``TrajectoryLimits`` defaults) with ``--speed/--accel/--jerk``."""
    from dataclasses import replace

    from companion.errors import SmoothingError
    from companion.smoothing import TrajectoryLimits

    changes = {
        name: value
        for name, value in (("speed_m_s", args.speed), ("accel_m_s2", args.accel), ("jerk_m_s3", args.jerk))
        if value is not None
    }
    try:
        return replace(TrajectoryLimits(), **changes)
    except SmoothingError as exc:
        raise PlanningError(f"--speed/--accel/--jerk: {exc}") from None


def trajectory_pipeline(args, gart_settings, kappa: float | None):
    """The trajectory pipeline of ``--smooth``, ``--kappa-max`` and the limits, with the
    closed-loop checker unless ``--no-feasibility`` (``TrajectoryPipeline.from_settings``)."""
    from companion.flight.pipeline import TrajectoryPipeline
    from companion.smoothing import SmoothingSettings

    checker = None
    if not args.no_feasibility:
        from companion.smoothing.feasibility import FeasibilityChecker
        from heli_model.model import HeliModel

        checker = FeasibilityChecker(HeliModel.default())
        checker.warm_up()  # the one-off LQI design is not any path's check time
    smoothing = SmoothingSettings(method=args.smooth, kappa_max_1_m=kappa or 0.1, limits=timing_limits(args))
    return TrajectoryPipeline.from_settings(smoothing, gart_settings, closed_loop=checker)


def time_and_check(pipeline, smoothed) -> list:
    """Time every smoothed path; check it on the closed loop (stretching it where needed).

    Returns, per path, None (no path) or a dict: ``duration_s`` of the first timing,
    ``limits`` and ``feasibility`` (``FeasibilityReport.summary()``, None with
    ``--no-feasibility``).
    """
    from dataclasses import asdict

    out = []
    for curve in smoothed:
        if curve is None:
            out.append(None)
            continue
        trajectory = pipeline.timer.time(curve, pipeline.limits)
        report = pipeline.checker.check(trajectory).report
        out.append(
            {
                "duration_s": float(trajectory.duration_s),
                "limits": asdict(pipeline.limits),
                "feasibility": report.summary() if report is not None else None,
            }
        )
    return out


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from companion.extras import require
    from companion.planning import gart, mgart
    from companion.world import read_world_file

    if args.plot:
        require("report", "matplotlib")  # before the planning, not after it
    wf = read_world_file(args.world, home_lla=args.home)
    world = wf.world
    start = parse_point(args.start, wf.start, world.dim, "--start")
    goal = parse_point(args.goal, wf.goal, world.dim, "--goal")
    gs, ms, kappa = build_settings(args)
    rng = np.random.default_rng(args.seed)
    if args.planner == "gart":
        results = [gart(world, start, goal, rng=rng, max_time_s=args.budget, settings=gs)]
    else:
        budget = args.budget if args.budget is not None else 3.0
        results = mgart(world, start, goal, args.k, rng=rng, max_time_s=budget, settings=ms)
    smoothed, timed = [], []
    if args.smooth != "none":
        pipeline = trajectory_pipeline(args, gs, kappa)
        smoothed = [pipeline.smoother.smooth(r.path, world) if r.solved else None for r in results]
        timed = time_and_check(pipeline, smoothed)
    print_summary(args, wf, results, smoothed, start, goal, timed)
    if args.json_out:
        write_json(args, wf, results, smoothed, start, goal, kappa, timed)
    if args.plot:
        plot_plan(args.plot, world, results, smoothed, start, goal, kappa, title=wf.name)
        print(f"plot: {args.plot}")
    return 0 if results[0].solved else 1


def print_summary(args, wf, results, smoothed, start, goal, timed=()) -> None:
    from companion.smoothing.feasibility import describe

    first = results[0]
    tree = first.tree
    about = "" if wf.home_lla is None else " about home {:.7f}, {:.7f}, {:.1f} m".format(*wf.home_lla)
    print(
        f"world: {wf.name} ({wf.world.dim}D, {len(wf.world.obstacles)} obstacles, margin {wf.world.margin_m} m){about}"
    )
    print(f"planner: {args.planner}  seed {args.seed}  start {list(start)}  goal {list(goal)}")
    if not first.solved:
        print(f"status: {first.status}  iterations {first.iterations}  elapsed {first.elapsed_s * 1e3:.1f} ms")
        return
    print(
        f"status: exact  paths {len(results)}  iterations {first.iterations}  "
        f"tree {tree.size} nodes  elapsed {first.elapsed_s * 1e3:.1f} ms"
    )
    for i, r in enumerate(results):
        when = "first path after" if args.planner == "gart" else "found after"
        line = (
            f"  path {i}: cost {r.cost:.2f}  length {r.length_m:.2f} m  waypoints {len(r.path)}  "
            f"{when} {r.time_to_first_s * 1e3:.1f} ms"
        )
        if smoothed and smoothed[i] is not None:
            s = smoothed[i]
            line += f"  smoothed {s.length_m:.2f} m, max curvature {s.max_curvature_1_m:.3f} 1/m"
            if not getattr(s, "kappa_ok", True):
                line += " (K_max exceeded)"
        print(line)
        if timed and timed[i] is not None:
            f = timed[i]["feasibility"]
            print(f"    timed {timed[i]['duration_s']:.1f} s" + (f"; closed loop: {describe(f)}" if f else ""))


def write_json(args, wf, results, smoothed, start, goal, kappa, timed=()) -> None:
    tree = results[0].tree
    out = {
        "world": str(args.world),
        "world_name": wf.name,
        "dim": wf.world.dim,
        "home_lla": wf.home_lla,
        "planner": args.planner,
        "seed": args.seed,
        "budget_s": args.budget,
        "start": list(start),
        "goal": list(goal),
        "kappa_max_1_m": kappa,
        "smooth": args.smooth,
        "status": results[0].status,
        "tree": None
        if tree is None
        else {
            "nodes": tree.size,
            "forbidden": int(tree.forbidden.sum()),
            "iterations": results[0].iterations,
            "elapsed_s": results[0].elapsed_s,
        },
        "paths": [],
    }
    for i, r in enumerate(results):
        entry = r.summary()
        entry.pop("tree_nodes")
        if smoothed and smoothed[i] is not None:
            s = smoothed[i]
            entry["smoothed"] = {
                "length_m": float(s.length_m),
                "max_curvature_1_m": float(s.max_curvature_1_m),
                "kappa_ok": bool(getattr(s, "kappa_ok", True)),
                "notes": list(getattr(s, "notes", [])),
                "polyline": s.polyline(1.0).tolist(),
            }
            if timed and timed[i] is not None:
                entry["smoothed"].update(timed[i])
        out["paths"].append(entry)
    path = Path(args.json_out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    print(f"json: {path}")


# ---------------------------------------------------------------------- plotting
def _draw_obstacles_2d(ax, world) -> None:
    from matplotlib.patches import Circle, Polygon, Rectangle

    from companion.world import Box, Cylinder, Disc, Prism, Sphere

    style = dict(facecolor="0.55", edgecolor="0.25", alpha=0.8, zorder=1)
    for ob in world.obstacles:
        if isinstance(ob, (Disc, Sphere)):
            ax.add_patch(Circle((ob.center_m[1], ob.center_m[0]), ob.radius_m, **style))
        elif isinstance(ob, Cylinder):
            ax.add_patch(Circle((ob.center_ne_m[1], ob.center_ne_m[0]), ob.radius_m, **style))
        elif isinstance(ob, Box):
            ax.add_patch(
                Rectangle((ob.min_m[1], ob.min_m[0]), ob.max_m[1] - ob.min_m[1], ob.max_m[0] - ob.min_m[0], **style)
            )
        elif isinstance(ob, Prism):
            ax.add_patch(Polygon([(e, n) for n, e in ob.vertices_ne_m], closed=True, **style))


def _draw_obstacles_3d(ax, world) -> None:
    import numpy as np

    from companion.world import Box, Cylinder, Prism, Sphere

    lo, hi = world.bounds_min, world.bounds_max
    kw = dict(color="0.4", linewidth=0.5, alpha=0.6)
    for ob in world.obstacles:
        if isinstance(ob, Sphere):
            u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
            n = ob.center_m[0] + ob.radius_m * np.cos(u) * np.sin(v)
            e = ob.center_m[1] + ob.radius_m * np.sin(u) * np.sin(v)
            d = ob.center_m[2] + ob.radius_m * np.cos(v)
            ax.plot_wireframe(e, n, -d, **kw)
        elif isinstance(ob, (Cylinder, Prism)):
            d0 = max(ob.down_min_m, lo[2])
            d1 = min(ob.down_max_m, hi[2])
            if isinstance(ob, Cylinder):
                a = np.linspace(0, 2 * np.pi, 25)
                ring = np.c_[ob.center_ne_m[0] + ob.radius_m * np.cos(a), ob.center_ne_m[1] + ob.radius_m * np.sin(a)]
            else:
                ring = np.vstack([ob.vertices_ne_m, ob.vertices_ne_m[:1]])
            for d in (d0, d1):
                ax.plot(ring[:, 1], ring[:, 0], -d, **kw)
            for n, e in ring[:: max(1, len(ring) // 8)]:
                ax.plot([e, e], [n, n], [-d0, -d1], **kw)
        elif isinstance(ob, Box):
            (n0, e0, d0), (n1, e1, d1) = ob.min_m, ob.max_m
            for d in (d0, d1):
                ax.plot([e0, e1, e1, e0, e0], [n0, n0, n1, n1, n0], [-d] * 5, **kw)
            for n, e in ((n0, e0), (n0, e1), (n1, e1), (n1, e0)):
                ax.plot([e, e], [n, n], [-d0, -d1], **kw)


def plot_plan(filename, world, results, smoothed, start, goal, kappa, title: str = "") -> None:
    """Tree, obstacles and paths (Fig. 6a / 7); with smoothing, curvature vs arc length (Fig. 6c)."""
    import numpy as np

    from companion.extras import require

    require("report", "matplotlib").use("Agg")
    plt = require("report", "matplotlib.pyplot")

    three_d = world.dim == 3
    has_smooth = any(s is not None for s in smoothed)
    fig = plt.figure(figsize=(13 if has_smooth else 8, 7))
    ax = fig.add_subplot(1, 2 if has_smooth else 1, 1, projection="3d" if three_d else None)
    tree = results[0].tree
    colors = plt.cm.tab10.colors
    if three_d:
        _draw_obstacles_3d(ax, world)
    else:
        _draw_obstacles_2d(ax, world)
    if tree is not None and tree.size > 1:
        edges = tree.edges()
        if three_d:
            for seg in edges[:: max(1, len(edges) // 3000)]:
                ax.plot(seg[:, 1], seg[:, 0], -seg[:, 2], color="tab:cyan", linewidth=0.3, alpha=0.5)
        else:
            from matplotlib.collections import LineCollection

            ax.add_collection(LineCollection(edges[:, :, ::-1], colors="tab:cyan", linewidths=0.4, alpha=0.6, zorder=2))
    for i, r in enumerate(results):
        if not r.solved:
            continue
        p = r.path
        label = f"path {i}: cost {r.cost:.1f}"
        col = colors[i % len(colors)]
        if three_d:
            ax.plot(p[:, 1], p[:, 0], -p[:, 2], "o-", color=col, markersize=2, linewidth=1.2, label=label)
        else:
            ax.plot(p[:, 1], p[:, 0], "o-", color=col, markersize=2.5, linewidth=1.2, label=label, zorder=4)
        if smoothed and smoothed[i] is not None:
            q = smoothed[i].polyline(0.5)
            if three_d:
                ax.plot(q[:, 1], q[:, 0], -q[:, 2], color="k", linewidth=1.6)
            else:
                ax.plot(q[:, 1], q[:, 0], color="k", linewidth=1.6, zorder=5, label="smoothed" if i == 0 else None)
    s, g = np.asarray(start), np.asarray(goal)
    if three_d:
        ax.scatter([s[1]], [s[0]], [-s[2]], color="green", s=40, label="start")
        ax.scatter([g[1]], [g[0]], [-g[2]], color="red", marker="*", s=80, label="goal")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_zlabel("altitude (m)")
        lo, hi = world.bounds_min, world.bounds_max
        ax.set_xlim(lo[1], hi[1])
        ax.set_ylim(lo[0], hi[0])
        ax.set_zlim(-hi[2], -lo[2])
        ax.set_box_aspect((hi[1] - lo[1], hi[0] - lo[0], max(hi[2] - lo[2], 0.2 * (hi[0] - lo[0]))))
    else:
        ax.plot(s[1], s[0], "o", color="green", markersize=8, label="start", zorder=6)
        ax.plot(g[1], g[0], "*", color="red", markersize=12, label="goal", zorder=6)
        lo, hi = world.bounds_min, world.bounds_max
        ax.set_xlim(lo[1], hi[1])
        ax.set_ylim(lo[0], hi[0])
        ax.set_aspect("equal")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
    ax.set_title(title or "plan")
    ax.legend(loc="upper left" if three_d else "best", fontsize=7)
    if has_smooth:
        ax2 = fig.add_subplot(1, 2, 2)
        for i, sm in enumerate(smoothed):
            if sm is None:
                continue
            s_m = np.linspace(0.0, sm.length_m, 800)
            ax2.plot(s_m, sm.curvature(s_m), color=colors[i % len(colors)], linewidth=1.0, label=f"path {i}")
        if kappa:
            ax2.axhline(kappa, color="red", linestyle="--", linewidth=1.0, label="K_max")
        ax2.set_xlabel("arc length (m)")
        ax2.set_ylabel("curvature (1/m)")
        ax2.set_title("curvature of the smoothed path(s)")
        ax2.legend(fontsize=7)
    fig.tight_layout()
    if three_d and has_smooth:
        fig.subplots_adjust(wspace=0.3)
    Path(filename).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(filename, dpi=110)
    plt.close(fig)
