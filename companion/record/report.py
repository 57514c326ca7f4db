"""Flight report: a flight record rendered as PNG plots (paper Fig. 6d-6f and Fig. 8).

``render_report(record, out_dir)`` writes

- ``flight_path.png``: top view (east right, north up) of obstacle footprints, the planner
  trees, the M-GART alternatives, the reference, the flown track and the threats with the
  decisions taken (Fig. 6d, Fig. 8);
- ``tracking.png``: reference against actual north, east and altitude, and the tracking error
  over time with the decisions marked (Fig. 6e);
- ``actuators.png``: the four normalised inputs (lateral and longitudinal cyclic, pedal,
  collective) from SERVO_OUTPUT_RAW (Fig. 6f), with the peak the closed-loop check predicted
  for each (dashed);
- ``summary.json``: the record's summary plus the statistics computed here, and ``legs``: each
  planned leg's closed-loop check (peak actuator use, predicted tracking error, stretch);
- ``summary.txt``: the same in a few lines of text (also printed by ``companion report``).

Matplotlib is imported inside ``render_report`` (Agg backend) so that importing this module is
cheap.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from companion.record.flight_record import FlightRecord
from companion.record.report_scene import plot_scene, scene_instant
from companion.smoothing.feasibility import describe

log = logging.getLogger(__name__)

INPUT_NAMES = ("lateral cyclic", "longitudinal cyclic", "pedal", "collective")
DECISION_COLOURS = {"replan": "tab:green", "switch": "tab:orange", "hold": "tab:red", "rejected": "tab:gray"}


def servo_us_to_delta(servo_us: np.ndarray) -> np.ndarray:
    """PWM (1000-2000 us, 1500 neutral) to normalised stick units in [-1, 1]; shape kept."""
    return (np.asarray(servo_us, dtype=float) - 1500.0) / 500.0


def tracking_statistics(record: FlightRecord) -> dict:
    """RMS and maximum tracking error (m) over the recorded samples."""
    if not record.has_samples or "tracking_error_m" not in record.samples:
        return {}
    err = record.samples["tracking_error_m"]
    err = err[np.isfinite(err)]
    return {
        "samples": int(err.size),
        "rms_tracking_error_m": float(np.sqrt(np.mean(err**2))),
        "max_tracking_error_m": float(np.max(err)),
        "duration_s": float(record.samples["t_s"][-1] - record.samples["t_s"][0]),
    }


def leg_feasibility(record: FlightRecord) -> list[dict]:
    """Each recorded leg plan's closed-loop figures (``plan`` lines), without the per-piece
    detail; legs planned without the check have ``feasibility`` None."""
    out = []
    for plan in record.plans:
        f = plan.get("feasibility")
        out.append(
            {
                "leg": plan.get("leg"),
                "seq": plan.get("seq"),
                "duration_s": plan.get("duration_s"),
                "feasibility": None if f is None else {k: v for k, v in f.items() if k != "pieces"},
            }
        )
    return out


def summary_text(summary: dict, legs: list[dict]) -> str:
    """A few lines of the flight: legs, tracking, and each leg's closed-loop check."""
    lines = [
        f"outcome: {summary.get('outcome')}  legs planned {summary.get('legs_planned')}  "
        f"reached {summary.get('legs_reached')}"
    ]
    if summary.get("rms_tracking_error_m") is not None:
        lines.append(
            f"tracking error (flown): RMS {summary['rms_tracking_error_m']:.2f} m, "
            f"max {summary.get('max_tracking_error_m', float('nan')):.2f} m"
        )
    for leg in legs:
        f = leg["feasibility"]
        head = f"leg {leg['leg']} (item {leg['seq']})"
        if f is None:
            lines.append(f"{head}: not checked on the closed loop")
            continue
        lines.append(f"{head}: {describe(f)}")
    return "\n".join(lines) + "\n"


