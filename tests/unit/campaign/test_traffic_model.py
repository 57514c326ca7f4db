"""MIT LL's uncorrelated encounter model: reading, the samplers against the counts, tracks, bad files."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chisquare

from companion.campaign.traffic_model import (
    MODEL_FILES,
    MODELS_ENV,
    EncounterModel,
    TrafficModelError,
    load_model,
    models_directory,
    read_model,
    sample_dynamic,
    sample_initial,
)
from companion.campaign.traffic_track import (
    FT_TO_M,
    KT_TO_M_S,
    dediscretize,
    dynamic_values,
    integrate,
    resample_mask,
    sample_track,
)

DIRECTORY = models_directory()
pytestmark = pytest.mark.skipif(
    not (DIRECTORY / MODEL_FILES["rotorcraft"]).is_file(),
    reason=f"encounter models not in {DIRECTORY} (set {MODELS_ENV})",
)
KINDS = tuple(MODEL_FILES)


@pytest.fixture(scope="module", params=KINDS)
def model(request) -> EncounterModel:
    return load_model(request.param)


def _configurations(bins: np.ndarray) -> np.ndarray:
    """Every combination of the given variables' bins, (prod(bins), len(bins))."""
    return np.indices(tuple(bins)).reshape(len(bins), -1).T


def _exact_marginals(model: EncounterModel) -> list[np.ndarray]:
    """Each initial variable's marginal, by enumerating the joint as the product of the
    conditionals (counts normalised per column), independent of the sampler."""
    net = model.initial
    assert net.order == tuple(range(net.n))  # the chain G -> A -> ... -> psi-dot
    joint = _configurations(net.bins)
    p = np.ones(joint.shape[0])
    for i in net.order:
        counts = net.counts[i]
        column = net.parent_index(i, joint)
        totals = counts.sum(axis=0)[column]
        p *= np.divide(counts[joint[:, i], column], totals, out=np.zeros_like(p), where=totals > 0)
    return [np.bincount(joint[:, i], weights=p, minlength=net.bins[i]) for i in range(net.n)]


def _chi_square_p(observed: np.ndarray, probabilities: np.ndarray) -> float:
    """Chi-square p value, the cells expecting fewer than 5 merged into one (then into the
    smallest other cell if still below 5)."""
    assert observed[probabilities == 0].sum() == 0  # never a bin of probability 0
    expected = probabilities / probabilities.sum() * observed.sum()
    small = expected < 5
    obs, exp = list(observed[~small]), list(expected[~small])
    if small.any():
        obs.append(observed[small].sum())
        exp.append(expected[small].sum())
        if exp[-1] < 5:
            k = int(np.argmin(exp[:-1]))
            obs[k] += obs.pop()
            exp[k] += exp.pop()
    return float(chisquare(obs, exp).pvalue) if len(obs) > 1 else 1.0


# ---------------------------------------------------------------------------- reading


@pytest.mark.parametrize("kind", KINDS)
def test_the_real_files_read_with_consistent_shapes(kind):
    model = load_model(kind)
    initial, transition = model.initial, model.transition
    assert initial.labels == ("G", "A", "L", "v", "\\dot v", "\\dot h", "\\dot \\psi")
    assert transition.n == 10 and transition.labels[7:] == ("\\dot v(t+1)", "\\dot h(t+1)", "\\dot \\psi(t+1)")
    assert initial.bins.tolist() == [5, 4, 4, 8, 5, 7, 7]
    assert transition.bins.tolist() == [5, 4, 4, 8, 5, 7, 7, 5, 7, 7]
    for net in (initial, transition):
        position = {v: k for k, v in enumerate(net.order)}
        assert sorted(net.order) == list(range(net.n))
        assert all(position[p] < position[i] for i in range(net.n) for p in net.parents[i])  # acyclic
    for i, counts in enumerate(initial.counts):
        assert counts.shape == (initial.bins[i], np.prod(initial.bins[list(initial.parents[i])]))
    assert [c.shape[1] for c in transition.counts[:7]] == [0] * 7
    assert [c.shape for c in transition.counts[7:]] == [(5, 7840), (7, 3920), (7, 1120)]
    assert model.temporal_map == ((4, 7), (5, 8), (6, 9)) and model.dynamic == (4, 5, 6)
    assert model.boundaries[0] is None and model.boundaries[1] is None
    assert model.boundaries[2].tolist() == [50, 500, 1200, 3000, 5000]
    assert model.boundaries[5][[0, -1]].tolist() == [-2000, 2000]
    assert model.resample_rates.shape == (7,) and model.resample_rates[:2].tolist() == [0, 0]
    assert load_model(kind) is model  # parsed once per process


