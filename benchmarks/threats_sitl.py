"""SITL threat series: randomised encounters flown by real processes, judged by the vehicle.

Issue 9's SITL series. Every flight starts a real ``sim-vehicle`` (wind 4 m/s with 1 m/s gusts,
seeded) and a real ``companion run`` (separate processes, at ``--speedup``, 2x by default) on
``mission_files/open_square.waypoints`` (four 80 m legs in open air at 20 m). This process is
the third one: it watches the companion's status and path over zenoh and puts one encounter on
each of legs 1-3, placed from the vehicle's telemetry and the published reference, drawn at
random (seeded) from:

- ``head_on``: a threat coming back along the leg at 2-6 m/s, met in 4-7 s;
- ``crossing``: a threat crossing the leg at 30-150 degrees at 1.5-5 m/s, timed to reach the
  point the reference reaches in 4-7 s;
- ``popup_near`` / ``popup_far``: a static threat on the path 1-3 s / 3-6 s ahead;
- ``overtaking``: a threat from behind along the leg at 1.2-1.5 times the vehicle's speed;
- ``multi``: two of the above at once.

Radii 2-4 m. Some threats are sent in the global frame (lat/lon/alt). An independent pymavlink
listener records the vehicle's own LOCAL_POSITION_NED; an intrusion is a sample inside a
threat's bare radius. Every encounter is also labelled by the independent oracle
(``companion.campaign.oracle.label_encounter``) from the vehicle's state when the threat was put.
Latency is the companion's: threat receipt (zenoh thread) to the first setpoint of the new
reference, per decision kind.

Prints a table, writes ``out/bench/threats_sitl.json`` and ``docs/benchmarks/threats_sitl.md``.
Run: ``.venv/bin/python benchmarks/threats_sitl.py [--flights N] [--speedup X] [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from flight_support import TrackListener, flight_processes  # noqa: E402

from companion.campaign.oracle import label_encounter  # noqa: E402
from companion.demo import DEMO_HOME, FlightWatcher, last_json_line  # noqa: E402
from companion.geo import LocalFrame  # noqa: E402
from companion.threats.model import Threat  # noqa: E402
from companion.threats.transport.bus import ThreatBus  # noqa: E402

MISSION = ROOT / "mission_files" / "open_square.waypoints"
CATEGORIES = ("head_on", "crossing", "popup_near", "popup_far", "overtaking", "multi")
WIND_ARGS = ("--wind-speed", "4", "--wind-dir", "250", "--gust", "1")
log = logging.getLogger("threats_sitl")


# ---------------------------------------------------------------------------- encounters
def draw_threat(kind: str, tid: str, watcher: FlightWatcher, rng: np.random.Generator) -> Threat | None:
    """One threat of ``kind`` placed on the current reference (local NED), or None."""
    now = watcher.status["t_s"]
    here = watcher.reference_at(now)
    if here is None:
        return None
    pos_now, direction = here
    u = np.append(direction[:2], 0.0) / max(np.linalg.norm(direction[:2]), 1e-9)
    speed_vehicle = 6.0
    radius = float(rng.uniform(2.0, 4.0))
    if kind.startswith("popup"):
        ahead = rng.uniform(1.0, 3.0) if kind == "popup_near" else rng.uniform(3.0, 6.0)
        centre, vel = watcher.reference_at(now + ahead)[0], np.zeros(3)
    elif kind == "head_on":
        meet_s, speed = rng.uniform(4.0, 7.0), rng.uniform(2.0, 6.0)
        meet = watcher.reference_at(now + meet_s)[0]
        vel = -speed * u
        centre = meet - vel * meet_s
    elif kind == "crossing":
        meet_s, speed = rng.uniform(4.0, 7.0), rng.uniform(1.5, 5.0)
        angle = math.radians(rng.uniform(30.0, 150.0)) * rng.choice([-1.0, 1.0])
        heading = np.array(
            [u[0] * math.cos(angle) - u[1] * math.sin(angle), u[0] * math.sin(angle) + u[1] * math.cos(angle), 0.0]
        )
        meet = watcher.reference_at(now + meet_s)[0]
        vel = speed * heading
        centre = meet - vel * meet_s
    else:  # overtaking, from behind
        speed = rng.uniform(1.2, 1.5) * speed_vehicle
        vel = speed * u
        centre = pos_now - u * rng.uniform(12.0, 20.0)
    return Threat(
        tid,
        "popup" if not np.any(vel) else "moving",
        "local_ned",
        tuple(map(float, centre)),
        tuple(map(float, vel)),
        radius,
        60.0,
    )


def as_sent(threat: Threat, rng: np.random.Generator) -> Threat:
    """Half of the threats go out in the global frame (lat, lon, alt AMSL)."""
    if rng.random() < 0.5:
        return threat
    lat, lon, alt = LocalFrame(*DEMO_HOME).to_lla(*threat.position)
    return Threat(
        threat.id,
        threat.kind,
        "global",
        (float(lat), float(lon), float(alt)),
        threat.velocity_ned_m_s,
        threat.radius_m,
        threat.ttl_s,
    )


def fly_series_flight(index: int, out_dir: Path, speedup: float, rng: np.random.Generator) -> dict:
    """One flight with an encounter on each of legs 1-3; returns its encounters and summary."""
    encounters = []
    with (
        TrackListener() as track,
        flight_processes(
            out_dir, MISSION, speedup=speedup, gcs_out=track.address, sim_args=(*WIND_ARGS, "--seed", str(index))
        ) as flight,
    ):
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = FlightWatcher(bus)
            plan = {leg: (str(rng.choice(CATEGORIES)), rng.uniform(2.0, 5.0)) for leg in (1, 2, 3)}
            deadline = time.monotonic() + 400.0
            while plan and flight.companion.poll() is None and time.monotonic() < deadline:
                time.sleep(0.02)
                status, path = watcher.status, watcher.path
                if not status or not path or path.get("leg") not in plan:
                    continue
                leg = path["leg"]
                category, after_s = plan[leg]
                if path.get("path_id") != f"leg{leg}" or status["t_s"] - path["t0_s"] < after_s:
                    continue
                del plan[leg]
                kinds = (
                    [str(k) for k in rng.choice(CATEGORIES[:-1], 2, replace=False)]
                    if category == "multi"
                    else [category]
                )
                threats = [draw_threat(k, f"f{index}l{leg}{chr(97 + i)}", watcher, rng) for i, k in enumerate(kinds)]
                threats = [t for t in threats if t is not None]
                pos, vel = track_state(track)
                for th in threats:
                    bus.client.put_threat(as_sent(th, rng))
                encounters.append(
                    {
                        "flight": index,
                        "leg": leg,
                        "category": category,
                        "kinds": kinds,
                        "t_put_s": status["t_s"],
                        "threats": threats,
                        "pos": pos,
                        "vel": vel,
                    }
                )
            flight.companion.wait(400.0)
            events = list(watcher.events)
        track_t = np.array([p[0] for p in track.track])
        track_pos = track.positions()
    summary = last_json_line(flight.log) or {}
    return {
        "summary": summary,
        "rc": flight.companion.returncode,
        "events": events,
        "encounters": encounters,
        "track_t": track_t,
        "track_pos": track_pos,
    }


def track_state(track: TrackListener) -> tuple[np.ndarray, np.ndarray]:
    """The vehicle's last position and its velocity from the last half second of track."""
    pts = np.array(track.track[-12:], dtype=float)
    if len(pts) < 2:
        return np.zeros(3), np.zeros(3)
    dt = max(pts[-1, 0] - pts[0, 0], 1e-3)
    return pts[-1, 1:], (pts[-1, 1:] - pts[0, 1:]) / dt


