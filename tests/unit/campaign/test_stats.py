"""The campaign's estimators, summary and report (companion.campaign.stats, .summary, .report).

The coverage tests simulate paired campaigns with a known risk ratio; everything random has a
fixed seed, so each run checks the same draws.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from companion.campaign.report import fmt_estimate, fmt_number, worst_encounters, write_report
from companion.campaign.stats import (
    MEASURED_COLUMNS,
    StatsError,
    convergence,
    default_checkpoints,
    induced_rate,
    is_converged,
    percentiles,
    risk_ratio,
    unnecessary_rate,
    weighted_quantile,
    weighted_rate,
)
from companion.campaign.summary import campaign_columns, event_convergence, summarise

P_WITHOUT, P_WITH = 0.3, 0.03
TRUE_RR = P_WITH / P_WITHOUT


def paired_events(rng, n, p_without, p_with, p_with_given_event):
    """(with, without) events (n,) with the given marginals, positively correlated:
    ``P(with | without) = p_with_given_event``."""
    without = rng.random(n) < p_without
    p_with_given_none = (p_with - p_without * p_with_given_event) / (1 - p_without)
    with_ = np.where(without, rng.random(n) < p_with_given_event, rng.random(n) < p_with_given_none)
    return with_, without


def importance_campaign(rng, n):
    """A campaign drawn from a proposal that over-samples hard encounters.

    Hard encounters are 20 % of the true encounter model and half of the proposal; each row's
    weight is p/q. Marginally ``P(without) = 0.3`` and ``P(with) = 0.03`` (RR 0.1).
    """
    p_hard, q_hard = 0.2, 0.5
    hard = rng.random(n) < q_hard
    weights = np.where(hard, p_hard / q_hard, (1 - p_hard) / (1 - q_hard))
    p_without = np.where(hard, 0.9, 0.15)
    p_with = np.where(hard, 0.09, 0.015)
    without = rng.random(n) < p_without
    p_given = np.minimum(p_with / p_without, 3 * p_with)
    p_none = (p_with - p_without * p_given) / (1 - p_without)
    with_ = np.where(without, rng.random(n) < p_given, rng.random(n) < p_none)
    return with_, without, weights


def coverage(draw, reps, **kwargs):
    rng = np.random.default_rng(20240611)
    hits = 0
    for _ in range(reps):
        est = risk_ratio(*draw(rng), **kwargs)
        hits += est.lo <= TRUE_RR <= est.hi
    return hits / reps


# ---- the intervals cover a known ratio --------------------------------------------------------


def test_delta_interval_covers_known_ratio_unweighted():
    cov = coverage(lambda rng: (*paired_events(rng, 600, P_WITHOUT, P_WITH, 0.08), None), 400)
    assert 0.92 <= cov <= 0.98


def test_delta_interval_covers_known_ratio_with_importance_weights():
    cov = coverage(lambda rng: importance_campaign(rng, 400), 400)
    assert 0.92 <= cov <= 0.98


def test_importance_weights_average_to_one_for_their_proposal():
    _, _, w = importance_campaign(np.random.default_rng(3), 200_000)
    assert abs(w.mean() - 1.0) < 0.01


def test_importance_weighted_rates_recover_the_true_model():
    a, b, w = importance_campaign(np.random.default_rng(4), 20_000)
    assert weighted_rate(b, w).lo <= P_WITHOUT <= weighted_rate(b, w).hi
    assert abs(weighted_rate(a, w).value - P_WITH) < 0.005
    assert abs(b.mean() - P_WITHOUT) > 0.1  # the unweighted rate is biased by the proposal


def test_bootstrap_interval_covers_known_ratio():
    cov = coverage(
        lambda rng: (*paired_events(rng, 600, P_WITHOUT, P_WITH, 0.08), None), 150, method="bootstrap", n_boot=400
    )
    assert 0.9 <= cov <= 0.99


def test_bootstrap_agrees_with_delta_on_a_large_campaign():
    a, b = paired_events(np.random.default_rng(5), 5000, P_WITHOUT, P_WITH, 0.08)
    d, boot = risk_ratio(a, b), risk_ratio(a, b, method="bootstrap", seed=1)
    assert boot.value == d.value and boot.method == "bootstrap"
    assert boot.lo == pytest.approx(d.lo, rel=0.1) and boot.hi == pytest.approx(d.hi, rel=0.1)
    assert risk_ratio(a, b, method="bootstrap", seed=1) == boot


def test_paired_covariance_narrows_the_interval():
    rng = np.random.default_rng(6)
    b = rng.random(2000) < 0.3
    a_corr = b & (rng.random(2000) < 0.5)  # every event with the system also without
    a_indep = rng.random(2000) < a_corr.mean()
    width = lambda a: math.log(risk_ratio(a, b).hi / risk_ratio(a, b).lo)
    assert width(a_corr) < 0.7 * width(a_indep)


# ---- rates, zero events, flags ----------------------------------------------------------------


def test_unit_weight_rate_is_exact_clopper_pearson():
    e = np.zeros(50, bool)
    e[:7] = True
    est = weighted_rate(e)
    ci = sps.binomtest(7, 50).proportion_ci(0.95, method="exact")
    assert est.value == pytest.approx(0.14)
    assert (est.lo, est.hi) == pytest.approx((ci.low, ci.high), rel=1e-9)
    assert est.n == 50 and est.n_eff == pytest.approx(50)


def test_rate_with_no_event_is_the_weighted_rule_of_three():
    est = weighted_rate(np.zeros(300, bool), np.full(300, 2.0))
    assert est.value == 0 and est.lo == 0
    assert est.hi == pytest.approx(3 / 300, rel=0.01)
    w = np.r_[np.full(150, 0.5), np.full(150, 1.5)]  # Kish n_eff = 240
    assert weighted_rate(np.zeros(300, bool), w).hi == pytest.approx(1 - 0.05 ** (1 / 240))


def test_ratio_with_no_event_with_the_system_is_zero_with_an_upper_bound():
    b = np.zeros(1000, bool)
    b[:300] = True
    est = risk_ratio(np.zeros(1000, bool), b)
    assert (est.value, est.lo, est.flag) == (0.0, 0.0, "zero_with")
    assert est.hi == pytest.approx((1 - 0.05 ** (1 / 1000)) / 0.3)


def test_ratio_flags_the_undefined_cases():
    a = np.zeros(100, bool)
    a[:3] = True
    inf = risk_ratio(a, np.zeros(100, bool))
    assert inf.value == math.inf and inf.flag == "zero_without" and inf.lo > 0
    none = risk_ratio(np.zeros(100, bool), np.zeros(100, bool))
    assert math.isnan(none.value) and none.flag == "no_events" and not none.defined
    empty = risk_ratio(np.zeros(0, bool), np.zeros(0, bool))
    assert math.isnan(empty.value) and empty.flag == "empty"
    assert weighted_rate([]).flag == "empty"


def test_bad_inputs_name_what_is_wrong():
    with pytest.raises(StatsError, match=r"weights\[1\]"):
        weighted_rate([True, False], [1.0, -1.0])
    with pytest.raises(StatsError, match="one length"):
        risk_ratio([True, False], [True, True, False])
    with pytest.raises(StatsError, match="method"):
        risk_ratio([True], [True], method="wald")


def test_induced_and_unnecessary_rates_count_the_right_encounters():
    with_ = np.array([1, 1, 0, 0, 1], bool)
    without = np.array([1, 0, 0, 1, 0], bool)
    assert induced_rate(with_, without).value == pytest.approx(2 / 5)
    w = np.array([1, 3, 1, 1, 1.0])
    assert induced_rate(with_, without, w).value == pytest.approx(4 / 7)
    manoeuvred = np.array([1, 1, 1, 0, 0], bool)
    assert unnecessary_rate(manoeuvred, without).value == pytest.approx(2 / 5)


def test_percentiles_tolerate_empty_and_nan():
    assert all(math.isnan(x) for x in percentiles([], (50, 99)))
    assert percentiles([1.0, np.nan, 3.0], (50,)) == (2.0,)
    assert percentiles(np.arange(101.0), (50, 99)) == (50.0, 99.0)
    assert weighted_quantile([1.0, 2.0, 3.0], [1.0, 1.0, 10.0], 0.5) == 3.0
    assert math.isnan(weighted_quantile([], [], 0.5))


def test_measured_columns_are_the_machine_timings():
    assert set(MEASURED_COLUMNS) == {"wall_ms", "cpu_ms", "m_decide_wall_ms"}


events = st.lists(st.tuples(st.booleans(), st.booleans(), st.floats(0.01, 100.0)), min_size=1, max_size=60)


@settings(max_examples=60, deadline=None)
@given(events, st.floats(1e-3, 1e3))
def test_ratio_is_invariant_to_scaling_the_weights(rows, scale):
    a, b, w = (np.array(c) for c in zip(*rows))
    r1, r2 = risk_ratio(a, b, w), risk_ratio(a, b, w * scale)
    assert r1.flag == r2.flag
    for x, y in ((r1.value, r2.value), (r1.lo, r2.lo), (r1.hi, r2.hi)):
        assert x == pytest.approx(y, rel=1e-9, nan_ok=True)


@settings(max_examples=80, deadline=None)
@given(events)
def test_ratio_is_in_zero_to_infinity_and_inside_its_interval(rows):
    a, b, w = (np.array(c) for c in zip(*rows))
    r = risk_ratio(a, b, w)
    if r.flag == "no_events":
        assert math.isnan(r.value)
        return
    assert 0.0 <= r.lo <= r.value <= r.hi
    assert (r.value == math.inf) == (r.flag == "zero_without")
    rate = weighted_rate(a, w)
    assert 0.0 <= rate.lo <= rate.value <= rate.hi <= 1.0


# ---- convergence --------------------------------------------------------------------------------


def test_a_converging_sequence_is_converged():
    rng = np.random.default_rng(7)
    b = rng.random(20_000) < 0.3
    a = b & (rng.random(20_000) < 0.5)
    curve = convergence(a, b)
    assert curve.n[-1] == 20_000 and np.all(np.diff(curve.n) > 0)
    verdict = is_converged(curve)
    assert verdict.converged, verdict.reason
    assert curve.ratio[-1] == pytest.approx(0.5, rel=0.05)


def test_a_drifting_sequence_is_not_converged():
    rng = np.random.default_rng(8)
    n = 20_000
    b = rng.random(n) < 0.3
    a = b & (rng.random(n) < np.linspace(0.1, 0.9, n))  # the system gets worse as ids grow
    verdict = is_converged(convergence(a, b))
    assert not verdict.converged and "moved" in verdict.reason


def test_a_small_campaign_is_not_precise_enough():
    a, b = paired_events(np.random.default_rng(9), 300, P_WITHOUT, P_WITH, 0.08)
    verdict = is_converged(convergence(a, b))
    assert not verdict.converged and verdict.reason


def test_a_ratio_of_zero_converges_through_the_floor():
    b = np.random.default_rng(10).random(20_000) < 0.3
    assert is_converged(convergence(np.zeros(20_000, bool), b)).converged
    small = is_converged(convergence(np.zeros(500, bool), b[:500]))
    assert not small.converged and "half-width" in small.reason


def test_convergence_needs_checkpoints_in_the_tail_and_a_defined_ratio():
    a, b = np.ones(100, bool), np.ones(100, bool)
    few = is_converged(convergence(a, b, checkpoints=[10, 50, 100]))
    assert not few.converged and "checkpoints" in few.reason
    undefined = is_converged(convergence(np.zeros(100, bool), np.zeros(100, bool)))
    assert not undefined.converged and "undefined" in undefined.reason
    assert np.sum(default_checkpoints(1000) >= 800) >= 5
    with pytest.raises(StatsError, match="checkpoints"):
        convergence(a, b, checkpoints=[0, 100])


# ---- summary and report --------------------------------------------------------------------------

STRATA = ("head-on", "crossing", "overtake", "manned-fixedwing")
KINDS = ("evade", "switch", "retime", "hold", "replan", "resume")


def synthetic_rows(n=300, seed=11):
    """Campaign rows in the flying code's schema, with separations that make sense."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in rng.permutation(n):  # any order: summarise sorts by id
        stratum = STRATA[i % len(STRATA)]
        manned = stratum.startswith("manned")
        weight = float(rng.choice([0.4, 1.6])) if stratum == "crossing" else 1.0
        k = int(rng.integers(1, 3))
        u_hmd = rng.gamma(2.0, 40.0, k)
        u_vmd = rng.gamma(2.0, 10.0, k)
        m_hmd = u_hmd + rng.gamma(2.0, 30.0, k) if rng.random() < 0.95 else 0.02 * u_hmd  # or worse
        m_vmd = u_vmd + rng.gamma(2.0, 5.0, k) if m_hmd[0] > u_hmd[0] else 0.02 * u_vmd
        u_sep = float(np.min(np.hypot(u_hmd, u_vmd))) - 5.0
        m_sep = float(np.min(np.hypot(m_hmd, m_vmd))) - 5.0
        decisions = [str(x) for x in rng.choice(KINDS, int(rng.integers(0, 4)))]
        u_path = float(rng.uniform(400, 600))
        m_path = u_path + float(rng.gamma(2.0, 15.0)) * bool(decisions)
        row = {
            "id": int(i),
            "stratum": stratum,
            "source": "manned" if manned else "parametric",
            "traffic": "fixedwing" if manned else ("drone", "rotorcraft")[i % 2],
            "world": ("open", "cluttered", "fenced")[i % 3],
            "seed": int(1000 + i),
            "spec_hash": "abc123",
            "weight": weight,
            "n_threats": k,
            "wall_ms": float(rng.uniform(50, 90)),
            "m_decide_wall_ms": [float(x) for x in rng.uniform(1, 5, len(decisions))],
            "noise_pos_m": 1.0,
            "noise_vel_m_s": 0.2,
            "update_hz": 1.0,
            "latency_s": 0.5,
            "dropout": 0.0,
        }
        for p, sep, hmd, vmd, path, done in (
            ("u_", u_sep, u_hmd, u_vmd, u_path, u_sep > 0),
            ("m_", m_sep, m_hmd, m_vmd, m_path, rng.random() < 0.95),
        ):
            row.update(
                {
                    f"{p}collision": sep < 0,
                    f"{p}nmac": sep < 15.0,
                    f"{p}lowc": sep < 60.0,
                    f"{p}min_sep_m": sep,
                    f"{p}hmd_m": hmd.tolist(),
                    f"{p}vmd_m": vmd.tolist(),
                    f"{p}obstacle_entries": 0,
                    f"{p}fence_entries": 0,
                    f"{p}completed": bool(done),
                    f"{p}path_m": path,
                }
            )
        row.update(
            {
                "m_alerted": True,
                "m_alert_t_s": float(rng.uniform(0, 5)),
                "m_manoeuvred": bool(decisions),
                "m_decisions": decisions,
                "m_latency_ms": [float(x) for x in rng.lognormal(2.0, 0.5, len(decisions))],
                "m_extra_path_m": m_path - u_path,
            }
        )
        rows.append(row)
    return rows


