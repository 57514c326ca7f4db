"""The campaign report's figures (matplotlib, Agg backend): each function draws one PNG.

Frames: flights are local NED metres; the top view plots east (x) against north (y), and the
altitude is ``-down``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
import numpy as np  # noqa: E402
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter  # noqa: E402

from companion.campaign.stats import ConvergenceCurve  # noqa: E402
from companion.campaign.summary import Columns, GroupSummary  # noqa: E402

__all__ = ["plot_miss_distances", "plot_convergence", "plot_ratio_bars", "plot_flight"]

_U_STYLE = {"color": "tab:red", "label": "without the system"}
_U_TRACK = {**_U_STYLE, "linewidth": 2.6, "alpha": 0.6}  # wider: visible under the other track
_M_STYLE = {"color": "tab:blue", "label": "with the system"}


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _per_threat(lists: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flatten (N,) lists of per-threat values: values (M,), each with its encounter's weight (M,)."""
    vals = [np.asarray(v, dtype=float) for v in lists]
    w = np.concatenate([np.full(v.size, wi) for v, wi in zip(vals, weights)]) if vals else np.zeros(0)
    return _finite(np.concatenate(vals) if vals else np.zeros(0), w)


def _finite(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keep = np.isfinite(x)
    return x[keep], w[keep]


def _weighted_hist(ax, u: tuple[np.ndarray, np.ndarray], m: tuple[np.ndarray, np.ndarray], xlabel: str) -> None:
    both = np.concatenate([u[0], m[0]])
    if both.size == 0:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel(xlabel)
        return
    lo, hi = np.percentile(both, [0.5, 99.5])
    bins = np.linspace(lo, hi if hi > lo else lo + 1.0, 40)
    for (x, w), style in ((u, _U_STYLE), (m, _M_STYLE)):
        if x.size:
            ax.hist(
                np.clip(x, bins[0], bins[-1]),
                bins=bins,
                weights=w / w.sum() if w.sum() > 0 else None,
                histtype="step",
                linewidth=1.6,
                **style,
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("weighted fraction")
    ax.legend(fontsize=8)


def plot_miss_distances(cols: Columns, path: Path) -> Path:
    """Weighted histograms of min separation, and of per-threat HMD and VMD when present."""
    w = cols["weight"].astype(float)
    panels = [
        (
            "min separation beyond the threat radius (m)",
            (cols["u_min_sep_m"].astype(float), w),
            (cols["m_min_sep_m"].astype(float), w),
        )
    ]
    for kind in ("hmd", "vmd"):
        if f"u_{kind}_m" in cols and f"m_{kind}_m" in cols:
            panels.append(
                (
                    f"{kind.upper()} at closest approach, per threat (m)",
                    _per_threat(cols[f"u_{kind}_m"], w),
                    _per_threat(cols[f"m_{kind}_m"], w),
                )
            )
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.6), squeeze=False)
    for ax, (label, u, m) in zip(axes[0], panels):
        _weighted_hist(ax, _finite(*u), _finite(*m), label)
    fig.suptitle("Miss distances with and without the system")
    return _save(fig, path)


def _convergence_top(c: ConvergenceCurve) -> float:
    """The y limit: the whole band over the last half of N, at most 3x the final bound early on."""
    late = c.n >= c.n[-1] / 2 if c.n.size else np.zeros(0, bool)
    finite = lambda x: x[np.isfinite(x)]
    late_hi = finite(np.r_[c.hi[late], c.ratio[late]])
    all_hi = finite(np.r_[c.hi, c.ratio])
    if all_hi.size == 0:
        return 1.0
    top = float(all_hi.max())
    if late_hi.size:
        top = min(top, 3.0 * float(late_hi.max()))
    return 1.05 * top if top > 0 else 1.0


def plot_convergence(curves: Mapping[str, ConvergenceCurve], path: Path) -> Path:
    """Running risk ratio and its CI band against N (log x), one panel per event."""
    fig, axes = plt.subplots(1, len(curves), figsize=(5.2 * len(curves), 3.6), squeeze=False)
    for ax, (event, c) in zip(axes[0], curves.items()):
        ok = np.isfinite(c.ratio)
        if ok.any():
            hi = np.where(np.isfinite(c.hi), c.hi, np.nan)
            ax.fill_between(c.n[ok], c.lo[ok], hi[ok], alpha=0.25, color="tab:blue", label="95 % CI")
            ax.plot(c.n[ok], c.ratio[ok], "o-", color="tab:blue", markersize=3, label="risk ratio")
            ax.axhline(c.ratio[-1], color="grey", linestyle=":", linewidth=1)
        else:
            ax.text(0.5, 0.5, "ratio undefined", ha="center", va="center", transform=ax.transAxes)
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("encounters N")
        ax.set_ylabel(f"RR {event}")
        ax.set_ylim(0, _convergence_top(c))
        ax.legend(fontsize=8)
        ax.set_title(f"{event} risk ratio vs N")
    return _save(fig, path)