def judge(flight: dict) -> list[dict]:
    """Each encounter's outcome from the vehicle's own track, and its oracle label."""
    rows = []
    t, pos = flight["track_t"], flight["track_pos"]
    for enc in flight["encounters"]:
        sep = math.inf
        stamped = [th.with_time(enc["t_put_s"]) for th in enc["threats"]]
        for th in stamped:
            after = (t >= enc["t_put_s"]) & (t <= enc["t_put_s"] + th.ttl_s)  # while it lives
            if after.sum() < 2:
                continue
            centre = th.position_at(t[after])
            sep = min(sep, float(np.min(np.linalg.norm(pos[after] - centre, axis=1))) - th.radius_m)
        oracle = label_encounter(enc["pos"], enc["vel"], stamped, enc["t_put_s"])
        ids = {th.id for th in enc["threats"]}
        decisions = [e for e in flight["events"] if e.get("threat_id") in ids and e.get("latency_ms") is not None]
        rows.append(
            {
                "flight": enc["flight"],
                "leg": enc["leg"],
                "category": enc["category"],
                "kinds": enc["kinds"],
                "min_sep_m": sep,
                "intrusion": sep < 0.0,
                "avoidable": bool(oracle.avoidable),
                "decisions": [
                    (decision_kind(e), e["latency_ms"], e.get("latency_parts_ms") or {}, e.get("trigger"))
                    for e in decisions
                ],
            }
        )
    return rows


