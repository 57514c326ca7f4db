"""Parameter table (ArduPilot names and units over the settings tree) and the settings loader."""

from __future__ import annotations

import math

import numpy as np
import pytest

from heli_model.model import HeliModel
from sim_vehicle.autopilot import Autopilot
from sim_vehicle.config import (
    SimConfigError,
    VehicleSettings,
    get_path,
    load_settings,
    parse_host_port,
    replace_path,
    settings_from_dict,
)
from sim_vehicle.params import MAV_PARAM_TYPE_INT8, MAV_PARAM_TYPE_REAL32, ParameterTable


def test_names_are_unique_mavlink_ids_and_values_match_settings():
    table = ParameterTable(VehicleSettings())
    names = [s.name for s in table.specs]
    assert len(set(names)) == len(names)
    assert all(0 < len(n) <= 16 and n == n.upper() for n in names)
    for spec in table.specs:
        value = table.value(spec)
        assert math.isfinite(value)
        assert spec.minimum <= value <= spec.maximum, spec.name
    assert table.value(table.lookup("WPNAV_SPEED")) == 500.0  # cm/s, ArduPilot units
    assert table.lookup("DISARM_DELAY").param_type == MAV_PARAM_TYPE_INT8
    assert table.lookup("SIM_SPEEDUP").param_type == MAV_PARAM_TYPE_REAL32
    assert table.lookup(index=0) is table.specs[0]
    assert table.lookup(index=len(table)) is None


def test_set_changes_the_settings_tree_in_setting_units():
    table = ParameterTable(VehicleSettings())
    assert table.set("WPNAV_SPEED", 800.0) == (True, "")
    assert table.settings.flight.wp_speed_m_s == pytest.approx(8.0)
    assert table.set("DISARM_DELAY", 4.6)[0]
    assert table.settings.flight.disarm_delay_s == 5.0
    assert table.set("SIM_WIND_SPD", 3.0)[0]
    assert table.settings.wind.enabled and table.settings.wind.speed_m_s == 3.0
    assert table.set("LQI_R_COL", 9.0)[0]
    assert table.settings.controller.r_weights[3] == 9.0


@pytest.mark.parametrize(
    "name, value",
    [
        ("WPNAV_SPEED", float("nan")),
        ("WPNAV_SPEED", float("inf")),
        ("WPNAV_SPEED", -5.0),
        ("WPNAV_SPEED", 1e9),
        ("SIM_SPEEDUP", 0.0),
        ("GUID_TIMEOUT", 1e6),
        ("LQI_QI_U", 0.0),
        ("SIM_WIND_SPD", 400.0),
    ],
)
def test_absurd_values_are_refused_and_nothing_changes(name, value, caplog):
    table = ParameterTable(VehicleSettings())
    before = table.settings
    spec = table.lookup(name)
    old_value = table.value(spec)
    ok, reason = table.set(name, value)
    assert not ok and name in reason
    assert table.settings is before
    assert table.value(spec) == old_value
    assert any("refused" in r.getMessage() for r in caplog.records)


def test_unknown_parameter_is_refused():
    table = ParameterTable(VehicleSettings())
    ok, reason = table.set("NO_SUCH_PARAM", 1.0)
    assert not ok and "unknown" in reason
    assert table.index("NO_SUCH_PARAM") == -1


def test_lqi_weight_change_redesigns_the_controller():
    model = HeliModel.default()
    vehicle = Autopilot(model, VehicleSettings(), (47.0, 8.0, 400.0, 0.0), np.random.default_rng(0))
    controller = vehicle.airframe.controller
    gains_before = controller.gains.K.copy() if hasattr(controller.gains, "K") else None
    table = ParameterTable(vehicle.settings)
    assert table.set("LQI_R_LON", 1.0)[0]
    vehicle.apply_settings(table.settings)
    assert vehicle.airframe.controller.settings.r_weights[1] == 1.0
    if gains_before is not None:
        assert not np.allclose(gains_before, vehicle.airframe.controller.gains.K)


def test_settings_errors_name_the_key(tmp_path):
    with pytest.raises(SimConfigError, match=r"flight\.wp_speed_m_s"):
        settings_from_dict({"flight": {"wp_speed_m_s": "fast"}})
    with pytest.raises(SimConfigError, match=r"timing\.bogus"):
        settings_from_dict({"timing": {"bogus": 1}})
    with pytest.raises(SimConfigError, match="control_rate_hz"):
        settings_from_dict({"timing": {"physics_rate_hz": 400.0, "control_rate_hz": 150.0}})
    with pytest.raises(SimConfigError, match="out"):
        settings_from_dict({"link": {"out": ["nonsense"]}})
    bad = tmp_path / "bad.toml"
    bad.write_text("[flight\n")
    with pytest.raises(SimConfigError, match="bad.toml"):
        load_settings(bad)
    good = tmp_path / "good.toml"
    good.write_text("[timing]\nspeedup = 5.0\n[wind]\nenabled = true\nspeed_m_s = 4.0\nfrom_deg = 270.0\n")
    loaded = load_settings(good)
    assert loaded.timing.speedup == 5.0
    north, east, _ = loaded.wind.steady_ned_m_s()
    assert north == pytest.approx(0.0, abs=1e-9) and east == pytest.approx(4.0)  # from the west, blowing east


def test_paths_and_addresses():
    tree = VehicleSettings()
    assert get_path(tree, "controller.r_weights#2") == tree.controller.r_weights[2]
    changed = replace_path(tree, "controller.r_weights#2", 3.0)
    assert changed.controller.r_weights[2] == 3.0
    assert tree.controller.r_weights[2] != 3.0  # trees are immutable
    assert parse_host_port("127.0.0.1:14550") == ("127.0.0.1", 14550)
    for bad in ("14550", "host:", "host:99999", ":1"):
        with pytest.raises(ValueError):
            parse_host_port(bad)