def plot_ratio_bars(groups: Sequence[GroupSummary], path: Path) -> Path:
    """Per-group bars of the NMAC and LoWC risk ratios with CI whiskers (undefined ones marked)."""
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(groups) + 2.5), 3.8))
    x = np.arange(len(groups))
    tops = [1.2]
    for j, (event, color) in enumerate((("NMAC", "tab:orange"), ("LoWC", "tab:purple"))):
        ests = [g.event(event).risk_ratio for g in groups]
        xs = x + (j - 0.5) * 0.38
        val = np.array([e.value if math.isfinite(e.value) else 0.0 for e in ests])
        lo = np.array([e.lo if math.isfinite(e.lo) else 0.0 for e in ests])
        hi = np.array([e.hi if math.isfinite(e.hi) else np.nan for e in ests])
        ax.bar(xs, val, width=0.38, color=color, alpha=0.8, label=f"RR {event}")
        ok = np.isfinite(hi)
        ax.errorbar(xs[ok], val[ok], yerr=[val[ok] - lo[ok], hi[ok] - val[ok]], fmt="none", ecolor="black", capsize=3)
        tops.extend(hi[ok].tolist())
        for xi, e in zip(xs, ests):
            if not math.isfinite(e.value):
                ax.text(xi, 0.08, "n/a" if math.isnan(e.value) else "inf", ha="center", va="bottom", fontsize=8)
    ax.axhline(1.0, color="grey", linestyle="--", linewidth=1)
    ax.set_ylim(0, min(max(tops) * 1.05, 3.0))
    ax.set_xticks(x, [g.name for g in groups], rotation=30, ha="right")
    ax.set_ylabel("risk ratio (with / without)")
    ax.set_title("Risk ratios per group, 95 % CI")
    ax.legend(fontsize=8)
    return _save(fig, path)


def _closest_index(own_ned_m: np.ndarray, threat_ned_m: np.ndarray) -> int:
    """Sample index of the closest approach of two (K, 3) tracks (over their common length)."""
    k = min(own_ned_m.shape[0], threat_ned_m.shape[0])
    return int(np.argmin(np.linalg.norm(own_ned_m[:k] - threat_ned_m[:k], axis=1)))


def plot_flight(flight, title: str, path: Path) -> Path:
    """Top view (east-north) and altitude vs time of one encounter flown without and with the
    system; the top view joins each threat's closest approach with the system (x).

    ``flight`` has ``t_s`` (K,), ``own_u_ned_m`` (K, 3), ``own_m_ned_m`` (K, 3) and ``threats``,
    a list of (K, 3) arrays (local NED metres).
    """
    t = np.asarray(flight.t_s, dtype=float)
    own_u, own_m = np.asarray(flight.own_u_ned_m, float), np.asarray(flight.own_m_ned_m, float)
    threats = [np.asarray(th, float) for th in flight.threats]
    fig, (top, alt) = plt.subplots(1, 2, figsize=(10, 4))
    for track, style in ((own_u, _U_TRACK), (own_m, _M_STYLE)):
        top.plot(track[:, 1], track[:, 0], **style)
        alt.plot(t, -track[:, 2], **style)
    for k, th in enumerate(threats):
        label = "threat" if k == 0 else None
        top.plot(th[:, 1], th[:, 0], color="black", linestyle="--", linewidth=1, label=label)
        top.plot(th[0, 1], th[0, 0], "k^", markersize=5)
        alt.plot(t[: th.shape[0]], -th[:, 2], color="black", linestyle="--", linewidth=1, label=label)
    for th in threats:  # closest approach with the system
        k = _closest_index(own_m, th)
        top.plot([own_m[k, 1], th[k, 1]], [own_m[k, 0], th[k, 0]], "x-", color="tab:blue", linewidth=0.8)
    top.plot(own_u[0, 1], own_u[0, 0], "go", markersize=5, label="start")
    top.set_xlabel("east (m)")
    top.set_ylabel("north (m)")
    top.set_aspect("equal", adjustable="datalim")
    top.legend(fontsize=7)
    alt.set_xlabel("t (s)")
    alt.set_ylabel("altitude (m)")
    fig.suptitle(title)
    return _save(fig, path)
