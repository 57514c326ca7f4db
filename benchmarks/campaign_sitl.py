"""SITL agreement of the validation campaign (issue 23): encounters of a campaign flown again by
real processes, their outcomes set against the fast-time rows.

For the first ``--n`` encounter ids of a campaign directory (ids cycle through the strata, so the
sample is spread evenly over them), the cluttered strata left out by default, the encounter is
flown in SITL by
``companion.campaign.replay.replay``: real ``sim-vehicle`` and ``companion run`` processes, the
reports put over zenoh at their encounter times, judged by the vehicle's own telemetry in the
flight record. The unmitigated flight does not depend on the intruders, so it is flown once per
mission (no report put) and judged against every encounter of that mission.

Reported: per encounter the fast-time and SITL flags (collision, NMAC, LoWC) of the mitigated
flight and whether all three agree; the agreement rate (goal >= 95 %); the SITL risk ratios
(SITL mitigated over SITL unmitigated) against the fast-time ratios of the same encounters and
their 95 % intervals (``companion.campaign.stats.risk_ratio``).

A series resumes: an encounter whose replay finished is judged again from its track
(``OUT/encounter-ID/track.npz``, the vehicle's telemetry from the record) or its record
(``done``) instead of flown again. ``--keep DIR`` copies the tracks there (about 10 kB an
encounter, small enough for the repository): ``--out DIR`` on them judges the series again, on
another machine, without flying. The cluttered strata are left out (``--skip``): ``companion
run`` plans a cluttered leg anew within a wall-clock budget, so its leg differs from the campaign's and the intruders aimed at
the campaign's leg meet another flight.

Writes ``out/bench/campaign_sitl.json`` and ``docs/benchmarks/campaign_sitl.md``.
Run: ``.venv/bin/python benchmarks/campaign_sitl.py --campaign DIR [--n 100] [--speedup 1] [--no-docs]``;
side by side: ``--shard 0/3``, ``--shard 1/3``, ``--shard 2/3`` into one ``--out``, then once more
without ``--shard`` (every encounter is then judged from its record).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from threats_sitl import decision_kind  # noqa: E402  (a sibling script: benchmarks/ is sys.path[0])

from companion.campaign.flying import CampaignWorker  # noqa: E402
from companion.campaign.replay import judge_track, judged, replay  # noqa: E402
from companion.campaign.runner import _settings_from_text  # noqa: E402
from companion.campaign.spec import spec_hash  # noqa: E402
from companion.campaign.stats import risk_ratio  # noqa: E402
from companion.campaign.store import CampaignStore  # noqa: E402
from companion.record.flight_record import load_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ("collision", "nmac", "lowc")
log = logging.getLogger("campaign_sitl")


def flown(worker, index: int, out: Path, speedup: float, mitigated: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The track (encounter times (K,), NED positions (K, 3)) of ``index``'s replay into ``out``.

    A finished replay keeps its track in ``OUT/.../track.npz`` (the vehicle's telemetry from the
    flight record, about 10 kB): a series resumes from the tracks, or from the records where
    no track was kept yet, and the tracks alone can be kept to judge the series again elsewhere.
    """
    track = out / "track.npz"
    if track.exists():
        with np.load(track) as npz:
            return npz["t_s"], npz["pos_ned_m"]
    if (out / "done").exists():
        got = judged(worker, worker.encounter(index), out / "flight.jsonl")
    else:
        got = replay(worker, index, out, speedup=speedup, mitigated=mitigated)
        (out / "done").write_text("")
    np.savez_compressed(track.with_suffix(".tmp.npz"), t_s=got.t_s, pos_ned_m=got.pos_ned_m)
    os.replace(track.with_suffix(".tmp.npz"), track)
    return got.t_s, got.pos_ned_m


