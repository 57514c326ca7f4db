"""``companion campaign``: the validation campaign (DESIGN section 13; docs/VALIDATION.md).

Actions:

- ``run SPEC.toml --out DIR [--workers N | --cluster tcp://HOST:8786] [--max-pairs N]``: fly
  the spec's encounters twice each in fast time, rows into ``DIR/rows/*.parquet``; resumes what
  ``DIR`` holds; stops when every ratio has converged (or at ``max_pairs``);
- ``status DIR``: pairs stored, throughput, the current ratios and whether they converged;
- ``label DIR``: the oracle's labels of the mitigated drone-scale collisions and NMACs
  (``DIR/labels.parquet``: could any feasible manoeuvre have avoided them?);
- ``report DIR``: ``DIR/report/report.md`` and its plots (miss distances, convergence,
  per-stratum ratios, the oracle's labels when made, the worst encounters flown again);
- ``pack DIR``: every batch's part packed into one zstd Parquet file (about 13 MB per 10^5
  pairs), to keep a campaign in a repository and resume it on another machine;
- ``replay DIR ID [--speedup X] [--foxglove PORT]``: fly encounter ``ID`` in SITL (real
  ``sim-vehicle`` and ``companion run``, the reports over zenoh or, for manned traffic, as
  ADSB_VEHICLE through the vehicle), judged by the vehicle's own telemetry, next to its
  fast-time row;
- ``strata``: the strata a spec can name.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from companion.errors import CompanionError

__all__ = ["register"]

log = logging.getLogger(__name__)

EPILOG = """examples:
  companion campaign run mission_files/campaigns/quick.toml --out out/campaign-quick
  companion campaign status out/campaign-quick
  companion campaign label out/campaign-quick
  companion campaign report out/campaign-quick
  companion campaign pack out/campaign-quick
  companion campaign replay out/campaign-quick 12 --foxglove 8765
  dask scheduler & dask worker tcp://127.0.0.1:8786 &
  companion campaign run mission_files/campaigns/full.toml --out out/full --cluster tcp://127.0.0.1:8786
"""


class CampaignCommandError(CompanionError):
    """A campaign command's arguments are wrong."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "campaign",
        help="validation campaign: encounters flown twice, risk ratios",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="campaign_command", metavar="ACTION")
    sub.required = True
    run = sub.add_parser(
        "run", help="run (or resume) a campaign", epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    run.add_argument("spec", help="campaign spec (TOML; see mission_files/campaigns/)")
    run.add_argument("--out", required=True, help="campaign directory (made, or resumed)")
    where = run.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="local worker processes (default: every core)")
    where.add_argument("--cluster", help="Dask scheduler address, e.g. tcp://127.0.0.1:8786")
    run.add_argument(
        "--max-pairs",
        dest="max_pairs",
        type=int,
        help="stop after this many pairs in all (at most the spec's max_pairs)",
    )
    run.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    status = sub.add_parser("status", help="pairs stored and the current ratios")
    status.add_argument("dir", help="campaign directory")
    status.add_argument("--json", action="store_true", help="print the summary as JSON")
    label = sub.add_parser(
        "label",
        help="label the mitigated drone-scale collisions and NMACs with the oracle "
        "(DIR/labels.parquet: avoidable or not)",
    )
    label.add_argument("dir", help="campaign directory")
    report = sub.add_parser("report", help="write DIR/report/report.md and its plots")
    report.add_argument("dir", help="campaign directory")
    report.add_argument("--worst", type=int, default=8, help="worst encounters flown again and plotted")
    pack = sub.add_parser("pack", help="pack the batches' parts into one compressed file (to keep or move DIR)")
    pack.add_argument("dir", help="campaign directory")
    replay = sub.add_parser("replay", help="fly one encounter in SITL (sim-vehicle + companion run)")
    replay.add_argument("dir", help="campaign directory")
    replay.add_argument("id", type=int, help="encounter id (a row's id)")
    replay.add_argument("--out", help="where the logs and the record go (default DIR/replay/ID)")
    replay.add_argument("--speedup", type=float, default=2.0, help="sim-vehicle --speedup (default 2)")
    replay.add_argument("--foxglove", metavar="[HOST:]PORT", help="the companion's Foxglove server, to watch")
    replay.add_argument("--gcs", metavar="HOST:PORT", help="another MAVLink output of the vehicle (QGroundControl)")
    sub.add_parser("strata", help="list the strata a spec can name")
    p.set_defaults(func=main)


