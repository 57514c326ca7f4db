"""The campaign's summary: rates, risk ratios and costs, overall, per stratum and per traffic kind.

:func:`campaign_columns` reads the rows (one per encounter pair, the schema in
``companion.campaign``'s flying code) into columns ordered by encounter id; :func:`summarise`
turns them into a :class:`CampaignSummary`, a tree of frozen dataclasses with ``to_dict()``.
The estimators are :mod:`companion.campaign.stats`'s. Rates, completion and extra path are
importance-weighted; decision latencies are not (they describe the computation, one sample per
decision, whatever the encounter's weight).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from companion.campaign.stats import (
    ConvergenceCurve,
    Estimate,
    StatsError,
    Verdict,
    convergence,
    induced_rate,
    is_converged,
    percentiles,
    risk_ratio,
    unnecessary_rate,
    weighted_quantile,
    weighted_rate,
)

__all__ = [
    "EVENTS",
    "REQUIRED_COLUMNS",
    "LIST_COLUMNS",
    "Columns",
    "campaign_columns",
    "LatencySummary",
    "EventSummary",
    "GroupSummary",
    "CampaignSummary",
    "summarise",
    "summarise_group",
    "event_convergence",
]

#: The events whose risk ratio the campaign reports: (name, column suffix).
EVENTS: tuple[tuple[str, str], ...] = (("NMAC", "nmac"), ("LoWC", "lowc"))

#: Columns :func:`summarise` reads.
REQUIRED_COLUMNS: tuple[str, ...] = (
    "id",
    "stratum",
    "traffic",
    "weight",
    "u_collision",
    "u_nmac",
    "u_lowc",
    "u_min_sep_m",
    "u_completed",
    "u_path_m",
    "m_collision",
    "m_nmac",
    "m_lowc",
    "m_min_sep_m",
    "m_completed",
    "m_path_m",
    "m_alerted",
    "m_manoeuvred",
    "m_decisions",
    "m_latency_ms",
    "m_extra_path_m",
)

#: Columns holding one list per row.
LIST_COLUMNS: tuple[str, ...] = (
    "u_hmd_m",
    "u_vmd_m",
    "m_hmd_m",
    "m_vmd_m",
    "m_decisions",
    "m_latency_ms",
    "m_decide_wall_ms",
)

_BOOL_COLUMNS = (
    "u_collision",
    "u_nmac",
    "u_lowc",
    "u_completed",
    "m_collision",
    "m_nmac",
    "m_lowc",
    "m_completed",
    "m_alerted",
    "m_manoeuvred",
)


@dataclass(frozen=True)
class Columns:
    """Campaign rows as columns, ordered by encounter id.

    ``data[name]`` is an (N,) array; a list column is an (N,) object array of lists.
    """

    data: Mapping[str, np.ndarray]

    @property
    def n(self) -> int:
        return int(self.data["id"].size)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[name]
        except KeyError:
            raise StatsError(f"campaign rows: no column {name!r}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.data

    def subset(self, mask: np.ndarray) -> Columns:
        """The rows where the (N,) bool ``mask`` is true, in the same order."""
        return Columns({k: v[mask] for k, v in self.data.items()})


def _to_table(rows) -> pa.Table:
    if isinstance(rows, pa.Table):
        return rows
    if isinstance(rows, list):
        if not rows:
            raise StatsError("campaign rows: the list is empty")
        return pa.Table.from_pylist(rows)
    raise StatsError(f"campaign rows: expected a pyarrow.Table or a list of dicts, got {type(rows).__name__}")


def _column_array(table: pa.Table, name: str) -> np.ndarray:
    col = table.column(name)
    if name in LIST_COLUMNS:
        arr = np.empty(len(col), dtype=object)
        arr[:] = [list(v) if v is not None else [] for v in col.to_pylist()]
        return arr
    if col.null_count and name in _BOOL_COLUMNS + ("id", "weight", "stratum", "traffic"):
        row = next(i for i, v in enumerate(col.to_pylist()) if v is None)
        raise StatsError(f"campaign rows: column {name!r} is null in row {row}")
    if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
        return np.asarray(col.to_pylist(), dtype=object)
    if pa.types.is_floating(col.type):
        return np.asarray(col.to_numpy(zero_copy_only=False), dtype=float)
    return np.asarray(col.to_numpy(zero_copy_only=False))


def campaign_columns(rows, *, required: Iterable[str] = REQUIRED_COLUMNS) -> Columns:
    """Read and check campaign rows.

    Parameters
    ----------
    rows : pyarrow.Table or list of dict
        One row per encounter pair.
    required : iterable of str
        Columns that must be present.

    Returns
    -------
    Columns
        Ordered by ``id``.

    Raises
    ------
    StatsError
        A required column is missing or null, an id repeats, a weight is negative or not
        finite, or a row's decisions and latencies differ in length (the message names them).
    """
    table = _to_table(rows)
    missing = [c for c in required if c not in table.column_names]
    if missing:
        raise StatsError(f"campaign rows: missing column(s) {', '.join(missing)}")
    data = {name: _column_array(table, name) for name in table.column_names}
    order = np.argsort(data["id"], kind="stable")
    data = {k: v[order] for k, v in data.items()}
    cols = Columns(data)
    _check_columns(cols)
    return cols


def _check_columns(cols: Columns) -> None:
    ids = cols["id"]
    dup = ids[1:][ids[1:] == ids[:-1]]
    if dup.size:
        raise StatsError(f"campaign rows: id {int(dup[0])} appears more than once")
    w = cols["weight"].astype(float)
    bad = np.flatnonzero(~np.isfinite(w) | (w < 0))
    if bad.size:
        raise StatsError(f"campaign rows: id {int(ids[bad[0]])}: weight {w[bad[0]]!r} must be finite and >= 0")
    if "m_decisions" in cols and "m_latency_ms" in cols:
        for i, (d, lat) in enumerate(zip(cols["m_decisions"], cols["m_latency_ms"])):
            if len(d) != len(lat):
                raise StatsError(f"campaign rows: id {int(ids[i])}: {len(d)} m_decisions but {len(lat)} m_latency_ms")


@dataclass(frozen=True)
class LatencySummary:
    """Decision latency (virtual clock, trigger to first setpoint: modelled) of ``n`` decisions,
    and the decisions' own compute as measured on the worker (``m_decide_wall_ms``; NaN in rows
    without it)."""

    kind: str
    n: int
    p50_ms: float
    p99_ms: float
    compute_p50_ms: float = math.nan
    compute_p99_ms: float = math.nan


@dataclass(frozen=True)
class EventSummary:
    """One event (NMAC or LoWC): its rates without and with the system, their ratio, the
    induced rate (with but not without) and whether the ratio has converged."""

    event: str
    u_rate: Estimate
    m_rate: Estimate
    risk_ratio: Estimate
    induced: Estimate
    convergence: Verdict


@dataclass(frozen=True)
class GroupSummary:
    """The summary of one group of encounters (all, a stratum or a traffic kind).

    Attributes
    ----------
    name : str
    n : int
    n_eff : float
        Kish's effective sample size of the weights.
    nmac, lowc : EventSummary
    unnecessary : Estimate
        Manoeuvred though the unmitigated encounter stayed well clear.
    alerted : Estimate
        Rate of encounters with an alert.
    u_collisions, m_collisions : int
        Encounters with a collision without / with the system (counts, not weighted).
    u_completion, m_completion : Estimate
        Rate of encounters whose mission completed.
    extra_path_mean_m, extra_path_p50_m : float
        Weighted mean and median of ``m_extra_path_m``.
    latency : LatencySummary
        Over all decisions (``kind="all"``).
    latency_by_kind : tuple of LatencySummary
        One per decision kind, sorted by kind.
    """

    name: str
    n: int
    n_eff: float
    nmac: EventSummary
    lowc: EventSummary
    unnecessary: Estimate
    alerted: Estimate
    u_collisions: int
    m_collisions: int
    u_completion: Estimate
    m_completion: Estimate
    extra_path_mean_m: float
    extra_path_p50_m: float
    latency: LatencySummary
    latency_by_kind: tuple[LatencySummary, ...]

    @property
    def converged(self) -> bool:
        """Whether both ratios (NMAC and LoWC) have converged."""
        return self.nmac.convergence.converged and self.lowc.convergence.converged

    def event(self, name: str) -> EventSummary:
        """``nmac`` or ``lowc`` by name (``"NMAC"``, ``"nmac"``, ``"LoWC"``, ``"lowc"``)."""
        key = name.lower()
        if key not in ("nmac", "lowc"):
            raise StatsError(f"event {name!r}: expected NMAC or LoWC")
        return self.nmac if key == "nmac" else self.lowc


@dataclass(frozen=True)
class CampaignSummary:
    """The whole campaign: ``overall`` and one :class:`GroupSummary` per stratum and per
    traffic kind (each tuple sorted by name)."""

    overall: GroupSummary
    strata: tuple[GroupSummary, ...]
    traffic: tuple[GroupSummary, ...]

    def stratum(self, name: str) -> GroupSummary:
        for g in self.strata:
            if g.name == name:
                return g
        raise StatsError(f"no stratum {name!r}; strata: {', '.join(g.name for g in self.strata)}")

    def to_dict(self) -> dict[str, object]:
        """The tree as JSON-serialisable dicts and lists (non-finite numbers as strings)."""
        return _plain(self)


def _plain(v: object) -> object:
    if hasattr(v, "__dataclass_fields__"):
        return {k: _plain(getattr(v, k)) for k in v.__dataclass_fields__}
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else ("nan" if math.isnan(f) else ("inf" if f > 0 else "-inf"))
    if isinstance(v, np.integer):
        return int(v)
    return v


def event_convergence(rows, metric: str, checkpoints=None, *, level: float = 0.95) -> ConvergenceCurve:
    """The running risk ratio of one event over the rows in id order.

    Parameters
    ----------
    rows : pyarrow.Table, list of dict or Columns
    metric : str
        The event's column suffix: ``"nmac"``, ``"lowc"`` or ``"collision"`` (``m_`` over ``u_``).
    checkpoints : (K,) array_like of int, optional
        Prefix lengths (default :func:`companion.campaign.stats.default_checkpoints`).

    Returns
    -------
    ConvergenceCurve
        ``n, ratio, lo, hi``, each (K,).
    """
    if metric not in ("nmac", "lowc", "collision"):
        raise StatsError(f"metric {metric!r}: expected 'nmac', 'lowc' or 'collision'")
    cols = rows if isinstance(rows, Columns) else campaign_columns(rows)
    return convergence(
        cols[f"m_{metric}"].astype(bool),
        cols[f"u_{metric}"].astype(bool),
        cols["weight"].astype(float),
        checkpoints,
        level=level,
    )


def _event_summary(cols: Columns, name: str, suffix: str, w: np.ndarray, level: float) -> EventSummary:
    a, b = cols[f"m_{suffix}"].astype(bool), cols[f"u_{suffix}"].astype(bool)
    verdict = is_converged(event_convergence(cols, suffix, level=level)) if a.size else Verdict(False, "no encounters")
    return EventSummary(
        name,
        weighted_rate(b, w, level=level),
        weighted_rate(a, w, level=level),
        risk_ratio(a, b, w, level=level),
        induced_rate(a, b, w, level=level),
        verdict,
    )


def _latencies(cols: Columns) -> tuple[LatencySummary, tuple[LatencySummary, ...]]:
    kinds = np.array([k for row in cols["m_decisions"] for k in row], dtype=object)
    lat = np.array([x for row in cols["m_latency_ms"] for x in row], dtype=float)
    compute = np.full(lat.shape, math.nan)
    if "m_decide_wall_ms" in cols:
        measured = [x for row in cols["m_decide_wall_ms"] for x in (row or ())]
        if len(measured) == lat.size:
            compute = np.array(measured, dtype=float)

    def summary(kind: str, sel) -> LatencySummary:
        return LatencySummary(
            kind,
            int(np.isfinite(lat[sel]).sum()),
            *percentiles(lat[sel], (50, 99)),
            *percentiles(compute[sel], (50, 99)),
        )

    return summary("all", slice(None)), tuple(summary(k, kinds == k) for k in sorted(set(kinds)))


def summarise_group(cols: Columns, name: str, *, level: float = 0.95) -> GroupSummary:
    """The :class:`GroupSummary` of the rows in ``cols`` (ordered by id)."""
    w = cols["weight"].astype(float)
    total_w = float(w.sum())
    latency, by_kind = _latencies(cols)
    extra = cols["m_extra_path_m"].astype(float)
    fin = np.isfinite(extra)
    mean_extra = float(np.sum(w[fin] * extra[fin]) / np.sum(w[fin])) if fin.any() and np.sum(w[fin]) > 0 else math.nan
    return GroupSummary(
        name=name,
        n=cols.n,
        n_eff=total_w**2 / float(np.sum(w * w)) if total_w > 0 else 0.0,
        nmac=_event_summary(cols, "NMAC", "nmac", w, level),
        lowc=_event_summary(cols, "LoWC", "lowc", w, level),
        unnecessary=unnecessary_rate(cols["m_manoeuvred"].astype(bool), cols["u_lowc"].astype(bool), w, level=level),
        alerted=weighted_rate(cols["m_alerted"].astype(bool), w, level=level),
        u_collisions=int(cols["u_collision"].astype(bool).sum()),
        m_collisions=int(cols["m_collision"].astype(bool).sum()),
        u_completion=weighted_rate(cols["u_completed"].astype(bool), w, level=level),
        m_completion=weighted_rate(cols["m_completed"].astype(bool), w, level=level),
        extra_path_mean_m=mean_extra,
        extra_path_p50_m=weighted_quantile(extra, w, 0.5),
        latency=latency,
        latency_by_kind=by_kind,
    )


def _groups(cols: Columns, column: str, level: float) -> tuple[GroupSummary, ...]:
    values = cols[column]
    return tuple(summarise_group(cols.subset(values == v), str(v), level=level) for v in sorted(set(values.tolist())))


def summarise(table, *, level: float = 0.95) -> CampaignSummary:
    """Summarise a campaign.

    Parameters
    ----------
    table : pyarrow.Table, list of dict or Columns
        One row per encounter pair (any order; read by :func:`campaign_columns`).
    level : float
        Confidence level of every interval.

    Returns
    -------
    CampaignSummary
    """
    cols = table if isinstance(table, Columns) else campaign_columns(table)
    return CampaignSummary(
        summarise_group(cols, "all", level=level), _groups(cols, "stratum", level), _groups(cols, "traffic", level)
    )
