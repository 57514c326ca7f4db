"""Threat reaction benchmark: Monte-Carlo encounters (replan-only, switch-only, hybrid) and a storm.

Paper section 3.3 (Fig. 5, Fig. 8) and DESIGN section 7. Two parts:

1. **Encounters** (>= 500, ``--quick``: 50). On the public 2D benchmark worlds (``worlds.py``,
   30 discs in 100 x 100 m, seeds 0-19, 1 m safety margin) the vehicle flies a GART + G2 +
   speed-profile trajectory from (0, 0) to (99, 99) at up to 6 m/s. At a random time a threat
   appears: a pop-up far ahead (5-12 s), a pop-up close ahead (3-5 s), or a threat moving at
   1-2 m/s (paper Fig. 8: sqrt(2) m/s) that crosses the path 3-5 s ahead. M-GART alternatives
   (k = 4) from where the vehicle was 1 s before are given to the manager, as the daemon's
   background refresh would have. Each policy decides on the same encounter; the vehicle keeps
   flying the old reference during the measured decision time, then the new one (after a hold,
   the manager is asked again at once, then every second, as the daemon does). The flown reference is tracked by the helicopter's
   closed loop (``sim_vehicle.control.simulate_closed_loop``, LQI + PID on the R-50 model) at
   100 Hz. Success: the vehicle never enters the threat's radius (not inflated) nor a static
   obstacle. Completed: success and the vehicle arrives within 3 m of the goal (a hold that is
   never followed by a clear path is safe but not completed).
2. **Storm**: 1000 threat PUTs per second for 10 s (``--quick``: 2 s) from one zenoh session into
   a ``ThreatBus`` subscriber in the same process over real zenoh on loopback TCP, handed to an
   asyncio loop that also runs a 50 Hz timer (the setpoint stream's stand-in): lost updates,
   PUT-to-handler latency, and the 50 Hz timer's jitter.

Prints a table, writes ``out/bench/threats.json`` and ``docs/benchmarks/threats.md``.
Run: ``.venv/bin/python benchmarks/threats.py [--quick] [--encounters N] [--storm-s S]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import os
import platform
import socket
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.worlds import make_world  # noqa: E402
from companion.planning import GartSettings, MgartSettings, gart  # noqa: E402
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize  # noqa: E402
from companion.threats.manager import ThreatManager  # noqa: E402
from companion.threats.model import Threat, ThreatTable  # noqa: E402
from companion.threats.settings import ThreatSettings  # noqa: E402
from companion.world import World  # noqa: E402
from sim_vehicle.control import simulate_closed_loop  # noqa: E402
from sim_vehicle.model import HeliModel  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STRATEGIES = ("hybrid", "replan", "switch")
LIMITS = TrajectoryLimits(speed_m_s=6.0)
KAPPA = 0.1
MARGIN_M = 1.0
DOWN_M = -20.0
DT_S = 0.02
N_WORLDS = 20
ENCOUNTER_KINDS = ("popup_far", "popup_near", "moving")
RESUME_EVERY_S = 1.0
RESUME_FOR_S = 30.0


# ---------------------------------------------------------------------------- encounters
def prepare_world(seed: int) -> dict | None:
    """Benchmark world ``seed`` with a safety margin and the nominal trajectory across it."""
    bw = make_world("2d", seed)
    world = World(bw.world.obstacles, bw.world.bounds_min, bw.world.bounds_max, margin_m=MARGIN_M)
    gs = GartSettings(kappa_max_1_m=KAPPA)
    res = gart(world, bw.start, bw.goal, rng=np.random.default_rng(seed), max_time_s=3.0, settings=gs)
    if res.status != "exact":
        return None
    traj = time_parameterize(smooth_g2(res.path, KAPPA, world=world), LIMITS)
    return {"seed": seed, "world": world, "raw": bw.world, "goal": bw.goal, "traj": traj, "gart": gs}


def make_threat(kind: str, traj, t_enc: float, goal: np.ndarray, rng: np.random.Generator,
                inflation_m: float) -> Threat | None:
    """A random threat of ``kind`` for an encounter at ``t_enc`` (None if it cannot be placed)."""
    pos_now = traj.sample(np.array([t_enc]))[0][0]
    for _ in range(20):
        if kind == "popup_far":
            tau, radius, speed = rng.uniform(5.0, 12.0), rng.uniform(3.0, 6.0), 0.0
        elif kind == "popup_near":
            tau, radius, speed = rng.uniform(3.0, 5.0), rng.uniform(2.0, 4.0), 0.0
        else:
            tau, radius, speed = rng.uniform(3.0, 5.0), rng.uniform(2.0, 4.0), rng.uniform(1.0, 2.0)
        t_hit = min(t_enc + tau, traj.duration_s)
        p, v, _ = traj.sample(np.array([t_hit]))
        p, v = p[0], v[0]
        tangent = v / np.linalg.norm(v) if np.linalg.norm(v) > 1e-6 else np.array([1.0, 0.0])
        normal = np.array([-tangent[1], tangent[0]])
        if speed == 0.0:
            center = p + normal * rng.uniform(-1.5, 1.5)
            vel = np.zeros(2)
        else:
            ang = rng.uniform(-math.pi / 4, math.pi / 4)
            side = rng.choice([-1.0, 1.0])
            direction = side * (math.cos(ang) * normal + math.sin(ang) * tangent)
            vel = speed * direction
            center = p - vel * (t_hit - t_enc)
        limit = radius + inflation_m
        if np.linalg.norm(center - pos_now) <= limit + 1.0:
            continue
        track = center[None, :] + np.linspace(0.0, 40.0, 81)[:, None] * vel[None, :]
        if np.min(np.linalg.norm(track - goal[None, :], axis=1)) <= limit + 3.0:
            continue
        return Threat("th", "moving" if speed else "popup", "local_ned", (center[0], center[1], DOWN_M),
                      (vel[0], vel[1], 0.0), radius, None, t_enc)
    return None


def compose_reference(segments, t_end_s: float):
    """Sample the flown reference: each (trajectory, start_t_s, engaged_t_s) from its engagement."""
    t = np.arange(0.0, t_end_s, DT_S)
    pos = np.empty((t.size, 2))
    vel = np.empty((t.size, 2))
    acc = np.empty((t.size, 2))
    yaw = np.empty(t.size)
    engaged = np.array([s[2] for s in segments])
    idx = np.searchsorted(engaged, t, side="right") - 1
    for k in np.unique(idx):
        sel = idx == k
        traj, start, _ = segments[k]
        p, v, a = traj.sample(t[sel] - start)
        pos[sel], vel[sel], acc[sel] = p[:, :2], v[:, :2], a[:, :2]
        yaw[sel] = traj.yaw_rad(t[sel] - start)
    return t, pos, vel, acc, yaw


def fly_encounter(prep: dict, threat: Threat, t_enc: float, alternatives, strategy: str,
                  settings: ThreatSettings, model: HeliModel, seed: int) -> dict:
    """Decide with one strategy, fly the result in closed loop, measure the outcome."""
    traj0 = prep["traj"]
    m = ThreatManager(prep["world"], prep["goal"], settings=settings, limits=LIMITS, kappa_max_1_m=KAPPA,
                      gart_settings=prep["gart"], rng=np.random.default_rng(seed), mode=strategy)
    m.set_active(traj0, 0.0, "nominal")
    m.set_alternatives(alternatives)
    segments = [(traj0, 0.0, 0.0)]
    d = m.on_threats([threat], t_enc)
    first = {"kind": d.kind, "decide_ms": d.decide_ms, "plan_ms": d.plan_ms,
             "ttc_s": d.conflict.time_to_conflict_s if d.conflict else None}
    decisions = [d.kind]
    t_now = t_enc
    if d.trajectory is not None:
        t_now = t_enc + d.decide_ms / 1e3
        segments.append((d.trajectory, d.start_t_s, t_now))
    resumes = 0
    while d.kind == "hold" and d.resume and t_now < t_enc + RESUME_FOR_S:
        # as the daemon does: resume at once after engaging the hold, then every second
        t_now += RESUME_EVERY_S if resumes else 0.0
        resumes += 1
        d = m.on_threats([threat], t_now)
        decisions.append(d.kind)
        if d.trajectory is not None:
            segments.append((d.trajectory, d.start_t_s, t_now + d.decide_ms / 1e3))
    last_traj, last_start, _ = segments[-1]
    t_end = max(last_start + last_traj.duration_s, t_now) + 3.0
    t, pos, vel, acc, yaw = compose_reference(segments, t_end)
    lift = np.full((t.size, 1), DOWN_M)
    zeros = np.zeros((t.size, 1))
    cl = simulate_closed_loop(model, t, np.hstack([pos, lift]), np.hstack([vel, zeros]),
                              np.hstack([acc, zeros]), yaw)
    veh = cl.pos_ned_m[:, :2]
    th_pos = threat.position_at(t)[:, :2]
    after = t >= t_enc
    sep = float(np.min(np.linalg.norm(veh[after] - th_pos[after], axis=1)) - threat.radius_m)
    static = float(np.min(prep["raw"].clearance_m(veh[after])))
    reached = float(np.linalg.norm(veh[-1] - prep["goal"])) <= 3.0
    flown = float(np.sum(np.linalg.norm(np.diff(veh[after], axis=0), axis=1)))
    s_enc = float(traj0.s_at(t_enc))
    nominal = traj0.length_m - s_enc
    return {"strategy": strategy, "first": first, "decisions": decisions, "min_sep_m": sep,
            "static_clearance_m": static, "reached": reached, "success": sep >= 0.0 and static >= 0.0,
            "completed": sep >= 0.0 and static >= 0.0 and reached,
            "extra_length_m": flown - nominal if reached else None,
            "max_tracking_error_m": float(np.max(cl.tracking_error_m)), "saturated": bool(cl.saturated)}


def run_encounters(n: int, settings: ThreatSettings, log_every: int = 25) -> list[dict]:
    model = HeliModel.default()
    preps = {}
    out = []
    for i in range(n):
        seed = i % N_WORLDS
        if seed not in preps:
            preps[seed] = prepare_world(seed)
        prep = preps[seed]
        if prep is None:
            continue
        rng = np.random.default_rng(1000 + i)
        kind = ENCOUNTER_KINDS[i % len(ENCOUNTER_KINDS)]
        traj0 = prep["traj"]
        threat = None
        for _ in range(10):
            t_enc = rng.uniform(2.0, max(traj0.duration_s - 5.0, 2.5))
            threat = make_threat(kind, traj0, t_enc, prep["goal"], rng, settings.inflation_m)
            if threat is not None:
                break
        if threat is None:
            continue
        refresher = ThreatManager(prep["world"], prep["goal"], settings=settings, limits=LIMITS,
                                  kappa_max_1_m=KAPPA, gart_settings=prep["gart"])
        refresher.set_active(traj0, 0.0)
        alts = refresher.compute_alternatives([], max(t_enc - 1.0, 0.0), 4, rng=np.random.default_rng(i),
                                              max_time_s=1.0, settings=MgartSettings(gart=prep["gart"]))
        row = {"index": i, "world": seed, "kind": kind, "t_enc_s": t_enc, "alternatives": len(alts),
               "threat": {"pos": list(threat.position[:2]), "vel": list(threat.velocity_ned_m_s[:2]),
                          "radius_m": threat.radius_m}}
        for strategy in STRATEGIES:
            row[strategy] = fly_encounter(prep, threat, t_enc, alts, strategy, settings, model, i)
        out.append(row)
        if log_every and (i + 1) % log_every == 0:
            ok = {s: (sum(r[s]["success"] for r in out), sum(r[s]["completed"] for r in out)) for s in STRATEGIES}
            print(f"  {i + 1}/{n} encounters: success/completed " + ", ".join(f"{s} {ok[s]}" for s in STRATEGIES),
                  file=sys.stderr, flush=True)
    return out


def percentile(values, q: float) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


def summarize_encounters(rows: list[dict]) -> dict:
    out = {}
    for s in STRATEGIES:
        res = [r[s] for r in rows]
        sep = np.array([x["min_sep_m"] for x in res])
        extra = [x["extra_length_m"] for x in res if x["extra_length_m"] is not None]
        lat = {}
        for kind in ("replan", "switch", "hold"):
            ms = [x["first"]["decide_ms"] for x in res if x["first"]["kind"] == kind]
            lat[kind] = {"n": len(ms), "p50_ms": percentile(ms, 50), "p99_ms": percentile(ms, 99),
                         "max_ms": max(ms) if ms else None}
        allms = [x["first"]["decide_ms"] for x in res]
        by_kind = {}
        for kind in ENCOUNTER_KINDS:
            sub = [r[s]["completed"] for r in rows if r["kind"] == kind]
            by_kind[kind] = sum(sub) / len(sub) if sub else None
        out[s] = {
            "n": len(res), "success_rate": sum(x["success"] for x in res) / max(len(res), 1),
            "completed_rate": sum(x["completed"] for x in res) / max(len(res), 1),
            "intrusions": int(np.sum(sep < 0.0)), "static_collisions": sum(x["static_clearance_m"] < 0 for x in res),
            "not_reached": sum(not x["reached"] for x in res),
            "min_sep_m": {"min": float(sep.min()) if sep.size else None, "p5": percentile(sep, 5),
                          "median": percentile(sep, 50)},
            "extra_length_m": {"median": percentile(extra, 50), "p95": percentile(extra, 95)},
            "decisions": {k: sum(x["first"]["kind"] == k for x in res) for k in ("none", "replan", "switch", "hold")},
            "latency": lat, "latency_all": {"p50_ms": percentile(allms, 50), "p99_ms": percentile(allms, 99)},
            "success_by_kind": by_kind,
        }
    return out


# ---------------------------------------------------------------------------- storm
def free_tcp_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def run_storm(duration_s: float, rate_hz: float = 1000.0, ids: int = 50) -> dict:
    """PUT ``rate_hz`` threats per second for ``duration_s`` into a ThreatBus on an asyncio loop."""
    from companion.threats.bus import ThreatBus

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    n = int(round(duration_s * rate_hz))
    sent_at = np.full(n, np.nan)
    recv_at = np.full(n, np.nan)

    async def main() -> dict:
        loop = asyncio.get_running_loop()
        table = ThreatTable()
        counts = {"handled": 0, "rejected": 0}
        ticks: list[float] = []
        done = asyncio.Event()

        def on_update(update) -> None:
            if update.action != "put":
                counts["rejected"] += 1
                return
            table.put(update.threat)
            k = int(update.threat.position[0])
            recv_at[k] = time.monotonic()
            counts["handled"] += 1
            if counts["handled"] == n:
                done.set()

        async def timer_50hz() -> None:
            period = 0.02
            nxt = time.monotonic()
            while not done.is_set():
                nxt += period
                await asyncio.sleep(max(nxt - time.monotonic(), 0.0))
                ticks.append(time.monotonic() - nxt)

        sub = ThreatBus(1, listen=[endpoint]).open()
        pub = ThreatBus(1, listen=[], connect=[endpoint]).open()
        try:
            sub.subscribe(on_update, loop=loop)
            for j in range(ids):
                await asyncio.to_thread(pub.wait_for_subscriber, 10.0, f"s{j}")

            def publish() -> None:
                t0 = time.monotonic()
                for k in range(n):
                    delay = t0 + k / rate_hz - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    th = Threat(f"s{k % ids}", "moving", "local_ned", (float(k), 1.0, -20.0),
                                (1.0, 0.0, 0.0), 3.0, 60.0, 0.0)
                    sent_at[k] = time.monotonic()
                    pub.put_threat(th)

            timer = asyncio.create_task(timer_50hz())
            t_start = time.monotonic()
            await asyncio.to_thread(publish)
            t_sent = time.monotonic() - t_start
            try:
                await asyncio.wait_for(done.wait(), 10.0)
            except asyncio.TimeoutError:
                pass
            done.set()
            await timer
            stats = sub.stats()
        finally:
            pub.close()
            sub.close()
        lat_ms = (recv_at - sent_at)[np.isfinite(recv_at)] * 1e3
        jitter_ms = np.abs(np.array(ticks)) * 1e3
        return {"sent": n, "send_duration_s": t_sent, "rate_hz": n / t_sent,
                "received": stats["received"], "handled": counts["handled"],
                "lost": n - counts["handled"], "rejected": counts["rejected"],
                "handler_errors": stats["handler_errors"], "table_active": len(table),
                "latency_ms": {"p50": percentile(lat_ms, 50), "p99": percentile(lat_ms, 99),
                               "max": float(lat_ms.max()) if lat_ms.size else None},
                "timer_50hz_jitter_ms": {"p50": percentile(jitter_ms, 50), "p99": percentile(jitter_ms, 99),
                                         "max": float(jitter_ms.max()) if jitter_ms.size else None,
                                         "ticks": int(jitter_ms.size)}}

    sys.setswitchinterval(0.0005)
    return asyncio.run(main())


# ---------------------------------------------------------------------------- report
def fmt(x, digits=1) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return str(x)


def tables(summary: dict, storm: dict, n: int) -> str:
    lines = [f"Encounters: {n} (a third each: pop-up far ahead, pop-up close ahead, moving threat at "
             "1-2 m/s crossing 3-5 s ahead); closed-loop helicopter model; success = no intrusion into "
             "the threat's radius and no static collision; completed = success and goal reached.", "",
             "| policy | success | completed | intrusions | min sep. (m) min / p5 / median | "
             "extra length (m) median / p95 | first decision replan / switch / hold / none | "
             "completed far / near / moving |",
             "|---|---|---|---|---|---|---|---|"]
    for s in STRATEGIES:
        x = summary[s]
        d = x["decisions"]
        k = x["success_by_kind"]
        lines.append(
            f"| {s} | {100 * x['success_rate']:.1f} % | {100 * x['completed_rate']:.1f} % | {x['intrusions']} | "
            f"{fmt(x['min_sep_m']['min'], 2)} / {fmt(x['min_sep_m']['p5'], 2)} / {fmt(x['min_sep_m']['median'], 2)} | "
            f"{fmt(x['extra_length_m']['median'])} / {fmt(x['extra_length_m']['p95'])} | "
            f"{d['replan']} / {d['switch']} / {d['hold']} / {d['none']} | "
            + " / ".join(f"{100 * k[c]:.0f} %" if k[c] is not None else "-" for c in ENCOUNTER_KINDS) + " |")
    lines += ["", "Decision latency (threat update -> new trajectory ready: conflict check, plan or splice, "
              "G2 smoothing, speed profile; goals: switch p99 <= 50 ms, replan p99 <= 250 ms):", "",
              "| policy | replan n / p50 / p99 (ms) | switch n / p50 / p99 (ms) | hold n / p50 / p99 (ms) |",
              "|---|---|---|---|"]
    for s in STRATEGIES:
        lat = summary[s]["latency"]
        lines.append(f"| {s} | " + " | ".join(
            f"{lat[k]['n']} / {fmt(lat[k]['p50_ms'])} / {fmt(lat[k]['p99_ms'])}" for k in ("replan", "switch", "hold"))
            + " |")
    lat = storm["latency_ms"]
    jit = storm["timer_50hz_jitter_ms"]
    lines += ["", f"Threat storm: {storm['sent']} PUTs at {storm['rate_hz']:.0f}/s over real zenoh (loopback TCP) "
              "into a ThreatBus handing them to an asyncio loop (decode, validate, table update):", "",
              "| sent | handled | lost | rejected | PUT -> handler p50 / p99 / max (ms) | "
              "50 Hz timer jitter p50 / p99 / max (ms) |", "|---|---|---|---|---|---|",
              f"| {storm['sent']} | {storm['handled']} | {storm['lost']} | {storm['rejected']} | "
              f"{fmt(lat['p50'], 2)} / {fmt(lat['p99'], 2)} / {fmt(lat['max'], 2)} | "
              f"{fmt(jit['p50'], 2)} / {fmt(jit['p99'], 2)} / {fmt(jit['max'], 2)} |"]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="50 encounters and a 2 s storm")
    parser.add_argument("--encounters", type=int, default=None, help="number of encounters (default 510)")
    parser.add_argument("--storm-s", type=float, default=None, help="storm duration in s (default 10)")
    parser.add_argument("--no-docs", action="store_true", help="do not write docs/benchmarks/threats.md")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    n = args.encounters or (51 if args.quick else 510)
    storm_s = args.storm_s or (2.0 if args.quick else 10.0)
    settings = ThreatSettings()
    t0 = time.perf_counter()
    storm = run_storm(storm_s)
    rows = run_encounters(n, settings)
    summary = summarize_encounters(rows)
    elapsed = time.perf_counter() - t0
    text = tables(summary, storm, len(rows))
    machine = (f"Machine: {platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores "
               f"(shared); run took {elapsed:.0f} s{' (--quick)' if args.quick else ''}.")
    print(text)
    print(machine)
    out = ROOT / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    (out / "threats.json").write_text(json.dumps({"summary": summary, "storm": storm, "settings": settings.__dict__,
                                                  "encounters": rows, "quick": args.quick,
                                                  "elapsed_s": elapsed}, indent=1, default=float))
    if not args.no_docs:
        doc = ROOT / "docs" / "benchmarks" / "threats.md"
        doc.parent.mkdir(parents=True, exist_ok=True)
        doc.write_text("# Threat reaction benchmark (`benchmarks/threats.py`)\n\n"
                       + (__doc__.split("\n\n", 1)[1].split("Prints a table")[0]).strip() + "\n\n"
                       + text + "\n\n" + machine + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
