"""QGroundControl .plan reader/writer: round trips, sample files and every bad input."""

import copy
import json
import math
from pathlib import Path

import pytest

from companion.errors import MissionError
from companion.mission import (
    FenceCircle,
    FencePolygon,
    MissionItem,
    MissionPlan,
    RallyPoint,
    load_mission_file,
    read_plan_text,
    save_mission_file,
)
from companion.mission.plan_file import plan_to_document

REPO = Path(__file__).resolve().parents[3]
HOME = (47.397742, 8.545594, 488.0)


def sample_plan() -> MissionPlan:
    return MissionPlan(
        items=(
            MissionItem(22, 3, alt_m=15.0),
            MissionItem(16, 3, 2.0, 1.5, 0.0, math.nan, 47.3981, 8.5459, 20.0),
            MissionItem(178, 2, 1.0, 4.0, -1.0, 0.0),
            MissionItem(16, 0, 0.0, 0.0, 0.0, math.nan, 47.3983, 8.5452, 510.0),
            MissionItem(20, 2),
        ),
        polygons=(
            FencePolygon(((47.3970, 8.5440), (47.3990, 8.5440), (47.3990, 8.5470), (47.3970, 8.5470)), True),
            FencePolygon(((47.3979, 8.5456), (47.3980, 8.5456), (47.3980, 8.5458)), False),
        ),
        circles=(FenceCircle(47.3985, 8.5460, 7.5, False),),
        rally=(RallyPoint(47.3976, 8.5450, 20.0),),
        planned_home=HOME,
        cruise_speed_m_s=8.0,
        hover_speed_m_s=5.0,
    )


def same_items(a, b) -> bool:
    def key(item):
        return tuple(
            "nan" if isinstance(v, float) and math.isnan(v) else v
            for v in (
                item.command,
                item.frame,
                item.param1,
                item.param2,
                item.param3,
                item.param4,
                item.lat_deg,
                item.lon_deg,
                item.alt_m,
                item.autocontinue,
            )
        )

    return [key(i) for i in a] == [key(i) for i in b]


def test_round_trip_preserves_everything(tmp_path):
    plan = sample_plan()
    path = tmp_path / "m.plan"
    save_mission_file(plan, path)
    back = load_mission_file(path)
    assert same_items(back.items, plan.items)
    assert back.polygons == plan.polygons
    assert back.circles == plan.circles
    assert back.rally == plan.rally
    assert back.planned_home == plan.planned_home
    assert back.cruise_speed_m_s == 8.0 and back.hover_speed_m_s == 5.0


def test_written_file_has_qgc_structure(tmp_path):
    doc = plan_to_document(sample_plan())
    assert doc["fileType"] == "Plan"
    assert doc["mission"]["version"] == 2 and doc["geoFence"]["version"] == 2
    first = doc["mission"]["items"][0]
    assert first["type"] == "SimpleItem" and len(first["params"]) == 7
    assert doc["mission"]["items"][1]["params"][3] is None  # NaN -> null
    assert doc["geoFence"]["circles"][0]["circle"]["radius"] == 7.5
    json.dumps(doc, allow_nan=False)  # valid strict JSON


@pytest.mark.parametrize("name", ["exclusion_zones.plan", "paper_cluttered_100m.plan"])
def test_sample_missions_load(name):
    plan = load_mission_file(REPO / "mission_files" / name)
    assert plan.items and plan.planned_home is not None
    assert plan.exclusion_circles or plan.exclusion_polygons


def test_exclusion_sample_has_polygons_circle_and_rally():
    plan = load_mission_file(REPO / "mission_files" / "exclusion_zones.plan")
    assert len(plan.exclusion_polygons) >= 2 and len(plan.exclusion_circles) >= 1
    assert len(plan.inclusion_polygons) == 1 and len(plan.rally) >= 2


def base_doc() -> dict:
    return plan_to_document(sample_plan())


def read(doc) -> MissionPlan:
    return read_plan_text(json.dumps(doc), "test.plan")


def test_broken_json_names_line_and_column():
    text = json.dumps(base_doc(), indent=2)
    broken = text.replace('"fileType": "Plan",', '"fileType": "Plan"', 1)
    with pytest.raises(MissionError, match=r"test\.plan: broken JSON at line \d+ column \d+"):
        read_plan_text(broken, "test.plan")


