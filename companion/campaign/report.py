"""The campaign report: ``report.md`` with its tables, and the PNG figures beside it.

:func:`write_report` summarises the rows (:func:`companion.campaign.summary.summarise`),
draws the figures (:mod:`companion.campaign.report_plots`) and writes the Markdown. Numbers
have 3 significant digits, intervals are in brackets; the estimators' methods are those of
:mod:`companion.campaign.stats`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from companion.campaign.report_plots import plot_convergence, plot_flight, plot_miss_distances, plot_ratio_bars
from companion.campaign.stats import (
    CONVERGENCE_FLOOR,
    CONVERGENCE_HALF_WIDTH,
    CONVERGENCE_MIN_CHECKPOINTS,
    CONVERGENCE_TAIL,
    CONVERGENCE_TOL,
    Estimate,
)
from companion.campaign.summary import (
    EVENTS,
    CampaignSummary,
    Columns,
    GroupSummary,
    campaign_columns,
    event_convergence,
    summarise,
)

__all__ = ["write_report", "worst_encounters", "fmt_number", "fmt_estimate", "render_markdown"]

log = logging.getLogger(__name__)

_FLAG_NOTES = {
    "zero_with": "no event with the system: the ratio is 0 and the bound one-sided",
    "zero_without": "no event without the system: the ratio is infinite",
    "no_events": "no event with or without the system: the ratio is undefined",
    "empty": "no encounter",
}


def fmt_number(x: float) -> str:
    """``x`` to 3 significant digits (``n/a`` for NaN, ``inf``), positional unless tiny or huge."""
    x = float(x)
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if x == 0:
        return "0"
    if 1e-4 <= abs(x) < 1e6:
        return np.format_float_positional(float(f"{x:.3g}"), trim="-")
    return f"{x:.3g}"


def fmt_estimate(e: Estimate) -> str:
    """``value [lo, hi]``, with the flag after an undefined or one-sided one."""
    if e.flag in ("no_events", "empty"):
        return f"n/a ({e.flag.replace('_', ' ')})"
    text = f"{fmt_number(e.value)} [{fmt_number(e.lo)}, {fmt_number(e.hi)}]"
    return f"{text} ({e.flag.replace('_', ' ')})" if e.flag else text


def worst_encounters(cols: Columns, k: int) -> np.ndarray:
    """Indices (k,) of the worst mitigated encounters: collisions first, then NMACs, then the
    smallest ``m_min_sep_m`` (the largest separation deficit)."""
    sep = cols["m_min_sep_m"].astype(float)
    sep = np.where(np.isfinite(sep), sep, np.inf)
    order = np.lexsort((sep, ~cols["m_nmac"].astype(bool), ~cols["m_collision"].astype(bool)))
    return order[: max(k, 0)]


def _row(cells: Sequence[object]) -> str:
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


def _table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    return [_row(header), _row(["---"] * len(header)), *(_row(r) for r in rows), ""]


def _risk_table(groups: Sequence[GroupSummary]) -> list[str]:
    header = ["group", "N", "n_eff", "NMAC u", "NMAC m", "RR NMAC", "LoWC u", "LoWC m", "RR LoWC", "converged"]
    rows = [
        [
            g.name,
            g.n,
            fmt_number(g.n_eff),
            fmt_number(g.nmac.u_rate.value),
            fmt_number(g.nmac.m_rate.value),
            fmt_estimate(g.nmac.risk_ratio),
            fmt_number(g.lowc.u_rate.value),
            fmt_number(g.lowc.m_rate.value),
            fmt_estimate(g.lowc.risk_ratio),
            "yes" if g.converged else "no",
        ]
        for g in groups
    ]
    return _table(header, rows)


def _cost_table(groups: Sequence[GroupSummary]) -> list[str]:
    header = [
        "group",
        "induced NMAC",
        "induced LoWC",
        "unnecessary",
        "collisions u / m",
        "completion u",
        "completion m",
        "extra path mean / p50 (m)",
        "latency p50 / p99 (ms)",
    ]
    rows = [
        [
            g.name,
            fmt_estimate(g.nmac.induced),
            fmt_estimate(g.lowc.induced),
            fmt_estimate(g.unnecessary),
            f"{g.u_collisions} / {g.m_collisions}",
            fmt_number(g.u_completion.value),
            fmt_estimate(g.m_completion),
            f"{fmt_number(g.extra_path_mean_m)} / {fmt_number(g.extra_path_p50_m)}",
            f"{fmt_number(g.latency.p50_ms)} / {fmt_number(g.latency.p99_ms)}",
        ]
        for g in groups
    ]
    return _table(header, rows)


def _overall_section(g: GroupSummary) -> list[str]:
    rows = [["encounters N (effective n)", f"{g.n} ({fmt_number(g.n_eff)})"]]
    for ev in (g.nmac, g.lowc):
        rows += [
            [f"P({ev.event}) without the system", fmt_estimate(ev.u_rate)],
            [f"P({ev.event}) with the system", fmt_estimate(ev.m_rate)],
            [f"risk ratio {ev.event}", fmt_estimate(ev.risk_ratio)],
            [f"induced {ev.event} (with, not without)", fmt_estimate(ev.induced)],
            [f"{ev.event} ratio converged", "yes" if ev.convergence.converged else f"no: {ev.convergence.reason}"],
        ]
    rows += [
        ["unnecessary manoeuvres (unmitigated stayed well clear)", fmt_estimate(g.unnecessary)],
        ["alerted", fmt_estimate(g.alerted)],
        ["collisions without / with (count)", f"{g.u_collisions} / {g.m_collisions}"],
        ["completion without", fmt_estimate(g.u_completion)],
        ["completion with", fmt_estimate(g.m_completion)],
        ["extra path mean / p50 (m)", f"{fmt_number(g.extra_path_mean_m)} / {fmt_number(g.extra_path_p50_m)}"],
        ["decision latency p50 / p99 (ms)", f"{fmt_number(g.latency.p50_ms)} / {fmt_number(g.latency.p99_ms)}"],
    ]
    return ["## Overall", "", *_table(["metric", "value [95 % CI]"], rows)]


def _convergence_section(summary: CampaignSummary, figure: str) -> list[str]:
    lines = [
        "## Convergence",
        "",
        f"![risk ratio against N]({figure})",
        "",
        f"A ratio has converged when it stays within {CONVERGENCE_TOL:.0%} of max(RR, {CONVERGENCE_FLOOR:g}) "
        f"from its final value over the last {CONVERGENCE_TAIL:.0%} of the encounters, at "
        f"{CONVERGENCE_MIN_CHECKPOINTS} checkpoints or more, and its 95 % CI half-width is at most "
        f"{CONVERGENCE_HALF_WIDTH:g} times max(RR, {CONVERGENCE_FLOOR:g}).",
        "",
    ]
    rows = [
        [g.name, ev.event, "yes" if ev.convergence.converged else "no", ev.convergence.reason]
        for g in (summary.overall, *summary.strata, *summary.traffic)
        for ev in (g.nmac, g.lowc)
    ]
    return lines + _table(["group", "event", "converged", "reason"], rows)


def _latency_section(g: GroupSummary) -> list[str]:
    rows = [
        [
            s.kind,
            s.n,
            fmt_number(s.p50_ms),
            fmt_number(s.p99_ms),
            fmt_number(s.compute_p50_ms),
            fmt_number(s.compute_p99_ms),
        ]
        for s in (g.latency, *g.latency_by_kind)
    ]
    return [
        "## Decision latency",
        "",
        "From each decision's trigger to its first setpoint, on the virtual "
        "clock (not weighted): the modelled job durations of the spec's `[latency]`. Beside it, the "
        "decisions' own compute as measured on the workers (this machine, its load).",
        "",
        *_table(
            ["decision", "n", "p50 (ms)", "p99 (ms)", "measured compute p50 (ms)", "measured compute p99 (ms)"], rows
        ),
    ]


def _worst_section(cols: Columns, idx: np.ndarray, flight_figures: dict[int, str]) -> list[str]:
    rows = []
    for rank, i in enumerate(idx, 1):
        decisions = cols["m_decisions"][i]
        rows.append(
            [
                rank,
                int(cols["id"][i]),
                cols["stratum"][i],
                cols["traffic"][i],
                cols["world"][i] if "world" in cols else "",
                int(cols["seed"][i]) if "seed" in cols else "",
                "yes" if cols["m_collision"][i] else "no",
                "yes" if cols["m_nmac"][i] else "no",
                fmt_number(cols["u_min_sep_m"][i]),
                fmt_number(cols["m_min_sep_m"][i]),
                ", ".join(decisions) if len(decisions) else "none",
            ]
        )
    header = [
        "#",
        "id",
        "stratum",
        "traffic",
        "world",
        "seed",
        "collision m",
        "NMAC m",
        "min sep u (m)",
        "min sep m (m)",
        "decisions",
    ]
    lines = [
        "## Worst encounters",
        "",
        "Mitigated collisions first, then NMACs, then the smallest separation with the system.",
        "",
        *_table(header, rows),
    ]
    for i in idx:
        enc = int(cols["id"][i])
        if enc in flight_figures:
            lines += [f"![encounter {enc}]({flight_figures[enc]})", ""]
    return lines


def oracle_section(cols: Columns, labels: Sequence[dict]) -> list[str]:
    """Mitigated drone-scale events against the oracle's labels (``companion.campaign.labels``):
    overall and per stratum, how many some manoeuvre could have avoided."""
    stratum = {int(i): str(s) for i, s in zip(cols["id"], cols["stratum"])}
    lines = [
        "## What the oracle says",
        "",
        "Every mitigated collision and NMAC of a drone-scale encounter, labelled by the brute-force oracle "
        "(`companion/campaign/oracle.py`, independent of the policy): *avoidable* when some feasible "
        "manoeuvre of a point mass within the helicopter's limits, started at the first report from the "
        "unmitigated state, stays out of the event's volume against the true tracks.",
        "",
    ]
    rows = []
    for event in ("collision", "nmac"):
        mine = [lab for lab in labels if lab["event"] == event]
        n_event = int(np.sum(cols[f"m_{event}"] & (cols["traffic"] == "drone")))
        avoid = sum(lab["avoidable"] for lab in mine)
        rows.append([event, n_event, len(mine), avoid, len(mine) - avoid])
    lines += _table(["event (with the system)", "events", "labelled", "avoidable", "unavoidable"], rows)
    per = {}
    for lab in labels:
        if lab["event"] == "collision":
            per.setdefault(stratum.get(int(lab["id"]), "?"), []).append(lab["avoidable"])
    if per:
        lines += ["Collisions with the system per stratum, oracle-avoidable of all:", ""]
        lines += _table(
            ["stratum", "avoidable", "collisions"],
            [[k, sum(v), len(v)] for k, v in sorted(per.items(), key=lambda kv: -sum(kv[1]))],
        )
    return lines


def render_markdown(
    spec_name: str,
    summary: CampaignSummary,
    cols: Columns,
    worst_idx: np.ndarray,
    figures: dict[str, str],
    flight_figures: dict[int, str],
    labels: Sequence[dict] = (),
) -> str:
    """The report's Markdown text (figures named by file, relative to the report)."""
    g = summary.overall
    flags = sorted(
        {
            ev.risk_ratio.flag
            for grp in (g, *summary.strata, *summary.traffic)
            for ev in (grp.nmac, grp.lowc)
            if ev.risk_ratio.flag
        }
    )
    lines = [
        f"# Validation campaign: {spec_name}",
        "",
        f"{g.n} encounters (effective n {fmt_number(g.n_eff)}) in {len(summary.strata)} strata, each flown "
        "without the system (u: the companion ignores threats) and with it (m: it avoids). Rates are "
        "importance-weighted; RR = P(event | with) / P(event | without) over the paired runs, 95 % CI by "
        "the delta method on log RR with the pairs' covariance (and an add-one-pair guard), "
        "a one-sided bound when there is no event with the system.",
        "",
    ]
    lines += [f"- *{f.replace('_', ' ')}*: {_FLAG_NOTES[f]}" for f in flags] + ([""] if flags else [])
    lines += _overall_section(g)
    for title, groups in (("Per stratum", summary.strata), ("Per traffic kind", summary.traffic)):
        lines += [
            f"## {title}",
            "",
            "### Risk",
            "",
            *_risk_table(groups),
            "### Side effects and costs",
            "",
            *_cost_table(groups),
        ]
    lines += _convergence_section(summary, figures["convergence"])
    lines += [
        "## Miss distances",
        "",
        f"![miss distances]({figures['miss']})",
        "",
        "## Risk ratios per stratum",
        "",
        f"![risk ratios per stratum]({figures['ratios']})",
        "",
    ]
    lines += _latency_section(g)
    if labels:
        lines += oracle_section(cols, labels)
    lines += _worst_section(cols, worst_idx, flight_figures)
    return "\n".join(lines)