def test_the_initial_counts_form_one_joint_table(model):
    """Each variable's column sums are its parent's joint counts: checks the column-major layout
    and the parents' column convention of ``parent_index``."""
    net = model.initial
    for i in range(1, 5):
        joint = _configurations(net.bins[:i])  # every configuration of variables < i
        values = np.zeros((joint.shape[0], net.n), dtype=int)
        values[:, :i] = joint
        child = net.counts[i].sum(axis=0)[net.parent_index(i, values)]
        parent = net.counts[i - 1][joint[:, i - 1], net.parent_index(i - 1, values)]
        np.testing.assert_array_equal(child, parent)
    assert net.parent_index(3, [2, 3, 1, 0, 0, 0, 0]) == 2 + 5 * 3 + 20 * 1


# ---------------------------------------------------------------------------- sampling


def test_the_initial_sampler_reproduces_the_models_marginals(model):
    samples = sample_initial(model, np.random.default_rng(20240601), size=20_000)
    assert samples.shape == (20_000, 7)
    exact = _exact_marginals(model)
    for i in range(7):
        np.testing.assert_allclose(exact[i], model.initial.counts[i].sum(axis=1) / model.initial.counts[i].sum())
        observed = np.bincount(samples[:, i], minlength=model.initial.bins[i])
        assert observed.size == model.initial.bins[i]
        assert _chi_square_p(observed, exact[i]) > 1e-3, model.initial.labels[i]


def test_a_single_initial_sample_is_one_row_of_bins(model):
    bins = sample_initial(model, np.random.default_rng(3))
    assert bins.shape == (7,) and np.all((bins >= 0) & (bins < model.initial.bins))


def test_one_transition_step_follows_the_transition_counts(model):
    rng = np.random.default_rng(11)
    start = np.array([0, 3, 1, 2, 2, 3, 3])  # CONUS, other airspace, 500-1200 ft, steady
    steps = np.array([sample_dynamic(model, start, 2, rng)[1] for _ in range(3000)])
    net = model.transition
    state = np.concatenate([start, start[4:]])
    for k, i in enumerate(model.dynamic_next):
        column = net.counts[i][:, net.parent_index(i, state)]
        assert column.sum() > 0
        assert _chi_square_p(np.bincount(steps[:, k], minlength=net.bins[i]), column) > 1e-3


def test_dynamic_bins_start_from_the_initial_sample_and_stay_in_range(model):
    rng = np.random.default_rng(5)
    for _ in range(20):
        initial = sample_initial(model, rng)
        bins = sample_dynamic(model, initial, 150, rng)
        assert bins.shape == (150, 3)
        np.testing.assert_array_equal(bins[0], initial[list(model.dynamic)])
        assert np.all((bins >= 0) & (bins < model.initial.bins[list(model.dynamic)]))
    with pytest.raises(TrafficModelError, match="duration_s"):
        sample_dynamic(model, initial, 2.5, rng)