@dataclass(frozen=True)
class Flight:
    t_s: np.ndarray
    own_u_ned_m: np.ndarray
    own_m_ned_m: np.ndarray
    threats: list


def synthetic_flight(enc_id):
    t = np.linspace(0.0, 60.0, 121)
    own_u = np.c_[10.0 * t, np.zeros_like(t), np.full_like(t, -50.0)]
    own_m = own_u + np.c_[np.zeros_like(t), 30.0 * np.sin(np.pi * t / 60.0), np.zeros_like(t)]
    threat = np.c_[600.0 - 10.0 * t, np.full_like(t, 5.0 + enc_id % 7), np.full_like(t, -55.0)]
    return Flight(t, own_u, own_m, [threat])


def test_summary_per_group_matches_the_estimators():
    rows = synthetic_rows()
    summary = summarise(pa.Table.from_pylist(rows))
    assert summary.overall.n == 300 and sum(g.n for g in summary.strata) == 300
    assert [g.name for g in summary.strata] == sorted(STRATA)
    assert {g.name for g in summary.traffic} == {"drone", "rotorcraft", "fixedwing"}
    crossing = [r for r in sorted(rows, key=lambda r: r["id"]) if r["stratum"] == "crossing"]
    w = np.array([r["weight"] for r in crossing])
    expected = risk_ratio([r["m_lowc"] for r in crossing], [r["u_lowc"] for r in crossing], w)
    assert summary.stratum("crossing").lowc.risk_ratio == expected
    assert summary.stratum("crossing").n_eff < summary.stratum("crossing").n
    lat = [x for r in rows for x in r["m_latency_ms"]]
    assert summary.overall.latency.p99_ms == pytest.approx(np.percentile(lat, 99))
    assert {s.kind for s in summary.overall.latency_by_kind} <= set(KINDS)
    for by_kind in summary.overall.latency_by_kind:  # the measured compute, kind by kind
        measured = [ms for r in rows for k, ms in zip(r["m_decisions"], r["m_decide_wall_ms"]) if k == by_kind.kind]
        assert by_kind.compute_p99_ms == pytest.approx(np.percentile(measured, 99))
    assert summary.overall.m_collisions == sum(r["m_collision"] for r in rows)


