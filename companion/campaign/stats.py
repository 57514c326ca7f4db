"""Estimators of the validation campaign: weighted rates, paired risk ratios, convergence.

The campaign flies every encounter twice, without the system (``u_``, the companion ignores the
threats) and with it (``m_``), as ASTM F3442, RTCA DO-365 and CAA CAP 3015 do. An encounter
``i`` gives a pair of events ``(a_i, b_i)`` (with, without) and one importance weight ``w_i``
(``p/q`` of the encounter model over the proposal it was drawn from; 1 for unweighted strata).

Methods
-------
Rate (:func:`weighted_rate`)
    The self-normalised (Hajek) mean ``p = sum(w e) / sum(w)``, with Clopper-Pearson on the
    effective size ``n* = p (1 - p) / Var(p)``, ``Var(p) = sum(w^2 (e - p)^2) / sum(w)^2``,
    capped at ``n`` (Korn & Graubard 1998; exact Clopper-Pearson with equal weights). With no
    event (or all) ``n*`` is Kish's ``sum(w)^2 / sum(w^2)`` and the bound one-sided at ``level``
    (the weighted rule of three, ``1 - (1-level)^(1/n*)``).
Risk ratio (:func:`risk_ratio`)
    ``RR = sum(w a) / sum(w b)`` (the weights' scale cancels), with the delta method on
    ``log RR``: ``Var(log RR) = n/(n-1) sum(w^2 (a - RR b)^2) / sum(w a)^2``, which is
    ``Var(log A) + Var(log B) - 2 Cov(log A, log B)`` with the pairs' covariance. With few
    events, the heavy encounters an importance sample under-draws are often missing, and then
    the estimate and its variance are both too small; so the interval is the union of that one
    and the same with a pseudo pair of the mean weight added, one encounter with the event only
    with the system and one only without (the add-one idea of Bonett & Price 2006 for paired
    ratios, and of Fay & Feuer 1997's extra event for weighted counts). Measured coverage of the
    nominal 95 % (4000 campaigns each, RR 0.1): 0.94-0.97 over 100-1000 pairs, also with
    importance proposals where the delta method alone fell to 0.85. The percentile bootstrap
    covers less with few events (0.92 at 18 expected events). With no event with the system, RR = 0 in ``[0, p_hi / p_b]``: the one-sided
    upper bound of the rate with the system over the rate without (flag ``zero_with``); with
    none without it, ``inf`` (``zero_without``); with none at all, NaN (``no_events``).
    ``method="bootstrap"`` resamples the pairs (seeded), for checks.
Convergence (:func:`convergence`, :func:`is_converged`)
    The running ratio over the first ``N_k`` encounters; :func:`is_converged` has the rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy import stats as sps

from companion.errors import CompanionError

__all__ = [
    "MEASURED_COLUMNS",
    "CONVERGENCE_TOL",
    "CONVERGENCE_FLOOR",
    "CONVERGENCE_HALF_WIDTH",
    "CONVERGENCE_TAIL",
    "CONVERGENCE_MIN_CHECKPOINTS",
    "StatsError",
    "Estimate",
    "Verdict",
    "ConvergenceCurve",
    "weighted_rate",
    "risk_ratio",
    "induced_rate",
    "unnecessary_rate",
    "percentiles",
    "weighted_quantile",
    "default_checkpoints",
    "convergence",
    "is_converged",
]

#: Row columns that are measured on the machine, not reproduced by a seed: leave them out when
#: two campaigns' rows are compared.
MEASURED_COLUMNS: tuple[str, ...] = ("wall_ms", "cpu_ms", "m_decide_wall_ms")


#: :func:`is_converged`'s defaults: relative tolerance of the running ratio, absolute floor of
#: its scale, bound of the CI half-width relative to that scale, the tail's fraction of the
#: encounters and the fewest checkpoints in it.
CONVERGENCE_TOL = 0.05
CONVERGENCE_FLOOR = 0.005
CONVERGENCE_HALF_WIDTH = 0.25
CONVERGENCE_TAIL = 0.2
CONVERGENCE_MIN_CHECKPOINTS = 5


class StatsError(CompanionError, ValueError):
    """Campaign rows or estimator arguments are invalid; the message names the column or argument."""


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its confidence interval.

    Attributes
    ----------
    value, lo, hi : float
        Estimate and interval bounds (``inf`` or NaN when undefined, see ``flag``).
    n : int
        Encounters used.
    n_eff : float
        Kish's effective sample size of their weights, ``sum(w)^2 / sum(w^2)``.
    level : float
        Confidence level of ``[lo, hi]``.
    method : str
        ``"clopper-pearson"``, ``"rule-of-three"``, ``"delta-log"``, ``"zero-upper"``,
        ``"bootstrap"`` or ``"none"``.
    flag : str
        ``""`` when defined; ``"empty"`` (no encounter), ``"zero_with"`` (no event with the
        system: the ratio is 0, the bound one-sided), ``"zero_without"`` (no event without it:
        the ratio is infinite), ``"no_events"`` (neither: the ratio is NaN).
    """

    value: float
    lo: float
    hi: float
    n: int
    n_eff: float
    level: float = 0.95
    method: str = "none"
    flag: str = ""

    @property
    def defined(self) -> bool:
        """Whether ``value`` is a finite number."""
        return math.isfinite(self.value)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready values (non-finite numbers as strings ``"inf"``, ``"nan"``)."""
        return {k: _json_number(v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class Verdict:
    """Whether a running ratio has converged, and if not, why (``reason``)."""

    converged: bool
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {"converged": self.converged, "reason": self.reason}


class ConvergenceCurve(NamedTuple):
    """The running ratio: all arrays have shape (K,), one entry per checkpoint ``n``."""

    n: np.ndarray
    ratio: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _json_number(v: object) -> object:
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return v


def _events_and_weights(events, weights, name: str = "events") -> tuple[np.ndarray, np.ndarray]:
    """Check and convert: events (N,) bool, weights (N,) finite and >= 0."""
    e = np.asarray(events)
    w = np.ones(e.shape, float) if weights is None else np.asarray(weights, dtype=float)
    if e.ndim != 1 or w.shape != e.shape:
        raise StatsError(f"{name} {e.shape} and weights {w.shape} must be (N,) arrays of one length")
    if e.dtype != bool and not np.isin(e, (0, 1)).all():
        raise StatsError(f"{name} must be booleans (or 0/1)")
    if not np.isfinite(w).all() or (w < 0).any():
        bad = int(np.flatnonzero(~np.isfinite(w) | (w < 0))[0])
        raise StatsError(f"weights[{bad}] = {w[bad]!r}: weights must be finite and >= 0")
    return e.astype(bool), w


def _kish_n_eff(w: np.ndarray) -> float:
    s2 = float(np.sum(w * w))
    return float(np.sum(w)) ** 2 / s2 if s2 > 0 else 0.0


def _upper_rule_of_three(n_eff: float, level: float) -> float:
    """One-sided upper bound of a rate with no event in ``n_eff`` trials (Clopper-Pearson)."""
    return 1.0 - (1.0 - level) ** (1.0 / n_eff) if n_eff > 0 else 1.0


def _rate_interval(p: float, n: int, n_eff_kish: float, var_p: float, level: float) -> tuple[float, float, str]:
    """Korn-Graubard: Clopper-Pearson on ``n* = p(1-p)/Var(p)``; one-sided at 0 and 1 events."""
    if p <= 0.0:
        return 0.0, _upper_rule_of_three(n_eff_kish, level), "rule-of-three"
    if p >= 1.0:
        return 1.0 - _upper_rule_of_three(n_eff_kish, level), 1.0, "rule-of-three"
    n_star = min(float(n), p * (1.0 - p) / var_p) if var_p > 0 else n_eff_kish
    x = p * n_star
    alpha = 1.0 - level
    lo = float(sps.beta.ppf(alpha / 2, x, n_star - x + 1))
    hi = float(sps.beta.ppf(1 - alpha / 2, x + 1, n_star - x))
    return lo, hi, "clopper-pearson"


def weighted_rate(events, weights=None, *, level: float = 0.95) -> Estimate:
    """Importance-weighted event rate with a small-count interval (module docstring).

    Parameters
    ----------
    events : (N,) array_like of bool
    weights : (N,) array_like of float, optional
        Importance weights, finite and >= 0 (default 1).
    level : float
        Confidence level.

    Returns
    -------
    Estimate
        ``flag="empty"`` and NaN values when N = 0 or the weights sum to 0.
    """
    e, w = _events_and_weights(events, weights)
    n, sw = e.size, float(np.sum(w))
    if n == 0 or sw <= 0:
        return Estimate(math.nan, math.nan, math.nan, n, 0.0, level, "none", "empty")
    p = float(np.sum(w * e)) / sw
    var_p = float(np.sum(w * w * (e - p) ** 2)) / sw**2
    n_eff = _kish_n_eff(w)
    lo, hi, method = _rate_interval(p, n, n_eff, var_p, level)
    return Estimate(p, lo, hi, n, n_eff, level, method)


def induced_rate(with_events, without_events, weights=None, *, level: float = 0.95) -> Estimate:
    """Rate of events with the system that did not happen without it (the system made it worse).

    ``with_events, without_events, weights`` are (N,); the rate is over all N encounters.
    """
    a, w = _events_and_weights(with_events, weights, "with_events")
    b, _ = _events_and_weights(without_events, weights, "without_events")
    return weighted_rate(a & ~b, w, level=level)


def unnecessary_rate(manoeuvred, without_lowc, weights=None, *, level: float = 0.95) -> Estimate:
    """Rate of manoeuvres though the unmitigated encounter stayed well clear, over all N encounters.

    ``manoeuvred`` (``m_manoeuvred``), ``without_lowc`` (``u_lowc``), ``weights`` are (N,).
    """
    m, w = _events_and_weights(manoeuvred, weights, "manoeuvred")
    u, _ = _events_and_weights(without_lowc, weights, "without_lowc")
    return weighted_rate(m & ~u, w, level=level)


def risk_ratio(
    with_events,
    without_events,
    weights=None,
    *,
    level: float = 0.95,
    method: str = "delta",
    n_boot: int = 2000,
    seed: int = 0,
) -> Estimate:
    """Paired, importance-weighted risk ratio ``P(event | with) / P(event | without)``.

    Parameters
    ----------
    with_events, without_events : (N,) array_like of bool
        The events of encounter ``i`` flown with and without the system.
    weights : (N,) array_like of float, optional
        One importance weight per encounter, shared by its two runs (default 1).
    level : float
        Confidence level.
    method : {"delta", "bootstrap"}
        Delta method on the log ratio (module docstring) or a seeded percentile bootstrap over
        the pairs (``n_boot`` resamples, ``numpy.random.default_rng(seed)``). Both use the
        same zero-event bounds.

    Returns
    -------
    Estimate
        ``flag`` names the undefined cases: ``zero_with`` (0, one-sided upper bound),
        ``zero_without`` (``inf``), ``no_events`` (NaN), ``empty``.
    """
    if method not in ("delta", "bootstrap"):
        raise StatsError(f"method {method!r}: expected 'delta' or 'bootstrap'")
    a, w = _events_and_weights(with_events, weights, "with_events")
    b, _ = _events_and_weights(without_events, w, "without_events")
    n, n_eff = a.size, _kish_n_eff(w)
    ta, tb = float(np.sum(w * a)), float(np.sum(w * b))
    if n == 0 or float(np.sum(w)) <= 0:
        return Estimate(math.nan, math.nan, math.nan, n, 0.0, level, "none", "empty")
    if ta <= 0 or tb <= 0:
        return _undefined_ratio(a, b, w, n_eff, ta, tb, level)
    rr = ta / tb
    if method == "bootstrap":
        lo, hi = _bootstrap_interval(a, b, w, level, n_boot, seed)
        return Estimate(rr, lo, hi, n, n_eff, level, "bootstrap")
    z = float(sps.norm.ppf(0.5 + level / 2))
    sums = (ta, tb, float(np.sum(w * w * a)), float(np.sum(w * w * a * b)), float(np.sum(w * w * b)), n)
    lo, hi = _delta_log_interval(*sums, z)
    lo_g, hi_g = _delta_log_interval(*_with_pseudo_pair(sums, float(np.mean(w))), z)
    return Estimate(rr, min(lo, lo_g), max(hi, hi_g), n, n_eff, level, "delta-log")


def _delta_log_interval(
    ta: float, tb: float, saa: float, sab: float, sbb: float, n: int, z: float
) -> tuple[float, float]:
    """Delta method on log(ta/tb) from the paired weighted sums (``saa = sum(w^2 a)`` etc.)."""
    rr = ta / tb
    var_log = n / max(n - 1, 1) * max(saa - 2 * rr * sab + rr * rr * sbb, 0.0) / ta**2
    half = z * math.sqrt(var_log)
    return rr * math.exp(-half), rr * math.exp(half)


def _with_pseudo_pair(sums: tuple, w_mean: float) -> tuple:
    """The sums plus two encounters of the mean weight, one with the event only with the
    system and one with it only without (the add-one guard of :func:`risk_ratio`)."""
    ta, tb, saa, sab, sbb, n = sums
    w2 = w_mean * w_mean
    return ta + w_mean, tb + w_mean, saa + w2, sab, sbb + w2, n + 2


def _undefined_ratio(a, b, w, n_eff, ta, tb, level) -> Estimate:
    """The zero-event cases of :func:`risk_ratio`."""
    n = a.size
    if ta <= 0 and tb <= 0:
        return Estimate(math.nan, math.nan, math.nan, n, n_eff, level, "none", "no_events")
    if ta <= 0:  # no event with the system: RR = 0, bounded above by p_a's upper bound / p_b
        p_b = tb / float(np.sum(w))
        hi = _upper_rule_of_three(n_eff, level) / p_b
        return Estimate(0.0, 0.0, hi, n, n_eff, level, "zero-upper", "zero_with")
    p_a = weighted_rate(a, w, level=level)  # no event without it: RR = inf, bounded below
    lo = p_a.lo / _upper_rule_of_three(n_eff, level)
    return Estimate(math.inf, lo, math.inf, n, n_eff, level, "zero-upper", "zero_without")


def _bootstrap_interval(a, b, w, level, n_boot, seed) -> tuple[float, float]:
    """Percentile interval of the ratio over ``n_boot`` resamples of the pairs."""
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, a.size, size=(n_boot, a.size))
    wa, wb = (w * a)[idx].sum(axis=1), (w * b)[idx].sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(wb > 0, wa / np.where(wb > 0, wb, 1.0), np.where(wa > 0, np.inf, np.nan))
    r = r[~np.isnan(r)]
    alpha = 1.0 - level
    lo, hi = np.quantile(r, [alpha / 2, 1 - alpha / 2], method="inverted_cdf")
    return float(lo), float(hi)


def percentiles(values, qs=(50, 99)) -> tuple[float, ...]:
    """Percentiles of the finite entries of ``values`` (any shape); NaN for each when none."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return tuple(math.nan for _ in qs)
    return tuple(float(x) for x in np.percentile(v, list(qs)))


