"""The report's 3D view of the flight at one instant: what an operator sees live in Foxglove.

``scene_instant`` picks the moment (the first threat decision, else the middle of the flight);
``plot_scene`` draws, east-north-up about home: the obstacles, the mission's legs, the path the
vehicle was on, the track flown so far (and, faded, the rest), the threats known at that moment
on their predicted tubes, and the helicopter. Reads a ``FlightRecord`` only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from companion.record.flight_record import FlightRecord
from companion.view.geometry import enu_from_ned, prism_side_triangles, threat_tube

__all__ = ["scene_instant", "threats_known_at", "path_at", "plot_scene"]

THREAT_DECISIONS = ("evade", "hold", "switch", "replan", "retime")


def scene_instant(record: FlightRecord) -> float | None:
    """Mission time of the first threat decision, else of the middle sample (None: no sample)."""
    for d in record.decisions:
        if d.get("kind") in THREAT_DECISIONS and d.get("t_s") is not None:
            return float(d["t_s"])
    if not record.has_samples:
        return None
    t = record.samples["t_s"]
    return float(t[len(t) // 2])


def threats_known_at(record: FlightRecord, t_s: float) -> dict[str, dict]:
    """Each threat's last report at or before ``t_s``, without those removed by then."""
    known: dict[str, dict] = {}
    for th in record.threats:
        if th.get("t_s", np.inf) > t_s:
            continue
        if th.get("removed"):
            known.pop(th.get("id"), None)
        elif th.get("position_ned_m") is not None:
            known[th["id"]] = th
    return known


def path_at(record: FlightRecord, t_s: float) -> list | None:
    """The new path of the last decision at or before ``t_s`` (None before the first: the
    vehicle was on its planned leg, drawn with the others)."""
    chosen = None
    for d in record.decisions:
        if d.get("t_s", np.inf) <= t_s and d.get("path_ned_m"):
            chosen = d["path_ned_m"]
    return chosen


def _draw_obstacles(ax, world: dict | None, ceiling_m: float) -> None:
    """The obstacles' walls, cut at ``ceiling_m`` up (the world may reach far above the flight)."""
    head = (world or {}).get("world", {})
    down = (float(head.get("bounds_min", [0, 0, -50])[-1]), float(head.get("bounds_max", [0, 0, 0])[-1]))
    for ob in (world or {}).get("obstacles", []):
        bottom = -float(ob.get("down_max", down[1]))
        top = min(-float(ob.get("down_min", down[0])), ceiling_m)
        if ob["type"] == "prism":
            ring = ob["vertices"]
        elif ob["type"] in ("cylinder", "disc"):
            a = np.linspace(0, 2 * np.pi, 33)[:-1]
            ring = np.column_stack(
                [ob["center"][0] + ob["radius"] * np.cos(a), ob["center"][1] + ob["radius"] * np.sin(a)]
            )
        elif ob["type"] == "box":
            (n0, e0, d0), (n1, e1, d1) = ob["min"], ob["max"]
            ring, bottom, top = [(n0, e0), (n1, e0), (n1, e1), (n0, e1)], -d1, min(-d0, ceiling_m)
        else:  # a sphere: drawn as its wireframe
            _sphere(ax, np.asarray(ob["center"], float), ob["radius"], "0.45", 0.3)
            continue
        walls = prism_side_triangles(ring, bottom, top).reshape(-1, 3, 3)
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        ax.add_collection3d(Poly3DCollection(walls, facecolor=(0.85, 0.3, 0.25, 0.25), edgecolor="none"))


def _ceiling_m(record: FlightRecord, above_m: float = 10.0) -> float:
    """``above_m`` over the highest point planned or flown (up, m)."""
    downs = [p[2] for plan in record.plans for p in plan["path_ned_m"]]
    if record.has_samples:
        downs.append(float(np.nanmin(record.samples["pos_ned_m"][:, 2])))
    return -min(downs, default=-20.0) + above_m


def _sphere(ax, centre_ned: np.ndarray, radius_m: float, colour, alpha: float) -> None:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
    e, n, up = enu_from_ned(centre_ned)
    ax.plot_wireframe(
        e + radius_m * np.cos(u) * np.sin(v),
        n + radius_m * np.sin(u) * np.sin(v),
        up + radius_m * np.cos(v),
        color=colour,
        alpha=alpha,
        linewidth=0.6,
    )


def _line(ax, path_ned: np.ndarray, **style) -> None:
    enu = enu_from_ned(path_ned)
    ax.plot(enu[:, 0], enu[:, 1], enu[:, 2], **style)


def plot_scene(
    plt, record: FlightRecord, path: Path, t_s: float, horizon_s: float = 10.0, uncertainty_m_s: float = 0.3
) -> None:
    """Draw the flight at mission time ``t_s`` into the PNG ``path``."""
    fig = plt.figure(figsize=(9, 8))
    ax = fig.add_subplot(projection="3d")
    _draw_obstacles(ax, record.world, _ceiling_m(record))
    for plan in record.plans:
        _line(ax, np.asarray(plan["path_ned_m"], float), color="0.6", lw=1.0, ls="--")
    active = path_at(record, t_s)
    if active:
        _line(ax, np.asarray(active, float), color="tab:green", lw=2.5, label="active path")
    if record.has_samples:
        t, pos = record.samples["t_s"], record.samples["pos_ned_m"]
        now = int(np.searchsorted(t, t_s, side="right"))
        _line(ax, pos[:now], color="tab:blue", lw=1.8, label="flown")
        _line(ax, pos[now:], color="tab:blue", lw=0.8, alpha=0.25)
        if now:
            e, n, up = enu_from_ned(pos[now - 1])
            ax.scatter([e], [n], [up], color="navy", s=60, marker="^", label="helicopter")
    for tid, th in threats_known_at(record, t_s).items():
        centres, radii = threat_tube(
            np.asarray(th["position_ned_m"], float),
            np.asarray(th.get("velocity_ned_m_s") or (0, 0, 0), float),
            th["radius_m"],
            max(0.0, t_s - th["t_s"]),
            horizon_s,
            2.5,
            uncertainty_m_s,
        )
        _sphere(ax, centres[0], radii[0], "tab:red", 0.8)
        if len(centres) > 1:
            _line(ax, centres, color="tab:red", lw=1.5)
            _sphere(ax, centres[-1], radii[-1], "tab:red", 0.2)
        ax.text(*enu_from_ned(centres[0]), f" {tid}", color="tab:red", fontsize=8)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_zlabel("up (m)")
    ax.set_title(f"The scene at t = {t_s:.1f} s (threats on their predicted tubes, {horizon_s:g} s ahead)")
    ax.view_init(elev=35, azim=-60)
    lo, hi = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()]).T
    ax.set_box_aspect(np.maximum(hi - lo, 1.0))  # metres the same on every axis
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