def _draw_obstacles(ax, world: dict | None) -> None:
    """Top view of the obstacles of a world in the world-file format (``world_to_dict``)."""
    from matplotlib.patches import Circle, Polygon, Rectangle

    margin = ((world or {}).get("world") or {}).get("margin_m", 0.0)
    for ob in (world or {}).get("obstacles", []):
        style = dict(facecolor="0.55", edgecolor="0.25", alpha=0.6, zorder=1)
        kind = ob.get("type")
        if kind in ("disc", "sphere", "cylinder"):
            n, e = ob["center"][:2]
            ax.add_patch(Circle((e, n), ob["radius"], **style))
            if margin > 0:
                ax.add_patch(
                    Circle((e, n), ob["radius"] + margin, fill=False, linestyle=":", edgecolor="0.4", zorder=1)
                )
        elif kind == "prism":
            ax.add_patch(Polygon([(e, n) for n, e in ob["vertices"]], closed=True, **style))
        elif kind == "box":
            (n0, e0), (n1, e1) = ob["min"][:2], ob["max"][:2]
            ax.add_patch(Rectangle((e0, n0), e1 - e0, n1 - n0, **style))


def _draw_plans(ax, plans: list[dict]) -> None:
    for plan in plans:
        tree = plan.get("tree")
        if tree and tree.get("nodes"):
            nodes = np.asarray(tree["nodes"], dtype=float)
            parents = np.asarray(tree["parents"], dtype=int)
            child = np.nonzero(parents >= 0)[0]
            segs = np.stack([nodes[child, :2], nodes[parents[child], :2]], axis=1)[:, :, ::-1]
            from matplotlib.collections import LineCollection

            ax.add_collection(LineCollection(segs, colors="0.8", linewidths=0.4, zorder=0))
        if plan.get("reference_ne") is not None:
            ref = np.asarray(plan["reference_ne"], dtype=float)
            ax.plot(
                ref[:, 1],
                ref[:, 0],
                color="tab:blue",
                lw=1.2,
                zorder=3,
                label="reference" if plan is plans[0] else None,
            )


def _draw_alternatives(ax, record: FlightRecord) -> None:
    """The last M-GART alternatives of every leg (dashed) and the decisions' new paths."""
    last = {}
    for alt in record.alternatives:
        last[alt["leg"]] = alt
    for alt in last.values():
        for path in alt["paths"]:
            p = np.asarray(path, dtype=float)
            ax.plot(p[:, 1], p[:, 0], "--", color="tab:purple", lw=0.8, alpha=0.6, zorder=2)
    for d in record.decisions:
        if d.get("path_ned_m") is not None:
            p = np.asarray(d["path_ned_m"], dtype=float)
            ax.plot(p[:, 1], p[:, 0], "-.", color=DECISION_COLOURS.get(d.get("kind"), "k"), lw=1.0, zorder=3)


def _draw_threats(ax, threats: list[dict]) -> None:
    from matplotlib.patches import Circle

    seen = set()
    for threat in threats:
        if threat.get("removed") or threat.get("position_ned_m") is None:
            continue
        n, e = threat["position_ned_m"][:2]
        ax.add_patch(Circle((e, n), threat["radius_m"], facecolor="tab:red", alpha=0.15, edgecolor="tab:red", zorder=2))
        vel = threat.get("velocity_ned_m_s") or [0.0, 0.0, 0.0]
        if np.hypot(vel[0], vel[1]) > 1e-6:
            ax.arrow(e, n, 5 * vel[1], 5 * vel[0], width=0.3, color="tab:red", zorder=4)
        if threat["id"] not in seen:
            ax.annotate(threat["id"], (e, n), color="tab:red", fontsize=8)
            seen.add(threat["id"])