def test_event_convergence_reads_the_rows_in_id_order():
    rows = synthetic_rows(200)
    ordered = sorted(rows, key=lambda r: r["id"])
    curve = event_convergence(rows, "lowc", checkpoints=[50, 200])
    first = risk_ratio(
        [r["m_lowc"] for r in ordered[:50]], [r["u_lowc"] for r in ordered[:50]], [r["weight"] for r in ordered[:50]]
    )
    assert list(curve.n) == [50, 200] and curve.ratio[0] == first.value and curve.hi[0] == first.hi
    with pytest.raises(StatsError, match="metric"):
        event_convergence(rows, "nmacs")


def test_summary_to_dict_is_json_and_the_same_from_a_list_of_dicts():
    rows = synthetic_rows(120)
    d = summarise(rows).to_dict()
    assert d == summarise(pa.Table.from_pylist(rows)).to_dict()
    text = json.dumps(d, allow_nan=False)
    assert "risk_ratio" in text and d["overall"]["n"] == 120


def test_summary_names_bad_rows():
    rows = synthetic_rows(20)
    with pytest.raises(StatsError, match="m_lowc"):
        summarise([{k: v for k, v in r.items() if k != "m_lowc"} for r in rows])
    rows[3]["m_latency_ms"] = rows[3]["m_latency_ms"] + [1.0]
    with pytest.raises(StatsError, match=f"id {rows[3]['id']}"):
        campaign_columns(rows)
    dup = synthetic_rows(5) + synthetic_rows(5)
    with pytest.raises(StatsError, match="more than once"):
        campaign_columns(dup)


