"""A campaign's spec (``companion.campaign.spec``): reading good and bad TOML files, the TOML it
writes back, and its hash."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from companion.campaign.judge import Volumes
from companion.campaign.spec import (
    CampaignSpec,
    MannedSpec,
    RobustnessSpec,
    SpecError,
    load_spec,
    spec_hash,
    spec_to_toml,
)
from companion.campaign.strata import stratum_names
from companion.flight.fast_time import JobLatency

GOOD = """\
name = "quick"
seed = 7
max_pairs = 2000
min_pairs = 500
batch_pairs = 10
tolerance = 0.02
check_every = 250
strata = ["crossing/open", "manned/rotorcraft"]
settings = "companion.toml"
iterations_per_s = 1500.0

[latency]
decision_s = 0.1

[volumes]
nmac_extra_m = 2.0
lowc_extra_m = 5.0

[manned]
hmd_max_m = 1200.0
near_share = 0.3

[robustness]
dropout = [0.2, 0.5]
update_hz = [1, 3]
"""


def write(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_good_spec(tmp_path):
    spec = load_spec(write(tmp_path, GOOD))
    assert spec.name == "quick" and spec.seed == 7
    assert (spec.max_pairs, spec.min_pairs, spec.batch_pairs, spec.check_every) == (2000, 500, 10, 250)
    assert spec.tolerance == 0.02 and spec.iterations_per_s == 1500.0
    assert spec.strata == ("crossing/open", "manned/rotorcraft") and spec.stratum_list == spec.strata
    assert spec.settings == "companion.toml"
    assert spec.latency == JobLatency(decision_s=0.1)
    assert spec.volumes == Volumes(nmac_extra_m=2.0, lowc_extra_m=5.0)
    assert spec.manned == MannedSpec(hmd_max_m=1200.0, near_share=0.3)
    assert spec.robustness == RobustnessSpec(dropout=(0.2, 0.5), update_hz=(1.0, 3.0))
    assert isinstance(spec.robustness.update_hz[0], float)


def test_empty_spec_is_the_defaults(tmp_path):
    spec = load_spec(write(tmp_path, ""))
    assert spec == CampaignSpec()
    assert spec.stratum_list == stratum_names()


BAD = [
    ("bogus = 1\n", "bogus"),
    ("[volumes]\nbogus_m = 1.0\n", "volumes.bogus_m"),
    ("[manned]\nhmd_far_m = 1.0\n", "manned.hmd_far_m"),
    ('seed = "one"\n', "seed"),
    ("max_pairs = 1.5\n", "max_pairs"),
    ("tolerance = true\n", "tolerance"),
    ("name = 3\n", "name"),
    ('strata = "crossing/open"\n', "strata"),
    ("strata = [1]\n", "strata[0]"),
    ('strata = ["crossing/nowhere"]\n', "strata"),
    ("min_pairs = 600\nmax_pairs = 500\n", "min_pairs"),
    ("seed = -1\n", "seed"),
    ("batch_pairs = 0\n", "batch_pairs"),
    ("tolerance = 0.0\n", "tolerance"),
    ("iterations_per_s = -3.0\n", "iterations_per_s"),
    ("[robustness]\ndropout = [0.1, 1.0]\n", "robustness.dropout"),
    ("[robustness]\nnoise_pos_m = [2.0, 1.0]\n", "robustness.noise_pos_m"),
    ("[robustness]\nupdate_hz = [0.0, 1.0]\n", "robustness.update_hz"),
    ("[robustness]\nlatency_s = [-0.1, 0.5]\n", "robustness.latency_s"),
    ("[robustness]\nlatency_s = [0.1]\n", "robustness.latency_s"),
    ('[robustness]\nlatency_s = ["a", 0.5]\n', "robustness.latency_s[0]"),
    ("[volumes]\nnmac_extra_m = -1.0\n", "volumes.nmac_extra_m"),
    ("[volumes]\nnmac_h_ft = 3000.0\n", "volumes"),
    ("[manned]\nnear_share = 1.0\n", "near_share"),
    ("[manned]\nhmd_near_m = 2000.0\n", "hmd_near_m"),
    ("[manned]\nvmd_max_m = 0.0\n", "manned.vmd_max_m"),
    ("[latency]\ndecision_s = -0.1\n", "decision_s"),
    ("volumes = 3\n", "volumes"),
]


@pytest.mark.parametrize("text, key", BAD, ids=[k for _, k in BAD])
def test_bad_spec_names_the_file_and_the_key(tmp_path, text, key):
    path = write(tmp_path, text)
    with pytest.raises(SpecError) as info:
        load_spec(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    assert key in message, message


def test_bad_section_names_its_table(tmp_path):
    with pytest.raises(SpecError, match=r"latency"):
        load_spec(write(tmp_path, "[latency]\ndecision_s = -0.1\n"))


def test_unknown_stratum_lists_the_known(tmp_path):
    with pytest.raises(SpecError, match=r"strata: unknown stratum 'crossing/nowhere' \(known: .*crossing/open"):
        load_spec(write(tmp_path, 'strata = ["crossing/open", "crossing/nowhere"]\n'))


def test_toml_syntax_error_names_the_file(tmp_path):
    path = write(tmp_path, "seed = = 1\n")
    with pytest.raises(SpecError, match=rf"^{path}: .*line 1"):
        load_spec(path)


def test_missing_file_names_it(tmp_path):
    path = tmp_path / "absent.toml"
    with pytest.raises(SpecError, match=rf"^{path}: no such file"):
        load_spec(path)


def test_spec_error_is_a_value_error():
    assert issubclass(SpecError, ValueError)
    with pytest.raises(SpecError, match="min_pairs"):
        CampaignSpec(min_pairs=10, max_pairs=5)


# ---------------------------------------------------------------------------------------------
# spec_to_toml and spec_hash
# ---------------------------------------------------------------------------------------------

NON_DEFAULT = CampaignSpec(
    name='odd "name" \\ here',
    seed=3,
    max_pairs=50,
    min_pairs=5,
    batch_pairs=3,
    tolerance=0.125,
    check_every=7,
    strata=("head_on/fenced", "robust/noise"),
    settings="../cfg/companion.toml",
    iterations_per_s=1234.5,
    latency=JobLatency(0.01, 0.2, 0.3),
    volumes=Volumes(0.5, 1.5, 2.5, 400.0, 90.0, 1800.0, 200.0),
    manned=MannedSpec(hmd_max_m=1000.0, before_s=40.0),
    robustness=RobustnessSpec(dropout=(0.05, 0.3), update_hz=(0.5, 4.0)),
)


@pytest.mark.parametrize("spec", [CampaignSpec(), NON_DEFAULT], ids=["defaults", "non-default"])
def test_toml_round_trip(tmp_path, spec):
    back = load_spec(write(tmp_path, spec_to_toml(spec)))
    assert back == spec
    assert spec_hash(back) == spec_hash(spec)
    assert spec_to_toml(back) == spec_to_toml(spec)


floats_01 = st.floats(0.001, 0.9, allow_nan=False)


@st.composite
def specs(draw):
    names = stratum_names()
    strata = tuple(draw(st.lists(st.sampled_from(names), max_size=5, unique=True)))
    max_pairs = draw(st.integers(1, 10**6))
    lo_drop = draw(st.floats(0.0, 0.5))
    return CampaignSpec(
        name=draw(st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF), max_size=20)),
        seed=draw(st.integers(0, 2**40)),
        max_pairs=max_pairs,
        min_pairs=draw(st.integers(1, max_pairs)),
        batch_pairs=draw(st.integers(1, 100)),
        tolerance=draw(floats_01),
        check_every=draw(st.integers(1, 5000)),
        strata=strata,
        settings=draw(st.sampled_from(["", "a.toml", "dir/with space/ß.toml"])),
        iterations_per_s=draw(st.floats(1.0, 1e6)),
        latency=JobLatency(draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0))),
        volumes=Volumes(nmac_extra_m=draw(st.floats(0.0, 2.0)), lowc_extra_m=draw(st.floats(2.0, 9.0))),
        manned=MannedSpec(hmd_max_m=draw(st.floats(300.0, 5000.0)), near_share=draw(st.floats(0.0, 0.99))),
        robustness=RobustnessSpec(dropout=(lo_drop, draw(st.floats(lo_drop, 0.99)))),
    )


@given(specs())
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_toml_round_trip_property(tmp_path, spec):
    back = load_spec(write(tmp_path, spec_to_toml(spec), "round.toml"))
    assert back == spec
    assert spec_hash(back) == spec_hash(spec)


def test_hash_of_an_int_valued_float_field_survives_the_round_trip(tmp_path):
    spec = CampaignSpec(tolerance=1, volumes=Volumes(nmac_h_ft=500))
    back = load_spec(write(tmp_path, spec_to_toml(spec)))
    assert back == spec
    assert spec_hash(back) == spec_hash(spec)


def _changed_specs():
    """One spec per field (top level and nested) with that field changed."""
    base = CampaignSpec()
    out = {
        "name": dataclasses.replace(base, name="other"),
        "seed": dataclasses.replace(base, seed=2),
        "max_pairs": dataclasses.replace(base, max_pairs=99_999),
        "min_pairs": dataclasses.replace(base, min_pairs=1_999),
        "batch_pairs": dataclasses.replace(base, batch_pairs=21),
        "tolerance": dataclasses.replace(base, tolerance=0.051),
        "check_every": dataclasses.replace(base, check_every=999),
        "strata": dataclasses.replace(base, strata=("crossing/open",)),
        "settings": dataclasses.replace(base, settings="x.toml"),
        "iterations_per_s": dataclasses.replace(base, iterations_per_s=3001.0),
    }
    for name, cls in (
        ("latency", JobLatency),
        ("volumes", Volumes),
        ("manned", MannedSpec),
        ("robustness", RobustnessSpec),
    ):
        nested = getattr(base, name)
        for f in dataclasses.fields(cls):
            value = getattr(nested, f.name)
            if isinstance(value, tuple):
                new = (value[0], value[1] * 0.99 + 0.001 * (value[1] == value[0]))
            elif f.name in ("collision_extra_m",):
                new = 0.5
            elif f.name in ("nmac_h_ft", "nmac_v_ft", "near_share"):
                new = value * 0.9
            else:
                new = value * 1.1 + 0.01
            out[f"{name}.{f.name}"] = dataclasses.replace(base, **{name: dataclasses.replace(nested, **{f.name: new})})
    return out


CHANGED = _changed_specs()


def test_every_field_is_covered_by_the_change_list():
    top = {f.name for f in dataclasses.fields(CampaignSpec)}
    nested = {
        f"{n}.{f.name}"
        for n in ("latency", "volumes", "manned", "robustness")
        for f in dataclasses.fields(type(getattr(CampaignSpec(), n)))
    }
    assert set(CHANGED) == (top - {"latency", "volumes", "manned", "robustness"}) | nested


@pytest.mark.parametrize("field", sorted(CHANGED))
def test_hash_changes_when_a_value_changes(field):
    changed = CHANGED[field]
    assert changed != CampaignSpec()
    assert spec_hash(changed) != spec_hash(CampaignSpec())


def test_hash_is_stable_and_covers_the_settings_text():
    h = spec_hash(CampaignSpec())
    assert h == spec_hash(CampaignSpec()) and len(h) == 16 and int(h, 16) >= 0
    assert spec_hash(CampaignSpec(), "[flight]\n") != h
    assert spec_hash(CampaignSpec(), "[flight]\n") == spec_hash(CampaignSpec(), "[flight]\n")
