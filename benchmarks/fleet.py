"""Fleet: N helicopters crossing at one point, with and without trajectory sharing (DESIGN 6, 7).

For each N (``--vehicles 2,3,5,8``) this generates N crossing missions on a circle
(``companion.fleet.missions.crossing_missions``: homes ``--radius`` m from a common centre, each
flying through the centre to the far side and back home, at one altitude and speed, so that all
meet at the centre at about the same time) in a temporary directory, and flies them twice with
``companion.fleet.launcher.Fleet`` (one zenoh router, N ``sim-vehicle``, N ``companion run``):

- ``share``: the companions share their committed trajectories (the default);
- ``no-share``: ``companion run --no-fleet``, the baseline.

Reported per flight, judged from the simulators' own tlogs (``companion.fleet.tracks``):

- minimum pairwise separation and losses of separation (pairs that came closer than
  ``FleetSettings().separation_m``);
- missions completed, and the companions' largest tracking error (their summaries: a companion
  that cannot keep up tracks worse);
- extra path: flown length over the planned straight length (climb, legs, descent), per vehicle;
- CPU per vehicle: the companion and its planning workers (``/proc``, sampled), as % of one core
  over the fleet's wall time, and the simulator's;
- zenoh messages per second per vehicle: every sample on ``uav/**`` counted by a client session
  on the router, by the sysid of its key, over the flight's wall time;
- real time: each simulator's clock against the wall clock (``tracks.achieved_speedup``). When a
  simulator ran more than 2 % slow or stalled for more than 0.5 s, or the fleet's CPU reached
  ``SATURATED`` of the machine's cores, two cores did not keep real time at that N: the
  benchmark says so and stops there (larger N would only be slower).

Usage::

    .venv/bin/python benchmarks/fleet.py                        # N = 2, 3, 5, 8 at speed-up 1
    .venv/bin/python benchmarks/fleet.py --vehicles 2,3 --speedup 1
    .venv/bin/python benchmarks/fleet.py --quick                # N = 2 only

Prints a table, writes ``out/bench/fleet.json``, ``out/bench/fleet.md`` and
``docs/benchmarks/fleet.md`` (not with ``--no-docs``); each flight's logs and tlogs stay in
``out/bench/fleet/n<N>-<mode>/``. Not part of the test suite (nor of ``run_all.py`` yet).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.fleet.launcher import Fleet  # noqa: E402
from companion.fleet.missions import crossing_missions, planned_length_m, write_missions  # noqa: E402
from companion.fleet.settings import FleetSettings  # noqa: E402
from companion.fleet.tracks import fleet_separation  # noqa: E402
from companion.sitl.procfs import descendants  # noqa: E402

log = logging.getLogger("fleet_bench")

CLOCK_TICKS_S = os.sysconf("SC_CLK_TCK")
SAMPLE_PERIOD_S = 0.5
#: A simulator that ran this much slower than its speed-up did not keep real time.
SLOW_TOLERANCE = 0.02
#: ... nor one whose samples lagged the wall clock by more than this (s).
MAX_LAG_S = 0.5
#: Fraction of the machine's cores above which the fleet is CPU-bound.
SATURATED = 0.9
MODES = ("share", "no-share")


def cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of one process (its own threads), None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_S


class FleetSampler:
    """Samples, per vehicle, the CPU of its companion (+ every descendant: the planning workers)
    and of its simulator, in a thread; the last value seen of a process that is gone is kept."""

    def __init__(self, fleet: Fleet) -> None:
        self.fleet = fleet
        self.cpu: dict[int, dict[int, float]] = {v.sysid: {} for v in fleet.vehicles}  # sysid -> pid -> s
        self.sim_cpu: dict[int, float] = {v.sysid: 0.0 for v in fleet.vehicles}
        self.router_cpu = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fleet-sampler", daemon=True)

    def _sample(self) -> None:
        for v in self.fleet.vehicles:
            if v.companion is not None:
                for pid in [v.companion.pid] + descendants(v.companion.pid):
                    value = cpu_s(pid)
                    if value is not None:
                        self.cpu[v.sysid][pid] = value
            if v.sim is not None:
                value = cpu_s(v.sim.pid)
                if value is not None:
                    self.sim_cpu[v.sysid] = value
        if self.fleet.router is not None:
            value = cpu_s(self.fleet.router.pid)
            if value is not None:
                self.router_cpu = value

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_PERIOD_S):
            self._sample()

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._sample()
        self._stop.set()
        self._thread.join(2.0)

    def companion_cpu_s(self) -> dict[int, float]:
        return {sysid: sum(pids.values()) for sysid, pids in self.cpu.items()}


class ZenohCounter:
    """Counts every sample on ``uav/**`` by the sysid of its key (a client session on the router)."""

    def __init__(self, router: str) -> None:
        from companion.threats.transport.bus import ThreatBus

        self.bus = ThreatBus(255, listen=(), connect=(router,), mode="client").open()
        self.counts: dict[int, int] = {}
        self.bytes: dict[int, int] = {}
        self._lock = threading.Lock()
        self._sub = self.bus.session.declare_subscriber("uav/**", self._on_sample)

    def _on_sample(self, sample) -> None:
        parts = str(sample.key_expr).split("/")
        if len(parts) < 2 or not parts[1].isdigit():
            return
        sysid = int(parts[1])
        size = len(sample.payload.to_bytes())
        with self._lock:
            self.counts[sysid] = self.counts.get(sysid, 0) + 1
            self.bytes[sysid] = self.bytes.get(sysid, 0) + size

    def close(self) -> None:
        try:
            self._sub.undeclare()
        finally:
            self.bus.close()


def fly(n: int, mode: str, missions: list[Path], out_dir: Path, speedup: float, seed: int, timeout_s: float) -> dict:
    """One fleet flight; its numbers."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    fleet = Fleet(missions, out_dir, speedup=speedup, share=(mode == "share"), seed=seed, gcs_out=None, env=env)
    sampler = FleetSampler(fleet)
    counter = None
    t0 = time.monotonic()
    try:
        fleet.start()
        sampler.start()
        counter = ZenohCounter(fleet.router_endpoint)
        try:
            fleet.wait(timeout_s)
        except TimeoutError as exc:
            log.warning("N=%d %s: %s", n, mode, exc)
    finally:
        sampler.stop()
        if counter is not None:
            counter.close()
        result = fleet.stop()
    wall = time.monotonic() - t0
    required = FleetSettings().separation_m
    numbers = fleet_separation([v.tlog for v in fleet.vehicles], [v.sysid for v in fleet.vehicles])
    sep = numbers.pop("separation")
    planned = {v.sysid: planned_length_m(v.mission) for v in fleet.vehicles}
    extra = {s: (numbers["path_length_m"][s] - planned[s]) / planned[s] for s in planned}
    comp_cpu = sampler.companion_cpu_s()
    msgs = {s: (counter.counts.get(s, 0) if counter else 0) / wall for s in planned}
    decisions = {v.sysid: (v.summary or {}).get("decisions") for v in result.vehicles}
    tracking = [(v.summary or {}).get("max_tracking_error_m") for v in result.vehicles]
    tracking = [t for t in tracking if isinstance(t, (int, float)) and np.isfinite(t)]
    speeds = numbers["speedup"]
    slow = {s: sp for s, sp in speeds.items() if not sp >= speedup * (1 - SLOW_TOLERANCE)}
    lagged = {s: lag for s, lag in numbers["max_lag_s"].items() if not lag <= MAX_LAG_S}
    total_cpu = sum(comp_cpu.values()) + sum(sampler.sim_cpu.values()) + sampler.router_cpu
    cores = os.cpu_count() or 1
    return {
        "n": n,
        "mode": mode,
        "speedup": speedup,
        "wall_s": wall,
        "completed": sum(1 for v in result.vehicles if v.completed),
        "outcomes": [v.outcome for v in result.vehicles],
        "min_separation_m": sep.min_m,
        "closest_pair": numbers["closest_pair"],
        "losses": sep.losses(required),
        "pairs": len(sep.pair_min_m),
        "required_m": required,
        "pair_min_m": numbers["pair_min_m"],
        "extra_path": extra,
        "extra_path_mean": float(np.mean(list(extra.values()))),
        "extra_path_max": float(np.max(list(extra.values()))),
        "planned_m": planned,
        "flown_m": numbers["path_length_m"],
        "decisions": decisions,
        "max_tracking_error_m": max(tracking) if tracking else None,
        "companion_cpu_s": comp_cpu,
        "sim_cpu_s": sampler.sim_cpu,
        "router_cpu_s": sampler.router_cpu,
        "companion_cpu_per_s": {s: c / wall for s, c in comp_cpu.items()},
        "companion_cpu_mean": float(np.mean(list(comp_cpu.values()))) / wall,
        "sim_cpu_mean": float(np.mean(list(sampler.sim_cpu.values()))) / wall,
        "fleet_cores": total_cpu / wall,
        "cores": cores,
        "zenoh_msgs_per_s": msgs,
        "zenoh_msgs_mean": float(np.mean(list(msgs.values()))),
        "zenoh_bytes": dict(counter.bytes) if counter else {},
        "sim_speedup": speeds,
        "sim_max_lag_s": numbers["max_lag_s"],
        "real_time": not slow and not lagged and total_cpu / wall < SATURATED * cores,
        "real_time_note": (
            ""
            if not slow and not lagged and total_cpu / wall < SATURATED * cores
            else f"simulators slow {slow}, lagging {lagged}, fleet CPU {total_cpu / wall:.2f} of {cores} cores"
        ),
        "logs": str(out_dir),
    }


def fmt(value, spec: str = ".2f") -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return format(value, spec)


def table(rows: list[dict], meta: dict) -> str:
    lines = [
        f"## Fleet: N helicopters crossing at one point, trajectory sharing against none "
        f"(real processes at {meta['speedup']:g}x, {meta['cores']} cores)",
        "",
        f"Crossing missions on a circle of radius {meta['radius_m']:g} m, {meta['alt_m']:g} m up, "
        f"{meta['speed_m_s']:g} m/s, through the centre to {meta['beyond_m']:g} m beyond and back (RTL). "
        f"Separation required: {meta['required_m']:.1f} m (2 rotor radii + margin); judged from the "
        f"simulators' own tlogs. CPU: % of one core over the fleet's wall time (companion with its "
        f"planning workers; simulator). zenoh: samples on uav/** per second per vehicle.",
        "",
        "| N | mode | completed | min separation (m) | losses (pairs) | extra path mean / max | "
        "decisions | max tracking error (m) | companion CPU | sim CPU | fleet cores | zenoh msg/s/vehicle | "
        "real time | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        decisions = sum(d for d in r["decisions"].values() if isinstance(d, int))
        lines.append(
            f"| {r['n']} | {r['mode']} | {r['completed']}/{r['n']} | {fmt(r['min_separation_m'])} | "
            f"{r['losses']}/{r['pairs']} | {100 * r['extra_path_mean']:.1f} % / {100 * r['extra_path_max']:.1f} % | "
            f"{decisions} | {fmt(r.get('max_tracking_error_m'))} | {100 * r['companion_cpu_mean']:.1f} % | {100 * r['sim_cpu_mean']:.1f} % | "
            f"{r['fleet_cores']:.2f} | {r['zenoh_msgs_mean']:.1f} | {'yes' if r['real_time'] else 'no'} | "
            f"{r['wall_s']:.0f} |"
        )
    for note in meta.get("notes", []):
        lines += ["", note]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--vehicles", default="2,3,5,8", help="comma-separated N to fly (default 2,3,5,8)")
    parser.add_argument("--speedup", type=float, default=1.0, help="SITL speed-up (default 1: real time)")
    parser.add_argument("--modes", default=",".join(MODES), help="share,no-share (default both)")
    parser.add_argument("--radius", type=float, default=70.0, help="homes' distance from the centre, m")
    parser.add_argument("--beyond", type=float, default=30.0, help="far waypoint past the centre, m")
    parser.add_argument("--alt", type=float, default=15.0, help="altitude above home, m")
    parser.add_argument("--speed", type=float, default=7.0, help="cruise speed, m/s")
    parser.add_argument("--seed", type=int, default=0, help="seed (vehicle i: seed + i)")
    parser.add_argument("--timeout", type=float, default=600.0, help="wall s allowed per flight")
    parser.add_argument("--quick", action="store_true", help="N = 2 only")
    parser.add_argument("--no-docs", action="store_true", help="do not write docs/benchmarks/fleet.md")
    parser.add_argument("--out", default=str(ROOT / "out" / "bench" / "fleet.json"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    try:
        ns = [2] if args.quick else [int(v) for v in args.vehicles.split(",") if v.strip()]
    except ValueError:
        parser.error(f"--vehicles: expected comma-separated integers, got {args.vehicles!r}")
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    if not ns or any(n < 2 for n in ns):
        parser.error("--vehicles: every N must be >= 2")
    if any(m not in MODES for m in modes):
        parser.error(f"--modes: expected some of {','.join(MODES)}, got {args.modes!r}")
    out = Path(args.out)
    runs_dir = out.parent / "fleet"
    meta = {
        "speedup": args.speedup,
        "cores": os.cpu_count(),
        "radius_m": args.radius,
        "beyond_m": args.beyond,
        "alt_m": args.alt,
        "speed_m_s": args.speed,
        "required_m": FleetSettings().separation_m,
        "load_average_1min_start": os.getloadavg()[0],
        "notes": [],
    }
    rows: list[dict] = []
    for n in sorted(ns):
        with tempfile.TemporaryDirectory(prefix=f"fleet{n}-") as tmp:
            missions = write_missions(
                crossing_missions(n, radius_m=args.radius, beyond_m=args.beyond, alt_m=args.alt, speed_m_s=args.speed),
                tmp,
            )
            kept_up = True
            for mode in modes:
                row = fly(n, mode, missions, runs_dir / f"n{n}-{mode}", args.speedup, args.seed, args.timeout)
                rows.append(row)
                print(
                    f"N={n} {mode}: completed {row['completed']}/{n}, min separation "
                    f"{fmt(row['min_separation_m'])} m, losses {row['losses']}/{row['pairs']}, extra path "
                    f"{100 * row['extra_path_mean']:.1f} %, companion CPU {100 * row['companion_cpu_mean']:.1f} %, "
                    f"fleet {row['fleet_cores']:.2f} cores, zenoh {row['zenoh_msgs_mean']:.1f} msg/s/vehicle, "
                    f"simulators {row['sim_speedup']}, wall {row['wall_s']:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
                kept_up = kept_up and row["real_time"]
        if not kept_up:
            note = (
                f"N={n}: {os.cpu_count()} cores did not keep real time at speed-up {args.speedup:g} "
                f"({'; '.join(r['real_time_note'] for r in rows if r['n'] == n and r['real_time_note'])}); "
                f"larger N not flown."
            )
            meta["notes"].append(note)
            print(note, file=sys.stderr, flush=True)
            break
    meta["load_average_1min_end"] = os.getloadavg()[0]
    text = table(rows, meta)
    print(text)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=str) + "\n")
    out.with_suffix(".md").write_text(text)
    if not args.no_docs:
        (ROOT / "docs" / "benchmarks" / "fleet.md").write_text(text)
    return 0 if all(r["completed"] == r["n"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