def _unmitigated(worker, index: int, out: Path, speedup: float):
    """The mission's unmitigated flight: flown by the first series that needs it (it claims it),
    waited for by the others (shards of one series share it); a kept track needs no claim."""
    if not (out / "track.npz").exists():
        claim = out.parent / f"{out.name}.claim"
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.close(os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            while not (out / "track.npz").exists():
                time.sleep(2.0)
    return flown(worker, index, out, speedup, mitigated=False)


#: Decisions that change the reference because of a threat (their latency is the issue's goal).
MANOEUVRES = ("evade", "hold", "retime", "switch", "replan")


def decision_latencies(enc_dir: Path) -> list[tuple[str, float]]:
    """(kind, ms from the threat's receipt to the new reference's first setpoint on the wire) of
    every manoeuvre of the replay's record (none when only its track was kept)."""
    path = enc_dir / "flight.jsonl"
    if not path.exists():
        return []
    return [
        (decision_kind({**d, "event": d.get("kind")}), float(d["latency_ms"]))
        for d in load_record(path).decisions
        if d.get("kind") in MANOEUVRES and d.get("latency_ms") is not None
    ]


def latency_summary(results: list[dict]) -> dict:
    """p50 / p99 / max (ms) per decision kind over the series."""
    by: dict[str, list[float]] = {}
    for r in results:
        for kind, ms in r.get("latency_ms", []):
            by.setdefault(kind, []).append(ms)
    return {
        k: {"n": len(v), "p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)), "max": float(max(v))}
        for k, v in sorted(by.items())
    }


def fly_series(store: CampaignStore, ids: list[int], out: Path, speedup: float, fly: bool = True) -> list[dict]:
    """The series' entries; with ``fly`` False only the encounters whose tracks are there (and
    whose mission's unmitigated track is)."""
    spec, settings_text = store.spec(), store.settings_text()
    worker = CampaignWorker(spec, _settings_from_text(settings_text), spec_hash(spec, settings_text))
    rows = {r["id"]: r for r in store.table().to_pylist() if r["id"] in set(ids)}
    unmitigated: dict[str, tuple] = {}
    results = []
    for i in ids:
        enc = worker.encounter(i)
        enc_dir, base_dir = out / f"encounter-{i}", out / f"unmitigated-{enc.mission}"
        if not fly and not ((enc_dir / "track.npz").exists() and (base_dir / "track.npz").exists()):
            continue
        if enc.mission not in unmitigated:
            unmitigated[enc.mission] = _unmitigated(worker, i, base_dir, speedup)
        t0 = time.perf_counter()
        m = judge_track(enc, *flown(worker, i, enc_dir, speedup), spec.volumes)
        u = judge_track(enc, *unmitigated[enc.mission], spec.volumes)
        row = rows.get(i)
        entry = {
            "id": i,
            "stratum": enc.stratum,
            "weight": enc.weight,
            "wall_s": time.perf_counter() - t0,
            "sitl_m": {f: getattr(m, f) for f in FLAGS},
            "sitl_u": {f: getattr(u, f) for f in FLAGS},
            "sitl_m_min_sep_m": m.min_sep_m,
            "latency_ms": decision_latencies(enc_dir),
        }
        if row is not None:
            entry["fast_m"] = {f: row[f"m_{f}"] for f in FLAGS}
            entry["fast_u"] = {f: row[f"u_{f}"] for f in FLAGS}
            entry["fast_m_min_sep_m"] = row["m_min_sep_m"]
            entry["agree"] = entry["fast_m"] == entry["sitl_m"]
        results.append(entry)
        log.info("%d %s: SITL %s fast %s", i, enc.stratum, entry["sitl_m"], entry.get("fast_m"))
    return results


def ratios(results: list[dict], which: str) -> dict:
    out = {}
    w = np.array([r["weight"] for r in results])
    for flag in ("nmac", "lowc"):
        m = np.array([r[f"{which}_m"][flag] for r in results])
        u = np.array([r[f"{which}_u"][flag] for r in results])
        e = risk_ratio(m, u, w)
        out[flag] = {"value": e.value, "lo": e.lo, "hi": e.hi, "flag": e.flag}
    return out


def write_docs(summary: dict, path: Path) -> None:
    lines = [
        "# SITL agreement of the validation campaign",
        "",
        f"Generated by `benchmarks/campaign_sitl.py` on {summary['date']}: {summary['n']} encounters of "
        f"`{summary['campaign']}` (the first ids, spread over the strata) flown by real `sim-vehicle` and "
        f"`companion run` processes at speed-up {summary['speedup']:g}, judged by the vehicle's telemetry.",
        "",
        f"- outcome (collision, NMAC, LoWC of the mitigated flight) agrees with fast time in "
        f"**{summary['agreement']:.1%}** of {summary['n_compared']} encounters (goal >= 95 %)",
        "",
    ]
    lines += ["| ratio | SITL | fast time, same encounters [95 % CI] | SITL inside the CI |", "|---|---|---|---|"]
    for flag in ("nmac", "lowc"):
        s, f = summary["sitl_ratios"][flag], summary["fast_ratios"][flag]
        inside = f["lo"] <= s["value"] <= f["hi"] if np.isfinite(s["value"]) else False
        lines.append(
            f"| {flag.upper()} | {s['value']:.3g} | {f['value']:.3g} [{f['lo']:.3g}, {f['hi']:.3g}] | "
            f"{'yes' if inside else 'no'} |"
        )
    lines += [
        "",
        "Threat receipt -> the new reference's first setpoint on the wire (the companion's own "
        "measure, `latency_ms` of each decision in the replay's record; goals: 50 ms, 250 ms for a "
        "decision that replans):",
        "",
        "| decision | n | p50 (ms) | p99 (ms) | max (ms) |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {k} | {v['n']} | {v['p50']:.1f} | {v['p99']:.1f} | {v['max']:.1f} |"
        for k, v in summary.get("latency_ms", {}).items()
    ] or ["| (no decision recorded) | | | | |"]
    lines += ["", "Disagreements:", ""]
    lines += [
        f"- {r['id']} ({r['stratum']}): SITL {r['sitl_m']}, min sep {r['sitl_m_min_sep_m']:.2f} m; fast "
        f"{r['fast_m']}, min sep {r['fast_m_min_sep_m']:.2f} m"
        for r in summary["results"]
        if r.get("agree") is False
    ] or ["- none"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaign", required=True, help="campaign directory with rows")
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        help="sim-vehicle --speedup (default 1: the companion's compute takes its real share of "
        "mission time, as in flight)",
    )
    parser.add_argument("--out", default=str(ROOT / "out" / "bench" / "campaign_sitl"))
    parser.add_argument(
        "--skip",
        default="cluttered",
        help="leave out the strata whose name holds this (default: cluttered; '' for none)",
    )
    parser.add_argument(
        "--shard",
        default="0/1",
        metavar="I/N",
        help="fly every N-th encounter from the I-th (shards run side by side into one --out and "
        "share the unmitigated flights; then run once without --shard to judge all)",
    )
    parser.add_argument(
        "--no-fly",
        dest="fly",
        action="store_false",
        help="judge only the encounters whose tracks are in --out (a series cut short, or kept)",
    )
    parser.add_argument("--keep", metavar="DIR", help="copy the series' tracks (track.npz) into DIR")
    parser.add_argument("--no-docs", dest="docs", action="store_false")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    for name in ("companion", "heli_model"):
        logging.getLogger(name).setLevel(logging.WARNING)
    store = CampaignStore(args.campaign)
    names = store.spec().stratum_list
    ids = [i for i in range(10 * args.n) if not (args.skip and args.skip in names[i % len(names)])][: args.n]
    try:
        shard, shards = (int(x) for x in args.shard.split("/"))
        if not 0 <= shard < shards:
            raise ValueError
    except ValueError:
        parser.error(f"--shard: expected I/N with 0 <= I < N, got {args.shard!r}")
    results = fly_series(store, ids[shard::shards], Path(args.out), args.speedup, args.fly)
    if args.keep:
        for track in Path(args.out).glob("*/track.npz"):
            kept = Path(args.keep) / track.parent.name / track.name
            kept.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(track, kept)
    if shards > 1:
        return 0
    compared = [r for r in results if "agree" in r]
    summary = {
        "date": time.strftime("%Y-%m-%d"),
        "campaign": str(args.campaign),
        "n": len(results),
        "speedup": args.speedup,
        "n_compared": len(compared),
        "agreement": float(np.mean([r["agree"] for r in compared])) if compared else float("nan"),
        "sitl_ratios": ratios(results, "sitl"),
        "fast_ratios": ratios(compared, "fast") if compared else {},
        "latency_ms": latency_summary(results),
        "results": results,
    }
    out_json = ROOT / "out" / "bench" / "campaign_sitl.json"
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(summary, indent=2, default=float))
    if args.docs and compared:
        write_docs(summary, ROOT / "docs" / "benchmarks" / "campaign_sitl.md")
    print(json.dumps({k: v for k, v in summary.items() if k != "results"}, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