def test_number_formatting():
    assert fmt_number(0.031234) == "0.0312"
    assert fmt_number(1234.5) == "1230"
    assert fmt_number(float("nan")) == "n/a" and fmt_number(math.inf) == "inf"
    assert re.fullmatch(r"0\.5 \[0\.\d{3}, 0\.\d{3}\]", fmt_estimate(risk_ratio([True, False] * 50, [True] * 100)))
    assert "zero with" in fmt_estimate(risk_ratio([False] * 10, [True] * 10))


def test_worst_encounters_put_mitigated_collisions_first():
    cols = campaign_columns(synthetic_rows())
    idx = worst_encounters(cols, 8)
    assert cols["m_collision"][idx].any()
    keys = [(not cols["m_collision"][i], not cols["m_nmac"][i], cols["m_min_sep_m"][i]) for i in idx]
    assert keys == sorted(keys)
    others = np.setdiff1d(np.arange(cols.n), idx)
    assert min((not cols["m_collision"][i], not cols["m_nmac"][i], cols["m_min_sep_m"][i]) for i in others) >= keys[-1]


def test_report_writes_markdown_and_figures(tmp_path):
    path = write_report(synthetic_rows(), tmp_path / "plain", spec_name="synthetic", worst=5)
    text = path.read_text()
    assert path.name == "report.md" and "# Validation campaign: synthetic" in text
    for section in ("## Overall", "## Per stratum", "## Per traffic kind", "## Convergence", "## Worst encounters"):
        assert section in text
    for fig in ("convergence.png", "miss_distances.png", "risk_ratios.png"):
        assert (tmp_path / "plain" / fig).stat().st_size > 5000 and f"({fig})" in text
    assert not list((tmp_path / "plain").glob("encounter_*.png"))
    assert all(s in text for s in STRATA)


