"""docs/SETTINGS.md is generated from the settings dataclasses and cannot drift; --print-config
prints TOML that --config reads back to the same settings (issue 14, item 5)."""

import dataclasses
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

from companion.cli import main
from companion.config import Settings, load_settings, settings_from_dict, settings_to_toml
from companion.settings_doc import field_descriptions, reference_markdown, setting_docs, unit_of
from sim_vehicle.config import VehicleSettings

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

from settings_doc import SETTINGS_TREES  # noqa: E402


def test_the_checked_in_reference_is_what_the_code_generates():
    current = (ROOT / "docs" / "SETTINGS.md").read_text(encoding="utf-8")
    assert current == reference_markdown(SETTINGS_TREES), "docs/SETTINGS.md is stale: run tools/settings_doc.py"


@pytest.mark.parametrize("tree", [Settings, VehicleSettings])
def test_every_key_has_a_type_a_default_and_a_meaning(tree):
    docs = list(setting_docs(tree))
    assert len(docs) > 50
    assert [d.key for d in docs if not d.meaning] == []
    assert all(d.type and d.default for d in docs)
    assert len({d.key for d in docs}) == len(docs)


def test_grouped_and_wrapped_numpydoc_entries_are_read():
    @dataclass
    class Example:
        """Example.

        Parameters
        ----------
        a_m, b_s,
        c_hz : float
            Shared text,
            on two lines.
        d : int
            Own text.

        Raises
        ------
        ValueError
            Not a field.
        """

        a_m: float = 1.0
        b_s: float = 2.0
        c_hz: float = 3.0
        d: int = 4

    text = field_descriptions(Example)
    assert text == {
        "a_m": "Shared text, on two lines.",
        "b_s": "Shared text, on two lines.",
        "c_hz": "Shared text, on two lines.",
        "d": "Own text.",
    }


@pytest.mark.parametrize(
    "name, unit",
    [
        ("speed_m_s", "m/s"),
        ("accel_m_s2", "m/s²"),
        ("dt_s", "s"),
        ("radius_m", "m"),
        ("rate_hz", "Hz"),
        ("kappa_max_1_m", "1/m"),
        ("turn_rate_rad_s", "rad/s"),
        ("mode", ""),
        ("retime_rates", ""),
    ],
)
def test_units_come_from_the_name(name, unit):
    assert unit_of(name) == unit


def test_printed_toml_reads_back_to_the_same_settings(tmp_path):
    changed = settings_from_dict(
        {
            "seed": 7,
            "link": {"connect": "udpin://0.0.0.0:14541", "signing_key_file": 'a "quoted" path'},
            "planning": {"kappa_max_1_m": 0.2},  # None by default: written when set
            "threats": {"retime_waits_s": [0.0, 2.0]},
            "zenoh": {"listen": [], "connect": ["tcp/10.0.0.1:7447"]},
        }
    )
    for settings in (Settings(), changed):
        text = settings_to_toml(settings)
        assert settings_from_dict(tomllib.loads(text)) == settings
        path = tmp_path / "settings.toml"
        path.write_text(text)
        assert load_settings(path) == settings
    assert "# kappa_max_1_m = (unset)" in settings_to_toml(Settings())
    assert dataclasses.asdict(changed)["planning"]["kappa_max_1_m"] == 0.2


def test_print_config_prints_toml_by_default_and_json_on_request(capsys):
    assert main(["run", "--print-config"]) == 0
    assert settings_from_dict(tomllib.loads(capsys.readouterr().out)) == Settings()
    assert main(["run", "--print-config", "json"]) == 0
    assert capsys.readouterr().out.lstrip().startswith("{")


def test_a_setting_added_without_documentation_is_caught():
    @dataclass(frozen=True)
    class Grown:
        """A settings table that grew a key.

        Parameters
        ----------
        rate_hz : float
            Documented.
        """

        rate_hz: float = 1.0
        new_key_m: float = 2.0

    undocumented = [d.key for d in setting_docs(Grown) if not d.meaning]
    assert undocumented == ["new_key_m"]