def decision_kind(event: dict) -> str:
    """The decision's kind, and for an evasion or a hold chosen once a replan had been tried
    (the conflict was far enough to replan first: its candidates start after the fast step and
    the replan, DESIGN 7.4), ``<kind> after a replan``."""
    kind = event["event"]
    return f"{kind} after a replan" if kind in ("evade", "hold") and event.get("branch") == "replan" else kind


# ---------------------------------------------------------------------------- report
def pct(values, q):
    return None if not values else float(np.percentile(values, q))


def summarize(rows: list[dict], flights: list[dict], wall_s: float) -> dict:
    latency: dict[str, list[float]] = {}
    parts: dict[str, dict[str, list[float]]] = {}
    slowest: dict[str, tuple] = {}
    for r in rows:
        for kind, ms, split, trigger in r["decisions"]:
            latency.setdefault(kind, []).append(ms)
            for name, v in split.items():
                parts.setdefault(kind, {}).setdefault(name, []).append(v)
            if ms >= slowest.get(kind, (-1.0,))[0]:
                slowest[kind] = (ms, split, trigger)
    per_cat = {}
    for cat in CATEGORIES:
        mine = [r for r in rows if r["category"] == cat]
        per_cat[cat] = {
            "n": len(mine),
            "avoidable": sum(r["avoidable"] for r in mine),
            "intrusions": sum(r["intrusion"] for r in mine),
            "intrusions_avoidable": sum(r["intrusion"] and r["avoidable"] for r in mine),
        }
    return {
        "encounters": len(rows),
        "flights": len(flights),
        "completed": sum(f["summary"].get("outcome") == "completed" for f in flights),
        "intrusions": sum(r["intrusion"] for r in rows),
        "intrusions_avoidable": sum(r["intrusion"] and r["avoidable"] for r in rows),
        "min_sep_m": min((r["min_sep_m"] for r in rows), default=None),
        "latency_ms": {
            k: {"n": len(v), "p50": pct(v, 50), "p99": pct(v, 99), "max": max(v)} for k, v in sorted(latency.items())
        },
        "latency_parts_ms": {
            k: {name: {"p50": pct(v, 50), "p99": pct(v, 99)} for name, v in split.items()}
            for k, split in sorted(parts.items())
        },
        "slowest": {k: {"ms": v[0], "parts": v[1], "trigger": v[2]} for k, v in sorted(slowest.items())},
        "categories": per_cat,
        "wall_s": wall_s,
    }