def _dynamics(model: EncounterModel, seed: int, tracks: int, seconds: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [sample_dynamic(model, sample_initial(model, rng), seconds, rng) for _ in range(tracks)]


def _within_binomial(hits: int, trials: int, p: float) -> bool:
    return abs(hits - trials * p) <= 4.5 * np.sqrt(trials * p * (1 - p)) + 1


def test_resampling_in_an_unchanged_bin_happens_at_the_resample_rate(model):
    rng = np.random.default_rng(7)
    rates = model.resample_rates[list(model.dynamic)]
    draws, stays = np.zeros(3, int), np.zeros(3, int)
    for bins in _dynamics(model, 8, 60, 200):
        mask = resample_mask(bins, rates, rng)
        assert mask[0].all() and mask[1:][bins[1:] != bins[:-1]].all()  # a new bin is a new value
        unchanged = bins[1:] == bins[:-1]
        draws += (mask[1:] & unchanged).sum(axis=0)
        stays += unchanged.sum(axis=0)
    for k in range(3):
        assert _within_binomial(int(draws[k]), int(stays[k]), rates[k]), (k, draws[k], stays[k], rates[k])


def test_values_are_held_between_draws_and_redrawn_at_the_rate(model):
    rng = np.random.default_rng(9)
    rates = model.resample_rates[list(model.dynamic)]
    changes, stays = np.zeros(3, int), np.zeros(3, int)
    for bins in _dynamics(model, 10, 60, 200):
        values = dynamic_values(model, bins, rng)
        low = np.column_stack([model.boundaries[i][bins[:, k]] for k, i in enumerate(model.dynamic)])
        high = np.column_stack([model.boundaries[i][bins[:, k] + 1] for k, i in enumerate(model.dynamic)])
        assert np.all((values >= low) & (values <= high))
        zero = (low < 0) & (high > 0)
        assert np.all(values[zero] == 0)  # the zero bin is exactly 0
        unchanged = (bins[1:] == bins[:-1]) & ~zero[1:]  # where only a resample changes it
        changes += ((values[1:] != values[:-1]) & unchanged).sum(axis=0)
        stays += unchanged.sum(axis=0)
    for k in range(3):
        assert _within_binomial(int(changes[k]), int(stays[k]), rates[k]), (k, changes[k], stays[k], rates[k])


# ---------------------------------------------------------------------------- dediscretize


@st.composite
def _edges_and_bins(draw):
    widths = draw(st.lists(st.one_of(st.just(0.0), st.floats(1e-3, 1e3)), min_size=1, max_size=9))
    low = draw(st.floats(-1e4, 1e4))
    edges = low + np.concatenate([[0.0], np.cumsum(widths)])
    bins = draw(st.lists(st.integers(0, len(widths) - 1), min_size=1, max_size=50))
    return edges, np.array(bins)


@settings(max_examples=200, deadline=None)
@given(_edges_and_bins(), st.integers(0, 2**32 - 1), st.booleans())
def test_dediscretized_values_are_inside_their_bins(edges_and_bins, seed, zero_bin):
    edges, bins = edges_and_bins
    values = dediscretize(bins, edges, np.random.default_rng(seed), zero_bin=zero_bin)
    low, high = edges[bins], edges[bins + 1]
    assert values.shape == bins.shape
    assert np.all((values >= low) & (values <= high))
    straddles = (low < 0) & (high > 0)
    assert np.all(values[straddles] == 0) if zero_bin else np.all(values[low == high] == low[low == high])


def test_dediscretize_gives_discrete_codes_and_rejects_bins_out_of_range():
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(dediscretize([0, 4], None, rng), [1.0, 5.0])
    values = dediscretize(np.full(2000, 6), np.array([-2000, -1250, -750, -250, 250, 750, 1250, 2000.0]), rng)
    assert values.min() >= 1250 and values.max() <= 2000 and values.std() > 100  # the outer bin, uniform
    with pytest.raises(TrafficModelError, match="bins outside"):
        dediscretize([5], np.arange(6.0), rng)


# ---------------------------------------------------------------------------- tracks


def test_integration_is_forward_euler_from_the_previous_point():
    rates = np.tile([1.0, 600.0, 90.0], (5, 1))  # +1 kt/s, +600 ft/min, +90 deg/s
    speed_kt, heading_deg, altitude_ft, pos, vel = integrate(20.0, 1000.0, 0.0, rates, 1.0)
    np.testing.assert_allclose(speed_kt, [20, 21, 22, 23, 24])
    np.testing.assert_allclose(heading_deg, [0, 90, 180, 270, 360])
    np.testing.assert_allclose(altitude_ft, [1000, 1010, 1020, 1030, 1040])
    # north: 20 cos 0 + 21 cos 90 + 22 cos 180 + 23 cos 270 = -2 kt s; east: 21 - 23 = -2 kt s
    np.testing.assert_allclose(pos[-1], [-2 * KT_TO_M_S, -2 * KT_TO_M_S, 40 * FT_TO_M], atol=1e-9)
    np.testing.assert_allclose(vel[:, 2], 600 * FT_TO_M / 60)


@pytest.mark.parametrize("dt_s", [1.0, 0.5])
def test_tracks_stay_in_the_models_bounds_and_integrate_consistently(model, dt_s):
    rng = np.random.default_rng(13)
    speed_edges, altitude_edges = model.boundaries[3], model.boundaries[2]
    for _ in range(25):
        track = sample_track(model, rng, duration_s=60.0, dt_s=dt_s)
        k = int(60 / dt_s) + 1
        assert track.t_s.shape == (k,) and track.pos_neu_m.shape == track.vel_neu_m_s.shape == (k, 3)
        np.testing.assert_allclose(np.diff(track.t_s), dt_s)
        assert np.all((track.speed_kt > speed_edges[0]) & (track.speed_kt < speed_edges[-1]))
        assert np.all((track.altitude_ft_agl >= altitude_edges[0]) & (track.altitude_ft_agl <= altitude_edges[-1]))
        low, high = altitude_edges[track.layer - 1], altitude_edges[track.layer]
        assert low <= track.altitude_ft_agl[0] <= high
        assert 1 <= track.domain <= 5 and 1 <= track.airspace <= 4 and track.attempts >= 1
        np.testing.assert_allclose(track.pos_neu_m[0], 0.0)
        np.testing.assert_allclose(np.diff(track.pos_neu_m, axis=0), track.vel_neu_m_s[:-1] * dt_s, atol=1e-9)
        np.testing.assert_allclose(np.hypot(*track.vel_neu_m_s[:, :2].T), track.speed_kt * KT_TO_M_S)
        np.testing.assert_allclose(
            track.pos_neu_m[:, 2], (track.altitude_ft_agl - track.altitude_ft_agl[0]) * FT_TO_M, atol=1e-9
        )
        assert np.all((track.heading_deg >= 0) & (track.heading_deg < 360))
        assert np.all(np.abs(np.diff(track.speed_kt)) <= 2.0 * dt_s + 1e-9)  # |v-dot| <= 2 kt/s
        assert np.all(np.abs(np.diff(track.altitude_ft_agl)) <= 2000 / 60 * dt_s + 1e-9)  # |h-dot| <= 2000 ft/min
        turn = (np.diff(track.heading_deg) + 180) % 360 - 180
        assert np.all(np.abs(turn) <= 8.0 * dt_s + 1e-9)  # |psi-dot| <= 8 deg/s
        heading = np.degrees(np.arctan2(track.vel_neu_m_s[:, 1], track.vel_neu_m_s[:, 0])) % 360
        np.testing.assert_allclose(np.cos(np.radians(heading - track.heading_deg)), 1.0, atol=1e-9)


def test_a_track_is_determined_by_its_seed_and_takes_its_initial_heading(model):
    first = sample_track(model, np.random.default_rng(99), duration_s=120.0)
    again = sample_track(model, np.random.default_rng(99), duration_s=120.0)
    other = sample_track(model, np.random.default_rng(100), duration_s=120.0)
    for field in dataclasses.fields(first):
        np.testing.assert_array_equal(getattr(first, field.name), getattr(again, field.name))
    assert not np.array_equal(first.pos_neu_m, other.pos_neu_m)
    assert sample_track(model, np.random.default_rng(1), heading0_deg=270.0).heading_deg[0] == 270.0


def test_a_track_the_bounds_cannot_hold_gives_up_naming_the_model(model):
    backwards = list(model.boundaries)
    backwards[3] = -model.boundaries[3][::-1]  # every speed negative: never inside
    impossible = dataclasses.replace(model, boundaries=tuple(backwards))
    with pytest.raises(TrafficModelError, match=f"{model.name}.*in 5 samples"):
        sample_track(impossible, np.random.default_rng(0), max_attempts=5)
    with pytest.raises(TrafficModelError, match="dt_s"):
        sample_track(model, np.random.default_rng(0), dt_s=0.3)


# ---------------------------------------------------------------------------- broken files


@pytest.fixture(scope="module")
def good_lines() -> list[str]:
    return (DIRECTORY / MODEL_FILES["rotorcraft"]).read_text().splitlines()


def _write(tmp_path: Path, lines: list[str]) -> Path:
    path = tmp_path / "bad_model.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def _replace(lines: list[str], section: str, offset: int, text: str) -> list[str]:
    out = list(lines)
    out[out.index(f"# {section}") + 1 + offset] = text
    return out


def test_a_truncated_file_names_the_missing_sections(tmp_path, good_lines):
    cut = good_lines[: good_lines.index("# N_transition") + 1]
    with pytest.raises(
        TrafficModelError, match="bad_model.txt.*missing or empty section.*N_transition, boundaries, resample_rates"
    ):
        read_model(_write(tmp_path, cut))


def test_a_file_cut_inside_the_counts_names_the_section_and_the_counts(tmp_path, good_lines):
    line = good_lines[good_lines.index("# N_initial") + 1]
    short = _replace(good_lines, "N_initial", 0, line[: len(line) // 2].rsplit(" ", 1)[0])
    with pytest.raises(TrafficModelError, match=r"section 'N_initial': \d+ numbers, expected 183145"):
        read_model(_write(tmp_path, short))


def test_a_non_numeric_token_names_the_section_its_line_and_the_token(tmp_path, good_lines):
    tokens = good_lines[good_lines.index("# N_transition") + 1].split()
    tokens[41] = "12x4"
    bad = _replace(good_lines, "N_transition", 0, " ".join(tokens))
    line_no = good_lines.index("# N_transition") + 2
    with pytest.raises(TrafficModelError, match=f"section 'N_transition', line {line_no}: token 42 '12x4'"):
        read_model(_write(tmp_path, bad))


def test_a_wrong_count_of_numbers_names_the_section(tmp_path, good_lines):
    longer = _replace(good_lines, "N_transition", 0, good_lines[good_lines.index("# N_transition") + 1] + " 7")
    with pytest.raises(TrafficModelError, match="section 'N_transition': 74481 numbers, expected 74480"):
        read_model(_write(tmp_path, longer))


@pytest.mark.parametrize(
    "section, offset, text, message",
    [
        (
            "G_initial",
            6,
            "1 0 0 0 0 0 0",
            r"'G_initial': is not a DAG: a cycle among variables \[0, 1, 2, 3, 4, 5, 6\]",
        ),
        ("G_initial", 2, "0 0 0 1 1 1", r"'G_initial', line 6: is not square: 6 entries in a row, expected 7"),
        ("r_initial", 0, "5 4 4 8 5 7", r"'r_initial', line 12: 6 entries, expected 7"),
        ("G_transition", 0, "0 0 0 0 0 0 0 0 0 2", r"'G_transition', line 18: entries must be 0 or 1"),
        ("boundaries", 3, "0 30 60 90 120 140 165 250", r"'boundaries', line 36: variable 'v': 8 edges, expected 9"),
        ("resample_rates", 0, "0 0 0.01 0.01 0.05 0.04", r"'resample_rates', line 41: 6 entries, expected 7"),
    ],
)
def test_structural_errors_name_the_section_and_what_is_wrong(tmp_path, good_lines, section, offset, text, message):
    with pytest.raises(TrafficModelError, match=message):
        read_model(_write(tmp_path, _replace(good_lines, section, offset, text)))


def test_unknown_sections_and_missing_files_are_named(tmp_path, good_lines):
    with pytest.raises(TrafficModelError, match="section 'N_extra', line 13: unknown section"):
        read_model(_write(tmp_path, _replace(good_lines, "r_initial", 1, "# N_extra")))
    with pytest.raises(TrafficModelError, match=f"{tmp_path}.*{MODEL_FILES['fixedwing']} not found"):
        load_model("fixedwing", directory=tmp_path)
    with pytest.raises(TrafficModelError, match="unknown encounter model kind 'glider'"):
        load_model("glider")


def test_the_models_directory_comes_from_the_argument_then_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    assert models_directory() == tmp_path.resolve()
    assert models_directory(tmp_path / "x") == (tmp_path / "x").resolve()
    monkeypatch.delenv(MODELS_ENV)
    assert (
        models_directory()
        == (Path(__file__).resolve().parents[3] / "companion" / "data" / "encounter_models").resolve()
    )
    assert os.environ.get(MODELS_ENV) is None
