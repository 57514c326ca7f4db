"""Oracle labels of a campaign's events: could any feasible manoeuvre have kept clear?

A mitigated flight that met an intruder's collision or NMAC volume is judged against what was
possible at all: ``companion.campaign.oracle.label_encounter`` (a brute-force search over a
point mass's manoeuvres within the helicopter's limits, written independently of the policy)
starts at the instant of the first report, from the unmitigated flight's state then (no
reaction time: an upper bound of what any policy could do), and flies against the intruders'
true tracks (turns and climbs included) in the mission's bare world (the obstacles and fences
without the planner's margin) until two seconds past the last closest approach, at least for
the oracle's 12 s. The allowance beyond the bare radius is the event's volume
(``Volumes.collision_extra_m``, ``nmac_extra_m``): *avoidable* means some manoeuvre stays out of
that volume.

Only drone-scale rows with the event are labelled (manned traffic's volumes are hundreds of
feet: the oracle's 12 s window does not cover them). Labels go to ``DIR/labels.parquet`` (one
row per labelled event), computed once; ``label_campaign`` labels what is not labelled yet.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from companion.campaign.oracle import OracleLimits, label_encounter
from companion.world import World

__all__ = ["LABEL_SCHEMA", "EVENTS", "label_event", "label_campaign", "read_labels"]

#: The events labelled, and their volume's allowance in ``Volumes``.
EVENTS = {"collision": "collision_extra_m", "nmac": "nmac_extra_m"}
#: The oracle's window runs this long past the last closest approach (s).
PAST_CPA_S = 2.0

LABEL_SCHEMA = pa.schema(
    [
        ("id", pa.int64()),
        ("event", pa.string()),
        ("avoidable", pa.bool_()),
        ("best_margin_m", pa.float64()),
        ("witness", pa.string()),
        ("horizon_s", pa.float64()),
        ("oracle_ms", pa.float64()),
    ]
)


def _horizon_s(enc, limits: OracleLimits) -> float:
    cpa = float(enc.params.get("t_cpa_s", enc.first_report_t_s))
    need = cpa + PAST_CPA_S - enc.first_report_t_s
    return max(limits.horizon_s, math.ceil(need / limits.control_step_s) * limits.control_step_s)


def label_event(worker, index: int, event: str) -> dict:
    """The label of encounter ``index`` of ``worker``'s campaign for ``event`` (``EVENTS``).

    Returns
    -------
    dict
        A row of ``LABEL_SCHEMA``.
    """
    if event not in EVENTS:
        raise ValueError(f"event: expected one of {', '.join(EVENTS)}, got {event!r}")
    enc = worker.encounter(index)
    if enc.traffic != "drone":
        raise ValueError(f"encounter {index}: manned traffic is not labelled (its volumes exceed the oracle's window)")
    mission, base = worker.mission(enc.mission), worker.unmitigated(enc.mission)
    t0 = enc.first_report_t_s
    pos0 = np.array([np.interp(t0, base.t_s, base.pos_ned_m[:, a]) for a in range(3)])
    k = min(int(np.searchsorted(base.t_s, t0)), len(base.t_s) - 1)
    k0 = max(k - 1, 0)
    vel0 = (base.pos_ned_m[k] - base.pos_ned_m[k0]) / max(base.t_s[k] - base.t_s[k0], 1e-9)
    allowance = getattr(worker.spec.volumes, EVENTS[event])
    limits = OracleLimits(threat_allowance_m=allowance)
    limits = dataclasses.replace(limits, horizon_s=_horizon_s(enc, limits))
    world = World(
        list(mission.obstacles) + list(mission.fences), mission.bounds_min_ned_m, mission.bounds_max_ned_m, margin_m=0.0
    )
    res = label_encounter(pos0, vel0, list(enc.intruders), t0, world, limits=limits)
    return {
        "id": int(index),
        "event": event,
        "avoidable": bool(res.avoidable),
        "best_margin_m": float(res.best_margin_m),
        "witness": "" if res.witness is None else res.witness.manoeuvre.name,
        "horizon_s": float(limits.horizon_s),
        "oracle_ms": float(res.elapsed_ms),
    }


def read_labels(root: str | Path) -> pa.Table:
    """The labels written (an empty table when none)."""
    path = Path(root) / "labels.parquet"
    if not path.exists():
        return LABEL_SCHEMA.empty_table()
    return pq.read_table(path).cast(LABEL_SCHEMA)


def label_campaign(worker, table: pa.Table, root: str | Path) -> pa.Table:
    """Label every drone-scale mitigated event of ``table`` not labelled yet; returns all labels.

    Parameters
    ----------
    worker : CampaignWorker
        Of the campaign's spec.
    table : pyarrow.Table
        The campaign's rows (``CampaignStore.table``).
    root : path
        The campaign directory (``labels.parquet`` is written there, atomically).
    """
    done = read_labels(root)
    have = set(zip(done.column("id").to_pylist(), done.column("event").to_pylist()))
    rows = table.select(["id", "traffic"] + [f"m_{e}" for e in EVENTS]).to_pylist()
    todo = [
        (r["id"], e)
        for r in rows
        if r["traffic"] == "drone"
        for e in EVENTS
        if r[f"m_{e}"] and (r["id"], e) not in have
    ]
    if not todo:
        return done
    new = pa.Table.from_pylist([label_event(worker, i, e) for i, e in todo], schema=LABEL_SCHEMA)
    out = pa.concat_tables([done, new]).sort_by([("id", "ascending"), ("event", "ascending")])
    path = Path(root) / "labels.parquet"
    tmp = path.with_suffix(".parquet.tmp")
    pq.write_table(out, tmp)
    os.replace(tmp, path)
    return out