def table(summary: dict, speedup: float) -> str:
    fmt = lambda x: "n/a" if x is None else f"{x:.1f}"  # noqa: E731
    lines = [
        f"## SITL threat series ({summary['encounters']} encounters in {summary['flights']} flights, "
        f"real sim-vehicle + companion run at {speedup:g}x, wind 4 m/s gusting 1 m/s)",
        "",
        f"Flights completed: {summary['completed']}/{summary['flights']}; intrusions (vehicle's own "
        f"track inside a threat's radius): {summary['intrusions']} ({summary['intrusions_avoidable']} "
        f"on encounters the oracle labels avoidable); smallest separation {fmt(summary['min_sep_m'])} m; "
        f"wall time {summary['wall_s']:.0f} s.",
        "",
        "| category | encounters | avoidable (oracle) | intrusions | on avoidable |",
        "|---|---|---|---|---|",
    ]
    for cat, c in summary["categories"].items():
        lines.append(f"| {cat} | {c['n']} | {c['avoidable']} | {c['intrusions']} | {c['intrusions_avoidable']} |")
    lines += [
        "",
        "| decision | n | threat receipt -> first new setpoint p50 (ms) | p99 (ms) | max (ms) |",
        "|---|---|---|---|---|",
    ]
    for kind, v in summary["latency_ms"].items():
        lines.append(f"| {kind} | {v['n']} | {fmt(v['p50'])} | {fmt(v['p99'])} | {fmt(v['max'])} |")
    names = ("queued", "compute", "transport", "gate", "start")
    lines += [
        "",
        "Where the time goes (``latency_parts_ms`` of each decision event, p50 / p99 ms): *queued* "
        "behind the decision before it, the decision's own *compute*, *transport* to the worker "
        "process and back, the fleet's delay check (*gate*), and *start*: from engaging to the first "
        "setpoint of the new reference, which takes effect at its start time (the trigger plus the "
        "decision's expected duration, or plus a replan's when it replans first).",
        "",
        "| decision | " + " | ".join(names) + " | slowest: ms (trigger) and its parts |",
        "|---|" + "---|" * (len(names) + 1),
    ]
    for kind, split in summary.get("latency_parts_ms", {}).items():
        cells = [f"{fmt(split[n]['p50'])} / {fmt(split[n]['p99'])}" if n in split else "-" for n in names]
        slow = summary["slowest"][kind]
        worst = ", ".join(f"{n} {slow['parts'][n]:.0f}" for n in names if n in slow["parts"])
        lines.append(f"| {kind} | " + " | ".join(cells) + f" | {slow['ms']:.0f} ({slow['trigger']}): {worst} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--flights", type=int, default=10, help="flights (3 encounters each; default 10)")
    parser.add_argument("--speedup", type=float, default=2.0, help="SITL speed-up (default 2)")
    parser.add_argument("--seed", type=int, default=9, help="seed of the encounters")
    parser.add_argument("--quick", action="store_true", help="2 flights")
    parser.add_argument("--no-docs", action="store_true", help="do not write docs/benchmarks/threats_sitl.md")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    n = 2 if args.quick else args.flights
    rng = np.random.default_rng(args.seed)
    out = ROOT / "out" / "bench"
    t0 = time.monotonic()
    flights, rows = [], []
    for i in range(n):
        flight = fly_series_flight(i, out / "threats_sitl" / f"flight{i}", args.speedup, rng)
        flights.append(flight)
        rows += judge(flight)
        print(
            f"flight {i}: {flight['summary'].get('outcome')}, "
            + ", ".join(f"{r['category']} sep {r['min_sep_m']:.1f} m" for r in rows[-len(flight["encounters"]) :]),
            file=sys.stderr,
            flush=True,
        )
    summary = summarize(rows, flights, time.monotonic() - t0)
    text = table(summary, args.speedup)
    print(text)
    out.mkdir(parents=True, exist_ok=True)
    (out / "threats_sitl.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=1, default=str))
    if not args.no_docs:
        (ROOT / "docs" / "benchmarks" / "threats_sitl.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