def weighted_quantile(values, weights, q: float) -> float:
    """Weighted quantile (inverted CDF) of (N,) ``values`` with (N,) ``weights``; NaN when empty.

    ``q`` is in [0, 1]; entries that are not finite, and zero weights, are left out.
    """
    v = np.asarray(values, dtype=float)
    w = np.asarray(weights, dtype=float)
    keep = np.isfinite(v) & (w > 0)
    if not keep.any():
        return math.nan
    order = np.argsort(v[keep], kind="stable")
    v, cw = v[keep][order], np.cumsum(w[keep][order])
    return float(v[min(int(np.searchsorted(cw, q * cw[-1], side="left")), v.size - 1)])


def default_checkpoints(n: int, *, n_min: int = 20, n_log: int = 15, n_tail: int = 6) -> np.ndarray:
    """Checkpoints for :func:`convergence`: (K,) ints, log-spaced from ``n_min`` to ``n`` plus
    ``n_tail`` evenly spaced over the last 20 % (so :func:`is_converged` has its tail)."""
    if n <= 0:
        return np.zeros(0, dtype=np.int64)
    first = min(n_min, n)
    log_pts = np.geomspace(first, n, n_log) if n > first else np.array([n])
    tail = np.linspace(0.8 * n, n, n_tail)
    pts = np.unique(np.round(np.concatenate([log_pts, tail])).astype(np.int64))
    return pts[pts >= 1]


