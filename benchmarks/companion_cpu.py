"""CPU of ``companion run`` per second of flight, in SITL (issue 13: idle cost).

A real ``sim-vehicle`` and a real ``companion run`` (separate processes, as the integration
tests start them: ``companion.sitl.vehicles.flight_processes``) fly the demo mission
(``exclusion_zones.plan``: five legs, RTL) twice:

- ``plain``: zenoh on (the default configuration), no threat at all;
- ``threats``: the demo's threats (``companion.demo.DEMO_INJECTIONS``: a head-on mover, a
  pop-up, an invalid payload) put over zenoh while the legs are flown.

This process samples the companion's CPU time from ``/proc/<pid>/stat`` (user + system, its
own threads, MAVSDK's in-process C++ threads included) and, separately, that of its child
processes (the planning pool's workers), every ``SAMPLE_PERIOD_S``. Reported per flight:

- ``total``: CPU seconds of the companion (and of its children) over its whole life, divided
  by its wall-clock life (start-up, planning and landing included);
- ``legs``: the same over the legs only (zenoh status ``leg`` >= 0 and mode GUIDED), the steady
  state the goal is about (<= 5 % of one core with no threat).

``--profile DIR`` runs the companion under ``cProfile`` (``python -m cProfile -o``; the
event-loop thread only) and writes ``DIR/<flight>.prof``. ``--account`` runs it under
``benchmarks/loop_account.py`` and reports the event-loop thread's CPU over the legs per
callback (its own CPU clock: far closer to the truth than cProfile for small calls).

Usage::

    .venv/bin/python benchmarks/companion_cpu.py [--speedup 4] [--flights plain threats]

Prints a table and writes ``out/bench/companion_cpu.json`` and ``docs/benchmarks/companion_cpu.md``
(``docs/benchmarks/companion_cpu.notes.md`` keeps the analysis and the history by hand).
``--quick``: the plain flight only, at speed-up 4.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from companion import demo  # noqa: E402
from companion.sitl.procfs import descendants  # noqa: E402
from companion.sitl.vehicles import flight_processes  # noqa: E402
from companion.threats.transport.bus import ThreatBus  # noqa: E402

log = logging.getLogger("companion_cpu")

MISSION = REPO / "mission_files" / "exclusion_zones.plan"
#: How often the companion's CPU time is read (wall clock, s).
SAMPLE_PERIOD_S = 0.25
CLOCK_TICKS_S = os.sysconf("SC_CLK_TCK")
GOAL_LEGS_CPU = 0.05
DOC = REPO / "docs" / "benchmarks" / "companion_cpu.md"


def voluntary_switches(pid: int, tid) -> int:
    """A thread's voluntary context switches so far (``/proc/<pid>/task/<tid>/status``)."""
    try:
        with open(f"/proc/{pid}/task/{tid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("voluntary_ctxt_switches:"):
                    return int(line.split()[1])
    except FileNotFoundError:
        pass
    return 0


def process_cpu_s(pid: int) -> tuple[float, float]:
    """(own, waited-for children's) CPU seconds of ``pid`` (``/proc/<pid>/stat``)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    utime, stime, cutime, cstime = (int(v) for v in fields[11:15])
    return (utime + stime) / CLOCK_TICKS_S, (cutime + cstime) / CLOCK_TICKS_S


class CpuSampler:
    """Samples (wall s, own CPU s, children's CPU s) of a process, and a phase flag, in a thread."""

    def __init__(self, pid: int, in_legs, on_legs=None) -> None:
        self.pid = pid
        self.in_legs = in_legs
        self.on_legs = on_legs  # on_legs(True) when the legs begin, on_legs(False) when they end
        self._legs_state: bool | None = None
        self.samples: list[tuple[float, float, float, bool]] = []
        self._children: dict[int, float] = {}
        self.threads: dict[int, tuple[str, float, int]] = {}  # tid -> (name, CPU s, wake-ups)
        self.legs_first: tuple[float, dict] | None = None  # (monotonic s, threads) at the legs' start
        self.legs_last: tuple[float, dict] | None = None  # ... and at their latest sample
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpu-sampler", daemon=True)

    def _children_cpu_s(self, waited_s: float) -> float:
        for kid in descendants(self.pid):
            try:
                self._children[kid] = process_cpu_s(kid)[0]
            except (FileNotFoundError, ProcessLookupError):
                pass
        return max(waited_s, 0.0) + sum(self._children.values())

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                own, waited = process_cpu_s(self.pid)
            except (FileNotFoundError, ProcessLookupError):
                return
            legs = bool(self.in_legs())
            if self.on_legs is not None and legs is not self._legs_state and (legs or self._legs_state):
                self._legs_state = legs  # None (before) -> True -> False (after)
                self.on_legs(legs)
            self.samples.append((time.monotonic(), own, self._children_cpu_s(waited), legs))
            self._sample_threads()
            if legs:
                self.legs_last = (time.monotonic(), dict(self.threads))
                self.legs_first = self.legs_first or self.legs_last
            self._stop.wait(SAMPLE_PERIOD_S)

    def _sample_threads(self) -> None:
        """CPU seconds and wake-ups of each of the companion's threads (``/proc/<pid>/task``)."""
        try:
            tids = os.listdir(f"/proc/{self.pid}/task")
        except FileNotFoundError:
            return
        for tid in tids:
            try:
                with open(f"/proc/{self.pid}/task/{tid}/stat", encoding="ascii", errors="replace") as fh:
                    text = fh.read()
            except FileNotFoundError:
                continue
            name = text[text.index("(") + 1 : text.rindex(")")]
            fields = text.rsplit(")", 1)[1].split()
            self.threads[int(tid)] = (
                name,
                (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_S,
                voluntary_switches(self.pid, tid),
            )

    def _legs_delta(self, column: int) -> tuple[dict[str, float], float]:
        """Each thread's increase of ``column`` (1: CPU s, 2: wake-ups) over the legs, by
        "name/tid", and the legs' wall time (s)."""
        if self.legs_first is None or self.legs_last is None:
            return {}, 0.0
        (t0, first), (t1, last) = self.legs_first, self.legs_last
        return {
            f"{row[0]}/{tid}": row[column] - first.get(tid, (0, 0, 0))[column] for tid, row in last.items()
        }, t1 - t0

    def thread_cpu_s(self) -> dict[str, float]:
        """CPU seconds per thread over the legs ("name/tid", the largest first)."""
        out, _ = self._legs_delta(1)
        return dict(sorted(((k, round(v, 2)) for k, v in out.items() if v > 0.0), key=lambda kv: -kv[1]))

    def thread_wakeups_per_s(self) -> dict[str, float]:
        """Voluntary context switches (wake-ups after a wait) per second of each thread over
        the legs ("name/tid", the most first)."""
        out, wall_s = self._legs_delta(2)
        if wall_s <= 0.0:
            return {}
        return dict(
            sorted(((k, round(v / wall_s, 1)) for k, v in out.items() if v / wall_s >= 0.5), key=lambda kv: -kv[1])
        )

    def __enter__(self) -> CpuSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def rates(self) -> dict:
        """CPU per wall second over the whole life and over the legs."""
        s = self.samples
        out = {"wall_s": s[-1][0] - s[0][0], "cpu_s": s[-1][1], "children_cpu_s": s[-1][2]}
        out["cpu_per_s"] = (s[-1][1] - s[0][1]) / max(out["wall_s"], 1e-9)
        out["children_cpu_per_s"] = (s[-1][2] - s[0][2]) / max(out["wall_s"], 1e-9)
        legs = [x for x in s if x[3]]
        if len(legs) >= 2:
            wall = legs[-1][0] - legs[0][0]
            out["legs_wall_s"] = wall
            out["legs_cpu_per_s"] = (legs[-1][1] - legs[0][1]) / wall
            out["legs_children_cpu_per_s"] = (legs[-1][2] - legs[0][2]) / wall
        return out


def fly_and_measure(
    name: str, out_dir: Path, speedup: float, profile_dir: Path | None, companion_args=(), account: bool = False
) -> dict:
    """One flight of the demo mission; its CPU figures and summary."""
    injections = demo.DEMO_INJECTIONS if name == "threats" else ()
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    prefix: list[str] = []
    if profile_dir is not None:
        profile_dir.mkdir(parents=True, exist_ok=True)
        prefix = ["cProfile", "-o", str(profile_dir / f"{name}.prof"), "-m"]
    accounts = out_dir / "loop_account.json"
    if account:
        env["PYTHONPATH"] = str(REPO / "benchmarks") + os.pathsep + env["PYTHONPATH"]
        accounts.unlink(missing_ok=True)
        prefix = ["loop_account", str(accounts)]
    with flight_processes(
        out_dir, MISSION, speedup=speedup, env=env, extra_args=companion_args, companion_prefix=prefix
    ) as flight:
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = demo.FlightWatcher(bus)

            def in_legs() -> bool:
                st = watcher.status
                return bool(st) and st.get("leg", -1) >= 0 and st.get("mode") == "GUIDED"

            signal_legs = (
                (lambda legs: os.kill(flight.companion.pid, signal.SIGUSR1 if legs else signal.SIGUSR2))
                if account
                else None
            )
            with CpuSampler(flight.companion.pid, in_legs, signal_legs) as sampler:
                done = lambda: flight.companion.poll() is not None  # noqa: E731
                sent = demo.inject(watcher, injections, 300, done=done) if injections else []
                if sent:
                    time.sleep(2.0)
                    for threat in sent:
                        bus.client.delete_threat(threat.id)
                flight.companion.wait(300)
    summary = demo.last_json_line(flight.log) or {}
    return {
        "flight": name,
        "speedup": speedup,
        "rc": flight.companion.returncode,
        "outcome": summary.get("outcome"),
        "decisions": summary.get("decisions"),
        **sampler.rates(),
        "threads_cpu_s": sampler.thread_cpu_s(),
        "threads_wakeups_per_s": sampler.thread_wakeups_per_s(),
        "loop_account": json.loads(accounts.read_text()) if account and accounts.exists() else None,
    }


def table(results: list[dict]) -> str:
    head = (
        "| flight | outcome | wall (s) | CPU (s) | CPU/s whole life | CPU/s legs | workers CPU/s legs |"
        " goal legs <= 5 % |\n|---|---|---|---|---|---|---|---|"
    )
    rows = []
    for r in results:
        legs = r.get("legs_cpu_per_s", float("nan"))
        rows.append(
            f"| {r['flight']} | {r['outcome']} | {r['wall_s']:.1f} | {r['cpu_s']:.2f} | "
            f"{100 * r['cpu_per_s']:.1f} % | {100 * legs:.1f} % | "
            f"{100 * r.get('legs_children_cpu_per_s', float('nan')):.1f} % | "
            f"{'yes' if legs <= GOAL_LEGS_CPU else 'no'} |"
        )
    return "\n".join([head] + rows)


def doc(results: list[dict], meta: dict, argv) -> str:
    """``docs/benchmarks/companion_cpu.md``: the run's table and where each thread's CPU went."""
    lines = [
        "# CPU of `companion run` per second of flight (`benchmarks/companion_cpu.py`)",
        "",
        f"Generated by `benchmarks/companion_cpu.py {' '.join(argv)}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"{meta['cpus']} shared CPUs, 1-min load average {meta['load_average_1min']:.2f} at the end. "
        '"legs": from the first leg to the landing; "workers": the planning worker processes.',
        "",
        table(results),
        "",
    ]
    for r in results:
        lines.append(
            f"- {r['flight']}: CPU s per thread over {r.get('legs_wall_s', float('nan')):.0f} s of legs "
            f"{r['threads_cpu_s']}; wake-ups per second {r['threads_wakeups_per_s']}"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--speedup", type=float, default=4.0, help="SITL speed-up (and --time-scale)")
    parser.add_argument("--flights", nargs="+", default=["plain", "threats"], choices=["plain", "threats"])
    parser.add_argument("--profile", type=Path, default=None, help="cProfile the companion into DIR")
    parser.add_argument("--quick", action="store_true", help="the plain flight only, at speed-up 4")
    parser.add_argument(
        "--account",
        action="store_true",
        help="the event loop's CPU over the legs per callback (benchmarks/loop_account.py)",
    )
    parser.add_argument(
        "--companion-args", default="", help="more arguments for companion run (one string, split on spaces)"
    )
    parser.add_argument("--out", default=str(REPO / "out" / "bench" / "companion_cpu.json"))
    args = parser.parse_args(argv)
    if args.quick:
        args.flights, args.speedup = ["plain"], 4.0
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(args.out)
    results = [
        fly_and_measure(
            name,
            out.parent / f"companion_cpu_{name}",
            args.speedup,
            args.profile,
            args.companion_args.split(),
            args.account,
        )
        for name in args.flights
    ]
    meta = {"cpus": os.cpu_count(), "load_average_1min": os.getloadavg()[0], "mission": MISSION.name}
    print(table(results))
    for r in results:
        print(f"{r['flight']}: CPU s per thread over the legs {r['threads_cpu_s']}")
        print(f"{r['flight']}: wake-ups per second per thread over the legs {r['threads_wakeups_per_s']}")
        if r["loop_account"]:
            top = list(r["loop_account"]["by"].items())[:12]
            print(f"{r['flight']}: event loop over the legs, % of a core and calls/s, largest first: {top}")
    print(f"{meta['cpus']} CPUs shared; 1-min load average {meta['load_average_1min']:.2f} at the end")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"meta": meta, "results": results}, indent=2) + "\n")
    DOC.write_text(doc(results, meta, argv if argv is not None else sys.argv[1:]))
    return 0 if all(r["rc"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