def _flight_figures(
    cols: Columns, idx: np.ndarray, flight_of: Callable[[int], object] | None, out: Path
) -> dict[int, str]:
    if flight_of is None:
        return {}
    names = {}
    for i in idx:
        enc = int(cols["id"][i])
        title = (
            f"encounter {enc} ({cols['stratum'][i]}, {cols['traffic'][i]}): min sep "
            f"{fmt_number(cols['u_min_sep_m'][i])} m without, {fmt_number(cols['m_min_sep_m'][i])} m with"
        )
        names[enc] = plot_flight(flight_of(enc), title, out / f"encounter_{enc}.png").name
    return names


def write_report(
    table,
    out_dir,
    *,
    spec_name: str,
    worst: int = 8,
    flight_of: Callable[[int], object] | None = None,
    labels: Sequence[dict] = (),
) -> Path:
    """Write ``report.md`` and its PNG figures into ``out_dir``.

    Parameters
    ----------
    table : pyarrow.Table or list of dict
        The campaign's rows, one per encounter pair.
    out_dir : path-like
        Created when missing.
    spec_name : str
        The campaign spec's name, in the title.
    worst : int
        How many of the worst encounters to list.
    flight_of : callable, optional
        ``flight_of(id)`` gives an object with ``t_s`` (K,), ``own_u_ned_m`` (K, 3),
        ``own_m_ned_m`` (K, 3) and ``threats`` (list of (K, 3), NED metres); each worst
        encounter is then drawn (top view and altitude). Without it they are only listed.
    labels : sequence of dict, optional
        The oracle's labels (``companion.campaign.labels.LABEL_SCHEMA`` rows): a section.

    Returns
    -------
    pathlib.Path
        The report's path, ``out_dir / "report.md"``.
    """
    cols = campaign_columns(table)
    summary = summarise(cols)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    curves = {name: event_convergence(cols, sfx) for name, sfx in EVENTS}
    figures = {
        "convergence": plot_convergence(curves, out / "convergence.png").name,
        "miss": plot_miss_distances(cols, out / "miss_distances.png").name,
        "ratios": plot_ratio_bars(summary.strata, out / "risk_ratios.png").name,
    }
    idx = worst_encounters(cols, worst)
    flights = _flight_figures(cols, idx, flight_of, out)
    path = out / "report.md"
    path.write_text(render_markdown(spec_name, summary, cols, idx, figures, flights, labels), encoding="utf-8")
    log.info("campaign report %s: %d encounters, %d figures", path, cols.n, len(figures) + len(flights))
    return path