def test_report_draws_the_worst_flights(tmp_path):
    asked = []
    path = write_report(
        pa.Table.from_pylist(synthetic_rows()),
        tmp_path,
        spec_name="s",
        worst=3,
        flight_of=lambda i: asked.append(i) or synthetic_flight(i),
    )
    figures = sorted(p.name for p in tmp_path.glob("encounter_*.png"))
    assert len(asked) == 3 and figures == sorted(f"encounter_{i}.png" for i in asked)
    assert all(f"({f})" in path.read_text() for f in figures)


def test_report_flags_undefined_ratios(tmp_path):
    rows = synthetic_rows(200)
    for r in rows:
        if r["stratum"] == "overtake":  # no NMAC with the system: RR 0, one-sided
            r["m_nmac"] = r["m_collision"] = False
        if r["stratum"] == "head-on":  # no NMAC either way: RR undefined
            r["m_nmac"] = r["u_nmac"] = r["m_collision"] = r["u_collision"] = False
    summary = summarise(rows)
    assert summary.stratum("overtake").nmac.risk_ratio.flag == "zero_with"
    assert summary.stratum("head-on").nmac.risk_ratio.flag == "no_events"
    text = write_report(rows, tmp_path, spec_name="degenerate").read_text()
    assert "n/a (no events)" in text and "(zero with)" in text
    assert "no event with the system: the ratio is 0" in text
    assert (tmp_path / "risk_ratios.png").stat().st_size > 5000


def test_report_sets_the_events_against_the_oracle(tmp_path):
    rows = synthetic_rows()
    drone = [r for r in rows if r["traffic"] == "drone" and r["m_collision"]]
    assert drone, "the synthetic rows need a mitigated drone-scale collision"
    labels = [
        {
            "id": r["id"],
            "event": "collision",
            "avoidable": k % 2 == 0,
            "best_margin_m": 0.1,
            "witness": "",
            "horizon_s": 12.0,
            "oracle_ms": 1.0,
        }
        for k, r in enumerate(drone)
    ]
    text = write_report(rows, tmp_path, spec_name="s", labels=labels).read_text()
    section = text[text.index("## What the oracle says") :]
    n_avoidable = sum(lab["avoidable"] for lab in labels)
    assert f"| collision | {len(drone)} | {len(drone)} | {n_avoidable} | {len(drone) - n_avoidable} |" in section
    assert "## What the oracle says" not in write_report(rows, tmp_path / "none", spec_name="s").read_text()