def _plot_flight_path(plt, record: FlightRecord, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(8, 8))
    _draw_obstacles(ax, record.world)
    _draw_plans(ax, record.plans)
    _draw_alternatives(ax, record)
    _draw_threats(ax, record.threats)
    if record.has_samples:
        pos = record.samples["pos_ned_m"]
        ax.plot(pos[:, 1], pos[:, 0], color="tab:red", lw=1.0, zorder=5, label="flown")
    for d in record.decisions:
        if d.get("pos_ned_m") is not None:
            n, e = d["pos_ned_m"][:2]
            ax.plot(e, n, "o", color=DECISION_COLOURS.get(d.get("kind"), "k"), ms=7, zorder=6)
            ax.annotate(d.get("kind"), (e, n), textcoords="offset points", xytext=(5, 5), fontsize=8)
    for wp in record.header.get("waypoints_ned_m") or []:
        ax.plot(wp[1], wp[0], "k^", ms=6, zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title("Flown path, reference, trees and alternatives")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _mark_decisions(ax, record: FlightRecord) -> None:
    for d in record.decisions:
        if d.get("t_s") is not None:
            ax.axvline(d["t_s"], color=DECISION_COLOURS.get(d.get("kind"), "k"), lw=0.8, ls="--")


def _plot_tracking(plt, record: FlightRecord, path: Path) -> None:
    s = record.samples
    t = s["t_s"]
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    labels = ("north (m)", "east (m)", "altitude (m)")
    for i, ax in enumerate(axes[:3]):
        sign = -1.0 if i == 2 else 1.0
        ax.plot(t, sign * s["ref_pos_ned_m"][:, i], color="tab:blue", label="reference")
        ax.plot(t, sign * s["pos_ned_m"][:, i], color="tab:red", lw=0.8, label="actual")
        ax.set_ylabel(labels[i])
    axes[0].legend(loc="best", fontsize=8)
    axes[3].plot(t, s["tracking_error_m"], color="k", lw=0.8)
    axes[3].set_ylabel("error (m)")
    axes[3].set_xlabel("time (s)")
    for ax in axes:
        _mark_decisions(ax, record)
    fig.suptitle("Tracking: reference against actual")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_actuators(plt, record: FlightRecord, path: Path) -> None:
    s = record.samples
    delta = servo_us_to_delta(s["servo_us"])
    checked = [leg["feasibility"] for leg in leg_feasibility(record) if leg["feasibility"]]
    fig, axes = plt.subplots(4, 1, figsize=(9, 8), sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(s["t_s"], delta[:, i], lw=0.8)
        ax.axhline(1.0, color="tab:red", ls=":", lw=0.8)
        ax.axhline(-1.0, color="tab:red", ls=":", lw=0.8)
        if checked:
            peak = max(list(f["peak_abs_delta"].values())[i] for f in checked)
            for sign in (1.0, -1.0):
                ax.axhline(
                    sign * peak,
                    color="tab:green",
                    ls="--",
                    lw=0.8,
                    label="predicted peak" if sign > 0 and i == 0 else None,
                )
            if i == 0:
                ax.legend(loc="upper right", fontsize=7)
        ax.set_ylabel(INPUT_NAMES[i], fontsize=8)
        _mark_decisions(ax, record)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("Actuator inputs (normalised, |delta| <= 1)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_report(record: FlightRecord, out_dir: str | Path) -> list[Path]:
    """Render the plots and ``summary.json`` of a flight record into ``out_dir``.

    Returns the paths written. Plots that need samples are skipped for a record without any.

    Raises
    ------
    companion.extras.MissingExtra
        Without matplotlib (the ``report`` extra).
    """
    from companion.extras import require

    require("report", "matplotlib").use("Agg")
    plt = require("report", "matplotlib.pyplot")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "flight_path.png"]
    _plot_flight_path(plt, record, written[0])
    if record.has_samples and "ref_pos_ned_m" in record.samples:
        written.append(out / "tracking.png")
        _plot_tracking(plt, record, written[-1])
    if record.has_samples and "servo_us" in record.samples:
        written.append(out / "actuators.png")
        _plot_actuators(plt, record, written[-1])
    instant = scene_instant(record)
    if instant is not None:
        written.append(out / "scene.png")
        plot_scene(plt, record, written[-1], instant)
    summary = dict(record.summary or {})
    for key, value in tracking_statistics(record).items():
        # the companion's own figures (over every LOCAL_POSITION_NED it read) stay: the record's
        # 10 Hz samples fill in only what a record without a summary (a flight cut short) lacks,
        # so the console and the report give one figure
        if summary.get(key) is None or (isinstance(summary.get(key), float) and math.isnan(summary[key])):
            summary[key] = value
    summary["decisions"] = [{k: d.get(k) for k in ("kind", "reason", "latency_ms", "t_s")} for d in record.decisions]
    summary["legs"] = leg_feasibility(record)
    written.append(out / "summary.json")
    written[-1].write_text(json.dumps(summary, indent=2))
    written.append(out / "summary.txt")
    written[-1].write_text(summary_text(summary, summary["legs"]))
    log.info("report written to %s (%d files)", out, len(written))
    return written
