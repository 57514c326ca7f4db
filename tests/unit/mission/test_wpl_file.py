"""QGC WPL 110 reader/writer: round trip, MAVProxy compatibility and bad input."""

import math
from pathlib import Path

import pytest

from companion.errors import MissionError
from companion.mission import MissionItem, MissionPlan, load_mission_file, read_wpl_text, save_mission_file
from companion.mission.wpl_file import plan_to_wpl_text

REPO = Path(__file__).resolve().parents[3]
HOME = (47.397742, 8.545594, 488.0)

GOOD = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t20\t1
2\t0\t3\t16\t2\t1.5\t0\t0\t47.3980\t8.5460\t20\t1
3\t0\t2\t178\t1\t3\t-1\t0\t0\t0\t0\t1
4\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1
"""


def test_reads_home_and_items():
    plan = read_wpl_text(GOOD, "t.waypoints")
    assert plan.planned_home == HOME
    assert [i.command for i in plan.items] == [22, 16, 178, 21]
    assert plan.items[1].hold_s == 2.0 and plan.items[1].acceptance_radius_m == 1.5
    assert plan.items[2].speed_m_s == 3.0


def test_round_trip(tmp_path):
    plan = read_wpl_text(GOOD)
    path = tmp_path / "m.waypoints"
    save_mission_file(plan, path)
    back = load_mission_file(path)
    assert back.items == plan.items and back.planned_home == plan.planned_home


def test_nan_params_survive(tmp_path):
    plan = MissionPlan(
        items=(MissionItem(22, 3, alt_m=10.0), MissionItem(16, 3, 0, 0, 0, math.nan, 47.39, 8.54, 10.0)),
        planned_home=HOME,
    )
    text = plan_to_wpl_text(plan)
    assert "\tnan\t" in text
    back = read_wpl_text(text)
    assert math.isnan(back.items[1].param4)


def test_mavproxy_reads_our_file(tmp_path):
    mavwp = pytest.importorskip("pymavlink.mavwp")
    path = tmp_path / "m.waypoints"
    save_mission_file(read_wpl_text(GOOD), path)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == 5  # home + 4 items
    assert loader.wp(2).command == 16 and loader.wp(2).x == pytest.approx(47.398)


def test_sample_waypoints_file_loads():
    plan = load_mission_file(REPO / "mission_files" / "square.waypoints")
    assert plan.items[0].command == 22 and plan.items[-1].command == 21


def test_bad_header():
    with pytest.raises(MissionError, match=r"line 1: expected header 'QGC WPL 110'"):
        read_wpl_text("QGC WPL 100\n" + GOOD.split("\n", 1)[1], "t.waypoints")
    with pytest.raises(MissionError, match="line 1"):
        read_wpl_text("", "t.waypoints")


def test_wrong_column_count_names_line():
    text = GOOD.replace(
        "2\t0\t3\t16\t2\t1.5\t0\t0\t47.3980\t8.5460\t20\t1", "2\t0\t3\t16\t2\t1.5\t0\t47.3980\t8.5460\t20\t1"
    )
    with pytest.raises(MissionError, match=r"t.waypoints: line 4: 11 columns, expected 12"):
        read_wpl_text(text, "t.waypoints")


def test_not_a_number_names_line():
    text = GOOD.replace("47.3980", "north")
    with pytest.raises(MissionError, match="line 4: not a number"):
        read_wpl_text(text, "t.waypoints")


def test_latitude_out_of_range_names_line():
    text = GOOD.replace("47.3980", "97.3980")
    with pytest.raises(MissionError, match=r"line 4: latitude 97.398 deg is out of range"):
        read_wpl_text(text, "t.waypoints")


def test_unknown_command_names_item():
    text = GOOD.replace("3\t0\t2\t178", "3\t0\t2\t183")
    with pytest.raises(MissionError, match=r"item 3: unsupported command DO_SET_SERVO"):
        read_wpl_text(text, "t.waypoints")


def test_out_of_order_index():
    text = GOOD.replace("3\t0\t2\t178", "7\t0\t2\t178")
    with pytest.raises(MissionError, match="line 5: item index 7, expected 3"):
        read_wpl_text(text, "t.waypoints")


def test_empty_mission():
    text = "\n".join(GOOD.splitlines()[:2]) + "\n"
    with pytest.raises(MissionError, match="empty"):
        read_wpl_text(text, "t.waypoints")


def test_json_in_a_waypoints_file_is_read_as_plan(tmp_path):
    path = tmp_path / "m.waypoints"
    path.write_text('{"fileType": "Plan", "mission": {"items": []}}')
    with pytest.raises(MissionError, match="empty"):
        load_mission_file(path)
