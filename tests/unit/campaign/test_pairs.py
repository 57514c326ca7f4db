"""Encounters flown twice by the fast-time executor (``companion.campaign.flying``): the rows are
reproducible (the same worker twice, a fresh worker), complete and typed, and their unmitigated
flags agree with a recomputation from the flown tracks.

One worker is built for the module (numba compiled, the missions planned and flown once); the
three encounters are one per stratum. About 30-40 s in all.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.campaign.flying import MEASURED_COLUMNS, CampaignWorker
from companion.campaign.judge import FT_M
from companion.campaign.manned import miss_weight
from companion.campaign.spec import CampaignSpec
from companion.campaign.traffic_model import MODEL_FILES, models_directory
from companion.config import Settings

STRATA = ("popup_far/open", "crossing/open", "manned/rotorcraft")
INDICES = (0, 1, 2)
SPEC = CampaignSpec(strata=STRATA)

pytestmark = pytest.mark.skipif(
    not (models_directory() / MODEL_FILES["rotorcraft"]).is_file(),
    reason=f"encounter models not in {models_directory()} (COMPANION_ENCOUNTER_MODELS)",
)

INT_COLUMNS = (
    "id",
    "seed",
    "n_threats",
    "u_obstacle_entries",
    "u_fence_entries",
    "m_obstacle_entries",
    "m_fence_entries",
)
STR_COLUMNS = ("stratum", "source", "traffic", "world", "mission", "spec_hash")
BOOL_COLUMNS = (
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
FLOAT_COLUMNS = (
    "weight",
    "u_min_sep_m",
    "u_path_m",
    "m_min_sep_m",
    "m_path_m",
    "m_alert_t_s",
    "m_extra_path_m",
    "noise_pos_m",
    "noise_vel_m_s",
    "update_hz",
    "latency_s",
    "dropout",
    "wall_ms",
    "cpu_ms",
)
FLOAT_LIST_COLUMNS = ("u_hmd_m", "u_vmd_m", "m_hmd_m", "m_vmd_m", "m_latency_ms", "m_decide_wall_ms")
STR_LIST_COLUMNS = ("m_decisions",)
ALL_COLUMNS = INT_COLUMNS + STR_COLUMNS + BOOL_COLUMNS + FLOAT_COLUMNS + FLOAT_LIST_COLUMNS + STR_LIST_COLUMNS


@pytest.fixture(scope="module")
def worker() -> CampaignWorker:
    return CampaignWorker(SPEC, Settings(), "h")


@pytest.fixture(scope="module")
def rows(worker) -> dict:
    return {i: worker.row(i) for i in INDICES}


@pytest.fixture(scope="module")
def flights(worker) -> dict:
    return {i: worker.fly(i) for i in INDICES}


def _same(a, b) -> bool:
    """Equal, NaN equal to NaN, element by element for lists; the types equal too."""
    if type(a) is not type(b):
        return False
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return a == b


def assert_rows_equal(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    different = [k for k in a if k not in MEASURED_COLUMNS and not _same(a[k], b[k])]
    assert not different, {k: (a[k], b[k]) for k in different}


# ---------------------------------------------------------------------------------------------
# reproducibility
# ---------------------------------------------------------------------------------------------


def test_row_repeats_on_the_same_worker(worker, rows):
    for i in INDICES:
        assert_rows_equal(rows[i], worker.row(i))


def test_row_repeats_on_a_fresh_worker(rows):
    fresh = CampaignWorker(SPEC, Settings(), "h")
    for i in reversed(INDICES):  # another order: nothing may depend on what was flown before
        assert_rows_equal(rows[i], fresh.row(i))


def test_the_comparison_sees_a_difference(rows):
    """The row comparison itself can fail (a changed value, a NaN against a number)."""
    changed = dict(rows[0], u_min_sep_m=rows[0]["u_min_sep_m"] + 1e-9)
    with pytest.raises(AssertionError):
        assert_rows_equal(rows[0], changed)
    assert not _same(float("nan"), 0.0) and _same([float("nan")], [float("nan")])
    assert not _same(1, 1.0)


def test_encounter_is_pure(worker):
    for i in INDICES:
        a, b = worker.encounter(i), worker.encounter(i)
        assert a.params == b.params and a.weight == b.weight and a.end_t_s == b.end_t_s
        for ta, tb in zip(a.intruders, b.intruders, strict=True):
            np.testing.assert_array_equal(ta.pos_ned_m, tb.pos_ned_m)
            np.testing.assert_array_equal(ta.t_s, tb.t_s)


# ---------------------------------------------------------------------------------------------
# the columns
# ---------------------------------------------------------------------------------------------


def test_every_column_with_its_type(rows):
    for i, row in rows.items():
        assert set(row) == set(ALL_COLUMNS), set(row) ^ set(ALL_COLUMNS)
        for k in INT_COLUMNS:
            assert type(row[k]) is int, (i, k, row[k])
        for k in STR_COLUMNS:
            assert type(row[k]) is str and row[k], (i, k)
        for k in BOOL_COLUMNS:
            assert type(row[k]) is bool, (i, k, row[k])
        for k in FLOAT_COLUMNS:
            assert type(row[k]) is float, (i, k, row[k])
        for k in FLOAT_LIST_COLUMNS:
            assert type(row[k]) is list and all(type(x) is float for x in row[k]), (i, k, row[k])
        for k in STR_LIST_COLUMNS:
            assert type(row[k]) is list and all(type(x) is str for x in row[k]), (i, k)


def test_column_values(rows):
    for i, row in rows.items():
        manned = STRATA[i % len(STRATA)].startswith("manned/")
        assert row["id"] == i and row["stratum"] == STRATA[i % len(STRATA)]
        assert row["seed"] == SPEC.seed and row["spec_hash"] == "h"
        assert row["source"] == ("manned" if manned else "parametric")
        assert row["traffic"] == ("rotorcraft" if manned else "drone")
        assert row["world"] == "open" and row["mission"] == ("long" if manned else "open")
        for prefix in ("u_", "m_"):
            assert len(row[f"{prefix}hmd_m"]) == len(row[f"{prefix}vmd_m"]) == row["n_threats"] >= 1
            assert row[f"{prefix}collision"] <= row[f"{prefix}nmac"] <= row[f"{prefix}lowc"]
            assert row[f"{prefix}obstacle_entries"] == row[f"{prefix}fence_entries"] == 0  # open air
            assert row[f"{prefix}path_m"] > 0
        assert row["m_extra_path_m"] == pytest.approx(row["m_path_m"] - row["u_path_m"])
        assert row["m_alerted"] == (not math.isnan(row["m_alert_t_s"]))
        assert len(row["m_latency_ms"]) == len(row["m_decisions"]) == len(row["m_decide_wall_ms"])
        assert row["update_hz"] == (1.0 if manned else 2.0)
        assert row["noise_pos_m"] == row["noise_vel_m_s"] == row["latency_s"] == row["dropout"] == 0.0
        assert row["wall_ms"] > 0 and row["cpu_ms"] > 0


def test_weights(worker, rows):
    for i, row in rows.items():
        if row["source"] == "parametric":
            assert row["weight"] == 1.0
        else:
            enc = worker.encounter(i)
            base = worker.unmitigated(enc.mission)
            own_alt = -float(np.interp(enc.params["t_cpa_s"], base.t_s, base.pos_ned_m[:, 2]))
            assert row["weight"] > 0
            assert row["weight"] == pytest.approx(
                miss_weight(enc.params["hmd_target_m"], enc.params["vmd_target_m"], SPEC.manned, own_alt), rel=1e-6
            )


# ---------------------------------------------------------------------------------------------
# the flags, recomputed from the flown tracks
# ---------------------------------------------------------------------------------------------


def _flags(own_ned_m: np.ndarray, threats: list, radii: list, manned: bool) -> dict:
    """Collision, NMAC, LoWC, least separation and the miss distances, from positions on one grid."""
    v = SPEC.volumes
    out = {"collision": False, "nmac": False, "lowc": False, "min_sep_m": math.inf, "hmd_m": [], "vmd_m": []}
    for pos, radius in zip(threats, radii):
        rel = own_ned_m - pos
        dh = np.sqrt(rel[:, 0] ** 2 + rel[:, 1] ** 2)
        dv = np.abs(rel[:, 2])
        d3 = np.linalg.norm(rel, axis=1)
        k = int(np.argmin(d3))
        out["hmd_m"].append(float(dh[k]))
        out["vmd_m"].append(float(dv[k]))
        out["min_sep_m"] = min(out["min_sep_m"], float(d3.min() - radius))
        out["collision"] |= bool(d3.min() < radius + v.collision_extra_m)
        if manned:
            out["nmac"] |= bool(np.any((dh < v.nmac_h_ft * FT_M) & (dv < v.nmac_v_ft * FT_M)))
            out["lowc"] |= bool(np.any((dh < v.wc_h_ft * FT_M) & (dv < v.wc_v_ft * FT_M)))
        else:
            out["nmac"] |= bool(d3.min() < radius + v.nmac_extra_m)
            out["lowc"] |= bool(d3.min() < radius + v.lowc_extra_m)
    return out


@pytest.mark.parametrize("prefix, track", [("u_", "own_u_ned_m"), ("m_", "own_m_ned_m")])
def test_flags_agree_with_a_recomputation(rows, flights, prefix, track):
    for i in INDICES:
        pair, row = flights[i], rows[i]
        radii = [tr.radius_m for tr in pair.encounter.intruders]
        got = _flags(getattr(pair, track), pair.threats, radii, pair.encounter.traffic != "drone")
        for key in ("collision", "nmac", "lowc"):
            assert row[f"{prefix}{key}"] == got[key], (i, key)
        assert row[f"{prefix}min_sep_m"] == pytest.approx(got["min_sep_m"], abs=1e-9)
        np.testing.assert_allclose(row[f"{prefix}hmd_m"], got["hmd_m"], atol=1e-9)
        np.testing.assert_allclose(row[f"{prefix}vmd_m"], got["vmd_m"], atol=1e-9)


def test_pair_grid_and_true_tracks(worker, flights):
    dt = 1.0 / Settings().link.setpoint_rate_hz
    for pair in flights.values():
        enc = pair.encounter
        assert pair.t_s[0] == enc.first_report_t_s
        assert pair.t_s[-1] == pytest.approx(enc.end_t_s, abs=dt)
        np.testing.assert_allclose(np.diff(pair.t_s), dt, rtol=1e-6)
        assert pair.own_u_ned_m.shape == pair.own_m_ned_m.shape == (pair.t_s.size, 3)
        for pos, tr in zip(pair.threats, enc.intruders, strict=True):
            np.testing.assert_array_equal(pos, tr.position_at(pair.t_s))
        base = worker.unmitigated(enc.mission)
        inside = pair.t_s <= base.t_s[-1]
        expected = np.column_stack([np.interp(pair.t_s[inside], base.t_s, base.pos_ned_m[:, a]) for a in range(3)])
        np.testing.assert_allclose(pair.own_u_ned_m[inside], expected, atol=1e-9)