def test_not_a_plan_file():
    with pytest.raises(MissionError, match="fileType"):
        read({"fileType": "Mission"})
    with pytest.raises(MissionError, match="top level"):
        read_plan_text("[1, 2]", "test.plan")


@pytest.mark.parametrize(
    "path, message",
    [
        (("mission",), "missing field mission"),
        (("mission", "items"), "missing field mission.items"),
        (("mission", "items", 1, "command"), r"missing field mission.items\[1\] \(item 2\).command"),
        (("mission", "items", 0, "params"), r"missing field mission.items\[0\] \(item 1\).params"),
        (("mission", "items", 2, "frame"), r"mission.items\[2\] \(item 3\).frame"),
        (("geoFence", "circles", 0, "circle", "radius"), r"geoFence.circles\[0\].circle.radius"),
    ],
)
def test_missing_fields_are_named(path, message):
    doc = base_doc()
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    del parent[path[-1]]
    with pytest.raises(MissionError, match=message):
        read(doc)


def test_wrong_param_count():
    doc = base_doc()
    doc["mission"]["items"][1]["params"] = [0, 0, 0]
    with pytest.raises(MissionError, match=r"item 2\).params has 3 entries"):
        read(doc)


def test_unknown_command_names_item_and_command():
    doc = base_doc()
    doc["mission"]["items"][3]["command"] = 31000
    with pytest.raises(MissionError, match=r"item 4: unsupported command .*31000"):
        read(doc)
    doc["mission"]["items"][3]["command"] = 183  # DO_SET_SERVO: known to MAVLink, unsupported
    with pytest.raises(MissionError, match=r"item 4: unsupported command DO_SET_SERVO \(183\)"):
        read(doc)


def test_complex_item_is_rejected_clearly():
    doc = base_doc()
    doc["mission"]["items"].insert(1, {"type": "ComplexItem", "complexItemType": "survey"})
    with pytest.raises(MissionError, match=r"item 2\) is a ComplexItem \(survey\): unsupported"):
        read(doc)


@pytest.mark.parametrize("lat", [91.0, -95.0, 1000.0])
def test_latitude_out_of_range(lat):
    doc = base_doc()
    doc["mission"]["items"][1]["params"][4] = lat
    with pytest.raises(MissionError, match=r"item 2 \(NAV_WAYPOINT\): latitude .* out of range"):
        read(doc)


def test_fence_and_rally_latitude_out_of_range():
    doc = base_doc()
    doc["geoFence"]["polygons"][1]["polygon"][2][0] = 99.0
    with pytest.raises(MissionError, match=r"geoFence.polygons\[1\].*vertex 2: latitude"):
        read(doc)
    doc = base_doc()
    doc["rallyPoints"]["points"][0][1] = 200.0
    with pytest.raises(MissionError, match=r"rallyPoints.points\[0\].*longitude"):
        read(doc)


def test_empty_mission():
    doc = base_doc()
    doc["mission"]["items"] = []
    with pytest.raises(MissionError, match="empty"):
        read(doc)


def test_wrong_types_are_named():
    doc = base_doc()
    doc["mission"]["items"][1]["params"][0] = "two"
    with pytest.raises(MissionError, match=r"params\[0\] must be a number"):
        read(doc)
    doc = base_doc()
    doc["mission"]["items"][1]["command"] = True
    with pytest.raises(MissionError, match="command must be an integer"):
        read(doc)


def test_unsupported_frame():
    doc = base_doc()
    doc["mission"]["items"][1]["frame"] = 1  # LOCAL_NED
    with pytest.raises(MissionError, match=r"item 2 \(NAV_WAYPOINT\): unsupported frame 1"):
        read(doc)


def test_fence_polygon_with_two_vertices():
    doc = base_doc()
    doc["geoFence"]["polygons"][1]["polygon"] = [[47.0, 8.0], [47.1, 8.0]]
    with pytest.raises(MissionError, match="2 vertices, needs at least 3"):
        read(doc)


def test_missing_file_and_bad_extension(tmp_path):
    with pytest.raises(MissionError, match="does not exist"):
        load_mission_file(tmp_path / "nope.plan")
    bad = tmp_path / "m.kml"
    bad.write_text("x")
    with pytest.raises(MissionError, match="unknown mission file extension"):
        load_mission_file(bad)


def test_reader_does_not_mutate_input():
    doc = base_doc()
    snapshot = copy.deepcopy(doc)
    read(doc)
    assert doc == snapshot