def convergence(
    with_events, without_events, weights=None, checkpoints=None, *, level: float = 0.95
) -> ConvergenceCurve:
    """The risk ratio over the first ``N_k`` encounters (rows in their campaign order, by id).

    Parameters
    ----------
    with_events, without_events, weights : (N,) array_like
        As for :func:`risk_ratio`, ordered by encounter id.
    checkpoints : (K,) array_like of int, optional
        Prefix lengths in 1..N (default :func:`default_checkpoints`).

    Returns
    -------
    ConvergenceCurve
        ``n, ratio, lo, hi``, each (K,).
    """
    a, w = _events_and_weights(with_events, weights, "with_events")
    b, _ = _events_and_weights(without_events, w, "without_events")
    ks = default_checkpoints(a.size) if checkpoints is None else np.asarray(checkpoints, dtype=np.int64)
    if ks.size and (ks.min() < 1 or ks.max() > a.size):
        raise StatsError(f"checkpoints must lie in 1..{a.size}, got {ks.min()}..{ks.max()}")
    ests = [risk_ratio(a[:k], b[:k], w[:k], level=level) for k in ks]
    return ConvergenceCurve(
        ks,
        np.array([e.value for e in ests], float),
        np.array([e.lo for e in ests], float),
        np.array([e.hi for e in ests], float),
    )