#: Campaign subcommand -> the optional modules it needs (all from the ``campaign`` extra).
CAMPAIGN_NEEDS = {
    "run": ("pyarrow", "distributed"),
    "status": ("pyarrow",),
    "label": ("pyarrow",),
    "report": ("pyarrow", "matplotlib"),
    "pack": ("pyarrow",),
    "replay": ("pyarrow",),
    "strata": (),
}


def main(args) -> int:
    from companion.extras import require

    for module in CAMPAIGN_NEEDS[args.campaign_command]:
        require("campaign", module)
    return {
        "run": _run,
        "status": _status,
        "label": _label,
        "report": _report,
        "pack": _pack,
        "replay": _replay,
        "strata": _strata,
    }[args.campaign_command](args)


def _spec_and_settings(path: str):
    from companion.campaign.spec import load_spec

    spec = load_spec(path)
    text = ""
    if spec.settings:
        settings_path = Path(spec.settings)
        if not settings_path.is_absolute():
            settings_path = Path(path).resolve().parent / settings_path
        if not settings_path.exists():
            raise CampaignCommandError(f"{path}: settings: no such file {settings_path}")
        text = settings_path.read_text()
        from companion.config import load_settings

        load_settings(settings_path)  # a bad settings file fails here, not in a worker
    return spec, text


def _progress_bar(enabled: bool):
    if not enabled or not sys.stderr.isatty():

        def log_progress(p) -> None:
            log.info(
                "campaign: %d/%d pairs, %.2f pairs/s%s",
                p.done,
                p.total,
                p.pairs_per_s,
                "".join(f", {k} RR {v.ratio:.3g}" for k, v in p.ratios.items()),
            )

        return log_progress, lambda: None
    from companion.extras import require

    require("campaign", "rich")
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn("campaign"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(),
        TextColumn("{task.fields[ratios]}"),
        transient=False,
    )
    bar.start()
    task = bar.add_task("pairs", total=None, ratios="")

    def show(p) -> None:
        ratios = " ".join(f"{k} {v.ratio:.3g}{'' if v.converged else '?'}" for k, v in p.ratios.items())
        bar.update(task, completed=p.done, total=p.total, ratios=f"{p.pairs_per_s:.2f}/s {ratios}")

    return show, bar.stop


def _run(args) -> int:
    from companion.campaign.runner import CampaignRun
    from companion.campaign.store import CampaignStore

    if args.workers is not None and args.workers < 1:
        raise CampaignCommandError(f"--workers: must be >= 1, got {args.workers}")
    if args.max_pairs is not None and args.max_pairs < 1:
        raise CampaignCommandError(f"--max-pairs: must be >= 1, got {args.max_pairs}")
    spec, settings_text = _spec_and_settings(args.spec)
    show, stop = _progress_bar(args.progress)
    try:
        run = CampaignRun(
            spec,
            CampaignStore(args.out),
            settings_text,
            workers=args.workers,
            cluster=args.cluster,
            progress=show,
            max_pairs=args.max_pairs,
        )
        result = run.run()
    finally:
        stop()
    print(json.dumps(result, indent=2))
    return 0


def _status(args) -> int:
    from companion.campaign.runner import convergence_verdicts
    from companion.campaign.store import CampaignStore
    from companion.campaign.summary import summarise

    store = CampaignStore(args.dir)
    spec = store.spec()
    table = store.table()
    if table.num_rows == 0:
        print(f"{args.dir}: campaign {spec.name!r}, no pairs stored yet")
        return 0
    summary = summarise(table)
    verdicts = convergence_verdicts(table, spec.tolerance)
    cpu_ms = [c for c in table.column("cpu_ms").to_pylist() if c is not None]
    cpu_s = sum(cpu_ms) / 1e3
    out = {
        "campaign": spec.name,
        "pairs": table.num_rows,
        "max_pairs": spec.max_pairs,
        "cpu_s_measured_pairs": cpu_s,
        "pairs_per_cpu_s": len(cpu_ms) / cpu_s if cpu_s > 0 else None,
        "converged": {k: (v.converged, v.reason) for k, v in verdicts.items()},
        "summary": summary.to_dict(),
    }
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=True))
        return 0
    print(
        f"campaign {spec.name!r}: {table.num_rows} pairs of {spec.max_pairs}, "
        f"{out['pairs_per_cpu_s'] or 0:.2f} pairs per CPU second (flying and judging, over the pairs timed)"
    )
    for group in summary.traffic:
        print(
            f"  {group.name:10s} n={group.n:7d}  NMAC RR {_estimate(group.nmac.risk_ratio)}  "
            f"LoWC RR {_estimate(group.lowc.risk_ratio)}"
        )
    for key, verdict in verdicts.items():
        print(
            f"  {key:16s} RR {verdict.ratio:.3g}: "
            f"{'converged' if verdict.converged else 'not converged: ' + verdict.reason}"
        )
    return 0


