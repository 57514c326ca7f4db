"""``sim-vehicle --home`` and ``--origin`` with southern latitudes and western longitudes (issue 25)."""

from __future__ import annotations

import pytest

from sim_vehicle.cli import build_parser

CANBERRA = (-35.363261, 149.16523, 584.0, 353.0)


@pytest.mark.parametrize(
    "argv",
    [
        ["--home", "-35.363261,149.165230,584,353"],
        ["--home=-35.363261,149.165230,584,353"],
        ["--speedup", "2", "--home", "-35.363261,149.165230,584,353", "-q"],
    ],
)
def test_a_southern_home_parses_in_both_forms(argv):
    assert build_parser().parse_args(argv).home == pytest.approx(CANBERRA)


def test_a_southern_origin_and_a_western_home():
    args = build_parser().parse_args(["--origin", "-33.8688,151.2093,20", "--home", "-.5,-70.25,10"])
    assert args.origin == pytest.approx((-33.8688, 151.2093, 20.0))
    assert args.home == pytest.approx((-0.5, -70.25, 10.0, 0.0))


def test_a_negative_wind_direction_is_a_value():
    assert build_parser().parse_args(["--wind-dir", "-90"]).wind_dir == -90.0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--home", "-95,0,10"], "latitude must be -90..90"),
        (["--home", "-33.8,151.2"], "expected LAT,LON,ALT"),
        (["--home", "-q"], "expected one argument"),  # an option is not taken for a value
    ],
)
def test_a_bad_home_is_one_line_and_exit_2(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--home" in err and message in err
