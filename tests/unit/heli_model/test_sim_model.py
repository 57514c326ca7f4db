"""HeliModel: matrices from the reference parameters, open-loop eigenvalues, profile errors."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from heli_model.model import INPUT_NAMES, PARAM_NAMES, STATE_NAMES, HeliModel, ModelError

REFERENCE = Path("/work/shared/reference/heli_r50_hover.json")
DEFAULT_PROFILE = Path(__file__).resolve().parents[3] / "heli_model" / "profiles" / "default.toml"


def _reference() -> dict:
    if REFERENCE.exists():
        return json.loads(REFERENCE.read_text())
    pytest.skip("shared reference file not available")


def _expected_eigenvalues(ref: dict) -> list[complex]:
    out = []
    for text in ref["open_loop_eigenvalues_check"].values():
        m = re.match(r"\s*([+-]?[\d.]+)\s*(?:\+/-\s*([\d.]+)j)?", text)
        re_part, im_part = float(m.group(1)), float(m.group(2) or 0.0)
        out.append(complex(re_part, im_part))
        if im_part:
            out.append(complex(re_part, -im_part))
    return out


def test_default_profile_carries_the_reference_parameters():
    ref = _reference()
    model = HeliModel.default()
    assert tuple(ref["state_order"]) == STATE_NAMES
    assert tuple(ref["input_order"]) == INPUT_NAMES
    assert set(ref["params_si"]) == set(PARAM_NAMES)
    for key, value in ref["params_si"].items():
        assert model.params[key] == pytest.approx(value, rel=1e-12), key
    assert model.gravity_m_s2 == ref["gravity_m_s2"]
    assert model.servo_tau_s == 0.0
    assert "Mettler" in model.source


def test_matrices_have_the_documented_shapes_and_read_only():
    model = HeliModel.default()
    assert model.A.shape == (13, 13) and model.B.shape == (13, 4)
    with pytest.raises(ValueError):
        model.A[0, 0] = 1.0


def test_flapping_and_stabiliser_rows_are_divided_by_their_time_constants():
    model = HeliModel.default()
    p = model.params
    ia, ib, ic, idd = (STATE_NAMES.index(k) for k in ("a", "b", "c", "d"))
    assert model.A[ia, ia] == pytest.approx(-1.0 / p["tau_f"])
    assert model.A[ia, ic] == pytest.approx(p["Ac"] / p["tau_f"])
    assert model.B[ib, 0] == pytest.approx(p["Blat"] / p["tau_f"])
    assert model.A[ic, ic] == pytest.approx(-1.0 / p["tau_s"])
    assert model.B[idd, 0] == pytest.approx(p["Dlat"] / p["tau_s"])
    # the rate terms keep their unit coefficient: tau * da/dt = -tau q ...
    assert model.A[ia, STATE_NAMES.index("q")] == -1.0


def test_open_loop_eigenvalues_match_the_reference():
    expected = _expected_eigenvalues(_reference())
    got = list(HeliModel.default().eigenvalues())
    assert len(expected) == len(got) == 13
    for ev in expected:
        nearest = min(got, key=lambda g: abs(g - ev))
        assert abs(nearest - ev) < 0.02, (ev, nearest)
        got.remove(nearest)
    # the hover phugoid is unstable: the model needs its controller
    assert max(e.real for e in HeliModel.default().eigenvalues()) == pytest.approx(0.306, abs=0.01)


def _profile_text(**overrides) -> str:
    lines = ['name = "test"', "gravity_m_s2 = 9.81", "servo_tau_s = 0.0", "[params]"]
    params = dict(HeliModel.default().params)
    for k, v in overrides.items():
        params[k] = v
    for k, v in params.items():
        if v is not None:
            lines.append(f"{k} = {v}")
    return "\n".join(lines) + "\n"


def test_user_profile_round_trip(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(_profile_text(Xu=-0.07))
    model = HeliModel.from_toml(path)
    assert model.params["Xu"] == -0.07
    assert model.A[0, 0] == -0.07
    assert model.name == "test"


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ({"Xu": "nan"}, "params.Xu"),
        ({"tau_f": "0.0"}, "params.tau_f"),
        ({"tau_s": "-0.3"}, "params.tau_s"),
        ({"Lb": '"big"'}, "params.Lb"),
        ({"Nv": None}, "params.Nv"),
        ({"Qx": "1.0"}, "params.Qx"),
    ],
)
def test_bad_parameters_are_rejected_naming_the_key(tmp_path, override, key):
    path = tmp_path / "bad.toml"
    path.write_text(_profile_text(**override))
    with pytest.raises(ModelError) as info:
        HeliModel.from_toml(path)
    assert key in str(info.value)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("top", "key"),
    [("servo_tau_s = -0.1", "servo_tau_s"), ("gravity_m_s2 = 0.0", "gravity_m_s2"), ("colour = 1", "colour")],
)
def test_bad_profile_options_are_rejected_naming_the_key(tmp_path, top, key):
    text = _profile_text()
    text = "\n".join(line for line in text.splitlines() if not line.startswith(top.split(" ")[0] + " "))
    path = tmp_path / "bad.toml"
    path.write_text(top + "\n" + text + "\n")
    with pytest.raises(ModelError, match=key):
        HeliModel.from_toml(path)


def test_bad_wind_table_is_rejected_naming_the_key(tmp_path):
    path = tmp_path / "wind.toml"
    path.write_text(_profile_text() + "[wind]\ngust_tau_s = 0.0\n")
    with pytest.raises(ModelError, match="wind.*gust_tau_s"):
        HeliModel.from_toml(path)


def test_wind_defaults_come_from_the_profile(tmp_path):
    path = tmp_path / "wind.toml"
    path.write_text(_profile_text() + "[wind]\nsteady_ned_m_s = [3.0, -1.0, 0.0]\ngust_std_m_s = 0.5\n")
    model = HeliModel.from_toml(path)
    assert model.wind.steady_ned_m_s == (3.0, -1.0, 0.0)
    assert model.wind.gust_std_m_s == 0.5


def test_missing_file_and_syntax_errors_are_model_errors(tmp_path):
    with pytest.raises(ModelError, match="no such file"):
        HeliModel.from_toml(tmp_path / "absent.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("[params\nXu = 1\n")
    with pytest.raises(ModelError, match="broken.toml"):
        HeliModel.from_toml(broken)


def test_replace_changes_one_parameter_and_validates():
    model = HeliModel.default()
    lag = model.replace(servo_tau_s=0.05, Xu=-0.1)
    assert lag.servo_tau_s == 0.05 and lag.params["Xu"] == -0.1
    assert model.params["Xu"] != -0.1
    with pytest.raises(ModelError, match="tau_f"):
        model.replace(tau_f=float("nan"))
    with pytest.raises(ModelError, match="nonsense"):
        model.replace(nonsense=1.0)


def test_default_profile_file_is_shipped_and_documented():
    text = DEFAULT_PROFILE.read_text()
    assert "CMU-RI-TR-00-03" in text
    assert math.isclose(HeliModel.from_toml(DEFAULT_PROFILE).params["Lb"], 166.1)
    assert np.allclose(HeliModel.from_toml(DEFAULT_PROFILE).A, HeliModel.default().A)