def _estimate(e) -> str:
    return f"{e.value:.3g} [{e.lo:.3g}, {e.hi:.3g}]"


def _stored(path: str):
    """(store, rows, worker) of a campaign directory with rows."""
    from companion.campaign.flying import CampaignWorker
    from companion.campaign.runner import _settings_from_text
    from companion.campaign.store import CampaignStore

    store = CampaignStore(path)
    spec = store.spec()
    table = store.table()
    if table.num_rows == 0:
        raise CampaignCommandError(f"{path}: no pairs stored yet (run the campaign first)")
    worker = CampaignWorker(spec, _settings_from_text(store.settings_text()), table.column("spec_hash")[0].as_py())
    return store, table, worker


def _label(args) -> int:
    from companion.campaign.labels import label_campaign

    store, table, worker = _stored(args.dir)
    labels = label_campaign(worker, table, store.root).to_pylist()
    counts = {
        e: (
            sum(1 for lab in labels if lab["event"] == e and lab["avoidable"]),
            sum(1 for lab in labels if lab["event"] == e),
        )
        for e in ("collision", "nmac")
    }
    print(json.dumps({f"{e}_avoidable_of_labelled": list(v) for e, v in counts.items()}))
    return 0


def _pack(args) -> int:
    from companion.campaign.store import CampaignStore

    store = CampaignStore(args.dir)
    store.spec()  # a campaign directory, or a clear error
    path = store.pack()
    if path is None:
        print(f"{args.dir}: nothing to pack (no parts)")
    else:
        print(f"{path}: {store.table().num_rows} pairs stored, {path.stat().st_size / 1e6:.1f} MB")
    return 0


def _report(args) -> int:
    from companion.campaign.labels import read_labels
    from companion.campaign.report import write_report

    store, table, worker = _stored(args.dir)
    path = write_report(
        table,
        store.root / "report",
        spec_name=store.spec().name,
        worst=args.worst,
        flight_of=worker.fly,
        labels=read_labels(store.root).to_pylist(),
    )
    print(path)
    return 0


def _replay(args) -> int:
    from companion.campaign.flying import CampaignWorker
    from companion.campaign.replay import replay
    from companion.campaign.runner import _settings_from_text
    from companion.campaign.spec import spec_hash
    from companion.campaign.store import CampaignStore

    if args.id < 0:
        raise CampaignCommandError(f"id: must be >= 0, got {args.id}")
    if not args.speedup > 0:
        raise CampaignCommandError(f"--speedup: must be > 0, got {args.speedup}")
    store = CampaignStore(args.dir)
    spec, settings_text = store.spec(), store.settings_text()
    worker = CampaignWorker(spec, _settings_from_text(settings_text), spec_hash(spec, settings_text))
    out = Path(args.out) if args.out else store.root / "replay" / str(args.id)
    result = replay(worker, args.id, out, speedup=args.speedup, foxglove=args.foxglove, gcs_out=args.gcs)
    outcome = result.outcome()
    row = next(
        (r for r in store.table().filter([i == args.id for i in store.table().column("id").to_pylist()]).to_pylist()),
        None,
    )
    if row is not None:
        outcome["fast_time"] = {k: row[f"m_{k}"] for k in ("collision", "nmac", "lowc", "min_sep_m")}
    print(json.dumps(outcome, indent=2))
    return 0


def _strata(args) -> int:
    from companion.campaign.strata import STRATA

    for s in STRATA.values():
        print(
            f"{s.name:24s} {s.source:10s} mission {s.mission:8s}{' robustness ' + s.robustness if s.robustness else ''}"
        )
    return 0