def is_converged(
    curve: ConvergenceCurve,
    *,
    tol: float = CONVERGENCE_TOL,
    floor: float = CONVERGENCE_FLOOR,
    max_rel_half_width: float = CONVERGENCE_HALF_WIDTH,
    tail_fraction: float = CONVERGENCE_TAIL,
    min_checkpoints: int = CONVERGENCE_MIN_CHECKPOINTS,
) -> Verdict:
    """Whether a running ratio has settled, with the reason when not.

    The rule, in order (``R`` the final ratio, ``s = max(R, floor)``):

    1. ``R`` and its upper bound are finite (the ratio is defined);
    2. at least ``min_checkpoints`` checkpoints lie in the tail, the last ``tail_fraction`` of
       the encounters (``n_k >= (1 - tail_fraction) N``);
    3. stable: every running ratio in the tail is within ``tol * s`` of ``R``;
    4. precise: the final interval's half-width ``(hi - lo) / 2`` is at most
       ``max_rel_half_width * s`` (the default 0.25: the ratio is known to within about
       +-25 %).

    Rule 3 is the stricter one when the ratio has events: the tail's running ratios share most
    of their encounters with the final one, and their spread is about the final ratio's
    standard error on the log scale, so a 5 % tolerance asks for a standard error near 0.05
    (several hundred events with the system). Rule 4 bounds the ratio near 0: the absolute
    ``floor`` lets it converge, with no event with the system, once its upper bound is below
    ``2 * max_rel_half_width * floor`` (0.0025 by default: about ``3 / (0.0025 p_without)``
    encounters).

    Parameters
    ----------
    curve : ConvergenceCurve
        From :func:`convergence`, checkpoints increasing.
    """
    if curve.n.size == 0:
        return Verdict(False, "no encounters")
    r, lo, hi = float(curve.ratio[-1]), float(curve.lo[-1]), float(curve.hi[-1])
    if not (math.isfinite(r) and math.isfinite(hi)):
        return Verdict(False, f"ratio undefined at N={int(curve.n[-1])} (ratio {r:.3g})")
    tail = curve.n >= (1.0 - tail_fraction) * float(curve.n[-1])
    if int(tail.sum()) < min_checkpoints:
        return Verdict(False, f"{int(tail.sum())} checkpoints in the last {tail_fraction:.0%}, need {min_checkpoints}")
    scale = max(r, floor)
    drift = np.abs(curve.ratio[tail] - r)
    worst = float(np.nanmax(np.where(np.isfinite(drift), drift, np.inf)))
    if worst > tol * scale:
        return Verdict(
            False,
            f"ratio moved by {worst / scale:.3g} (relative) over the last {tail_fraction:.0%}, tolerance {tol:.3g}",
        )
    half = (hi - lo) / 2.0
    if half > max_rel_half_width * scale:
        return Verdict(False, f"CI half-width {half / scale:.3g} of the ratio, bound {max_rel_half_width:.3g}")
    return Verdict(True, "")
