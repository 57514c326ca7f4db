"""Map world files (GeoJSON, KML): every geometry kind and height rule becomes the obstacle it
should, about the home, and every mistake names the file, the feature and the property."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Polygon

from companion.cli import main
from companion.errors import WorldError
from companion.mission.convert import mission_to_local
from companion.mission.plan_file import read_plan_file
from companion.world import Cylinder, Prism, read_world_file
from heli_common.frames import LocalFrame

ROOT = Path(__file__).resolve().parents[3]
SITE = ROOT / "mission_files" / "sites" / "cmac"
HOME = (-35.363261, 149.165230, 584.0)
FRAME = LocalFrame(*HOME)


def lon_lat(points_ne_m) -> list[list[float]]:
    """North-east metres about HOME (at its level) -> GeoJSON positions."""
    pts = np.asarray(points_ne_m, dtype=float).reshape(-1, 2)
    lat, lon, _ = FRAME.to_lla(pts[:, 0], pts[:, 1], np.zeros(len(pts)))
    return [[float(x), float(y)] for x, y in zip(lon, lat)]


def ring(n0: float, e0: float, n1: float, e1: float) -> list[list[float]]:
    return lon_lat([(n0, e0), (n0, e1), (n1, e1), (n1, e0), (n0, e0)])


def polygon(*rings, **props) -> dict:
    return {"type": "Feature", "properties": props, "geometry": {"type": "Polygon", "coordinates": list(rings)}}


def collection(*features, **header) -> dict:
    return {
        "type": "FeatureCollection",
        "companion": {"home": [HOME[1], HOME[0], HOME[2]], **header},
        "features": list(features),
    }


def load(tmp_path, data, name="site.geojson", **kwargs):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return read_world_file(path, **kwargs)


HANGAR = ring(10, -5, 30, 15)


# ----------------------------------------------------------------------------- geometry kinds


def test_a_polygon_with_a_height_is_a_prism_from_the_ground_to_its_top(tmp_path):
    wf = load(tmp_path, collection(polygon(HANGAR, height=12)))
    (prism,) = wf.world.obstacles
    assert isinstance(prism, Prism)
    assert (
        Polygon(prism.vertices_ne_m).symmetric_difference(Polygon([(10, -5), (10, 15), (30, 15), (30, -5)])).area < 1e-4
    )
    assert prism.down_min_m == pytest.approx(-12.0, abs=1e-3)  # curvature: < 1 mm at 30 m
    assert prism.down_max_m == math.inf  # nothing flies under a building
    assert wf.home_lla == HOME and wf.world.dim == 3 and wf.name == "site"


@pytest.mark.parametrize(
    "props, top_m",
    [
        ({"building:levels": 4}, 12.0),
        ({"building:levels": "4"}, 12.0),  # OpenStreetMap exports tags as strings
        ({"height": "7.5 m", "building:levels": 4}, 7.5),  # height wins over levels
        ({"height": "9"}, 9.0),
    ],
)
def test_heights_come_from_height_or_levels_at_three_metres(tmp_path, props, top_m):
    (prism,) = load(tmp_path, collection(polygon(HANGAR, **props))).world.obstacles
    assert prism.down_min_m == pytest.approx(-top_m, abs=1e-3)


@pytest.mark.parametrize(
    "props, bottom_m", [({"min_height": 4, "height": 9}, 4.0), ({"building:min_level": 2, "building:levels": 5}, 6.0)]
)
def test_min_height_lifts_the_bottom(tmp_path, props, bottom_m):
    wf = load(tmp_path, collection(polygon(HANGAR, **props)))
    (prism,) = wf.world.obstacles
    assert prism.down_max_m == pytest.approx(-bottom_m, abs=1e-3)
    under = (20.0, 5.0, -(bottom_m / 2))
    assert wf.world.is_free([under])[0] and not wf.world.is_free([(20.0, 5.0, -(bottom_m + 1))])[0]


def test_a_multipolygon_gives_one_prism_per_part(tmp_path):
    feature = {
        "type": "Feature",
        "properties": {"height": 4},
        "geometry": {"type": "MultiPolygon", "coordinates": [[ring(0, 40, 8, 48)], [[*ring(20, 40, 26, 46)]]]},
    }
    obstacles = load(tmp_path, collection(feature)).world.obstacles
    assert len(obstacles) == 2 and all(isinstance(o, Prism) for o in obstacles)
    areas = sorted(Polygon(o.vertices_ne_m).area for o in obstacles)
    assert areas == pytest.approx([36.0, 64.0], rel=1e-5)


def test_a_polygon_with_a_hole_is_cut_into_simple_prisms_that_cover_it_exactly(tmp_path):
    outer, hole = ring(0, 0, 30, 30), ring(8, 8, 22, 22)
    wf = load(tmp_path, collection(polygon(outer, hole, height=9)))
    pieces = [Polygon(o.vertices_ne_m) for o in wf.world.obstacles]
    assert len(pieces) >= 2 and all(p.is_valid and not p.interiors for p in pieces)
    assert sum(p.area for p in pieces) == pytest.approx(30 * 30 - 14 * 14, rel=1e-6)
    free = wf.world.is_free([(15.0, 15.0, -5.0), (4.0, 15.0, -5.0), (26.0, 4.0, -5.0), (15.0, 15.0, -10.0)])
    assert free.tolist() == [True, False, False, True]  # the courtyard, walls, above the roof


def test_a_concave_polygon_stays_one_prism_with_its_notch_free(tmp_path):
    l_shape = lon_lat([(0, 0), (0, 30), (10, 30), (10, 10), (30, 10), (30, 0), (0, 0)])
    wf = load(tmp_path, collection(polygon(l_shape, height=10)))
    (prism,) = wf.world.obstacles
    assert len(prism.vertices_ne_m) == 6
    assert wf.world.is_free([(20.0, 20.0, -5.0)])[0] and not wf.world.is_free([(5.0, 20.0, -5.0)])[0]


def test_points_are_cylinders_with_their_radius_and_height(tmp_path):
    mast = {
        "type": "Feature",
        "properties": {"radius": 1.5, "height": 30},
        "geometry": {"type": "Point", "coordinates": lon_lat([(40, 20)])[0]},
    }
    trees = {
        "type": "Feature",
        "properties": {"radius": "2", "height": 8},
        "geometry": {"type": "MultiPoint", "coordinates": lon_lat([(0, 60), (5, 60)])},
    }
    obstacles = load(tmp_path, collection(mast, trees)).world.obstacles
    assert len(obstacles) == 3 and all(isinstance(o, Cylinder) for o in obstacles)
    assert obstacles[0].center_ne_m == pytest.approx((40.0, 20.0), abs=1e-6)
    assert obstacles[0].radius_m == 1.5 and obstacles[0].down_min_m == pytest.approx(-30.0, abs=1e-3)
    assert obstacles[2].radius_m == 2.0 and obstacles[2].down_max_m == math.inf


def test_a_line_is_a_wall_of_its_width(tmp_path):
    wall = {
        "type": "Feature",
        "properties": {"width": 0.5, "height": 3},
        "geometry": {"type": "LineString", "coordinates": lon_lat([(0, 0), (20, 0), (20, 10)])},
    }
    wf = load(tmp_path, collection(wall))
    (prism,) = wf.world.obstacles
    assert Polygon(prism.vertices_ne_m).area == pytest.approx(30 * 0.5, rel=1e-3)
    free = wf.world.is_free([(10.0, 0.2, -1.0), (10.0, 0.3, -1.0), (10.0, 0.0, -3.5)])
    assert free.tolist() == [False, True, True]


def test_a_wire_with_a_bottom_leaves_room_below(tmp_path):
    wire = {
        "type": "Feature",
        "properties": {"width": 0.3, "min_height": 8, "height": 9},
        "geometry": {"type": "MultiLineString", "coordinates": [lon_lat([(0, -10), (0, 10)])]},
    }
    wf = load(tmp_path, collection(wire))
    assert wf.world.is_free([(0.0, 0.0, -5.0), (0.0, 0.0, -9.5)]).all()
    assert not wf.world.is_free([(0.0, 0.0, -8.5)])[0]


# ----------------------------------------------------------------------------- the world


def test_default_bounds_are_the_extent_with_home_padding_and_margin(tmp_path):
    wf = load(tmp_path, collection(polygon(HANGAR, height=12), margin_m=2.0, padding_m=10.0, ceiling_m=50))
    assert wf.world.bounds_min == pytest.approx([-12.0, -17.0, -50.0], abs=1e-3)
    assert wf.world.bounds_max == pytest.approx([42.0, 27.0, 0.0], abs=1e-3)
    assert wf.world.margin_m == 2.0


def test_the_file_bounds_start_goal_and_default_height(tmp_path):
    (west, south), (east, north) = lon_lat([(-50, -60)])[0], lon_lat([(80, 70)])[0]
    start, goal = lon_lat([(0, 0)])[0] + [10.0], lon_lat([(50, 10)])[0] + [12.0]
    wf = load(
        tmp_path,
        collection(
            polygon(HANGAR), bounds=[west, south, east, north], default_height_m=6, start=start, goal=goal, name="yard"
        ),
    )
    assert wf.name == "yard" and wf.world.obstacles[0].down_min_m == pytest.approx(-6.0, abs=1e-3)
    assert wf.world.bounds_min[:2] == pytest.approx([-50.0, -60.0], abs=1e-3)
    assert wf.world.bounds_max[:2] == pytest.approx([80.0, 70.0], abs=1e-3)
    assert wf.start == pytest.approx((0.0, 0.0, -10.0), abs=1e-5)
    assert wf.goal == pytest.approx((50.0, 10.0, -12.0), abs=1e-3)


def test_the_home_argument_wins_and_the_ground_function_sets_the_base(tmp_path):
    data = collection(polygon(HANGAR, height=12))
    other = (HOME[0] + 1e-3, HOME[1], HOME[2] - 5.0)  # 111 m north of the file's home
    wf = load(tmp_path, data, home_lla=other)
    assert wf.home_lla == other
    assert wf.world.obstacles[0].aabb(2)[0][0] == pytest.approx(10.0 - 110.9, abs=0.5)
    assert wf.world.obstacles[0].down_min_m == pytest.approx(-12.0, abs=1e-2)  # flat ground at the home used
    hill = load(tmp_path, data, ground_alt_m=lambda lat, lon: np.full(np.shape(lat), HOME[2] + 10.0))
    assert hill.world.obstacles[0].down_min_m == pytest.approx(-22.0, abs=1e-3)


def test_a_json_file_that_is_geojson_is_read_as_a_map(tmp_path):
    wf = load(tmp_path, collection(polygon(HANGAR, height=12)), name="site.json")
    assert isinstance(wf.world.obstacles[0], Prism) and wf.home_lla == HOME


# ----------------------------------------------------------------------------- KML


def kml(body: str, ns: str = ' xmlns="http://www.opengis.net/kml/2.2"') -> str:
    return f'<?xml version="1.0" encoding="UTF-8"?>\n<kml{ns}><Document><name>doc</name>{body}</Document></kml>\n'


def kml_polygon(rings_ne, height_m: float, mode: str = "relativeToGround", extrude: str = "1") -> str:
    def coords(r):
        return " ".join(f"{x},{y},{height_m}" for x, y in lon_lat(r))

    inner = "".join(
        f"<innerBoundaryIs><LinearRing><coordinates>{coords(r)}</coordinates></LinearRing></innerBoundaryIs>"
        for r in rings_ne[1:]
    )
    return (
        f"<Polygon><extrude>{extrude}</extrude><altitudeMode>{mode}</altitudeMode><outerBoundaryIs><LinearRing>"
        f"<coordinates>{coords(rings_ne[0])}</coordinates></LinearRing></outerBoundaryIs>{inner}</Polygon>"
    )


SQUARE_NE = [(10, -5), (10, 15), (30, 15), (30, -5), (10, -5)]


def test_the_site_kml_hangar_is_the_geojson_hangar():
    home = read_world_file(SITE / "buildings.geojson").home_lla
    (from_kml,) = read_world_file(SITE / "hangar.kml", home_lla=home).world.obstacles
    from_geojson = read_world_file(SITE / "buildings.geojson").world.obstacles[0]
    assert Polygon(from_kml.vertices_ne_m).symmetric_difference(Polygon(from_geojson.vertices_ne_m)).area < 1e-3
    assert from_kml.down_min_m == pytest.approx(from_geojson.down_min_m, abs=1e-6)


@pytest.mark.parametrize(
    "ns",
    [
        "",
        ' xmlns="http://earth.google.com/kml/2.1"',
        ' xmlns="http://www.opengis.net/kml/2.2" xmlns:gx="http://www.google.com/kml/ext/2.2"',
    ],
)
def test_kml_relative_to_ground_in_any_namespace(tmp_path, ns):
    text = kml(f"<Placemark><name>a</name>{kml_polygon([SQUARE_NE], 12)}</Placemark>", ns)
    wf = load(tmp_path, text, name="site.kml", home_lla=HOME)
    (prism,) = wf.world.obstacles
    assert prism.down_min_m == pytest.approx(-12.0, abs=1e-3) and wf.name == "doc"


def test_kml_absolute_tops_holes_and_multigeometry(tmp_path):
    absolute = kml_polygon([SQUARE_NE], HOME[2] + 20.0, mode="absolute")
    courtyard = kml_polygon(
        [[(50, 0), (50, 30), (80, 30), (80, 0), (50, 0)], [(58, 8), (58, 22), (72, 22), (72, 8), (58, 8)]], 6
    )
    text = kml(
        f"<Folder><Placemark>{absolute}</Placemark></Folder>"
        f"<Placemark><MultiGeometry>{courtyard}{kml_polygon([[(0, 50), (0, 60), (10, 60), (0, 50)]], 3)}"
        "</MultiGeometry></Placemark>"
    )
    obstacles = load(tmp_path, text, name="site.kml", home_lla=HOME).world.obstacles
    assert obstacles[0].down_min_m == pytest.approx(-20.0, abs=1e-3)
    assert len(obstacles) >= 4 and obstacles[-1].down_min_m == pytest.approx(-3.0, abs=1e-3)
    assert sum(Polygon(o.vertices_ne_m).area for o in obstacles[1:-1]) == pytest.approx(900 - 196, rel=1e-6)


# ----------------------------------------------------------------------------- the site and the commands


def test_the_committed_site_is_what_the_generator_writes():
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_site.py"), "--check"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr


def test_the_site_mission_legs_cross_the_buildings():
    local = mission_to_local(read_plan_file(SITE / "mission.plan"), world_file=SITE / "buildings.geojson")
    assert len(local.world.obstacles) == 12
    points = [tuple(w.pos_ned_m) for w in local.waypoints]
    blocked = [not local.world.segment_free(a, b) for a, b in zip(points[:-1], points[1:])]
    assert blocked == [True, False, True, False]


def test_a_bad_map_file_is_one_error_line_and_status_2(tmp_path, capsys):
    path = tmp_path / "site.geojson"
    path.write_text(
        json.dumps(
            collection(polygon(HANGAR, height=12), polygon(HANGAR), polygon(HANGAR), polygon(HANGAR, height="tall"))
        )
    )
    assert main(["plan", "--world", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert (
        err == f"companion: error: {path}: features[1].properties.height: missing (give height in m or "
        "building:levels, or companion.default_height_m for the whole file)"
    )


def test_plan_home_option_is_parsed_as_elsewhere(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["plan", "--world", "x.geojson", "--home=-35.3,149.1"])  # '=': a negative latitude is no option
    assert exc.value.code == 2 and "expected LAT,LON,ALT" in capsys.readouterr().err


# ----------------------------------------------------------------------------- errors


def feature_error_cases():
    good = polygon(HANGAR, height=12)
    point = lon_lat([(0, 0)])[0]
    bowtie = lon_lat([(0, 0), (10, 10), (10, 0), (0, 10), (0, 0)])

    def geom(kind, coords, **props):
        return {
            "type": "Feature",
            "properties": props or {"height": 5},
            "geometry": {"type": kind, "coordinates": coords},
        }

    return [
        (polygon(HANGAR, height="tall"), r'features\[3\]\.properties\.height: expected a number > 0, got "tall"$'),
        (polygon(HANGAR, height=-2), r"features\[3\]\.properties\.height: expected a number > 0, got -2"),
        (polygon(HANGAR, height=True), r"features\[3\]\.properties\.height: expected a number > 0, got true"),
        (polygon(HANGAR), r"features\[3\]\.properties\.height: missing"),
        (
            polygon(HANGAR, **{"building:levels": "some"}),
            r"features\[3\]\.properties\.building:levels: expected a number",
        ),
        (polygon(HANGAR, height=5, min_height=5), r"features\[3\]\.properties\.min_height: must be below the height"),
        (polygon(HANGAR, height=5, min_height=-1), r"features\[3\]\.properties\.min_height: expected a number >= 0"),
        ({**good, "properties": [1]}, r"features\[3\]\.properties: expected an object"),
        ({**good, "type": "Geometry"}, r'features\[3\]\.type: expected "Feature", got "Geometry"'),
        ([1, 2], r"features\[3\]: expected a Feature object"),
        ({**good, "geometry": None}, r"features\[3\]\.geometry: null"),
        (geom("GeometryCollection", []), r'features\[3\]\.geometry\.type: unsupported geometry "GeometryCollection"'),
        ({**good, "geometry": {"type": "Polygon"}}, r"features\[3\]\.geometry\.coordinates: missing"),
        (geom("Polygon", [bowtie]), r"features\[3\]\.geometry\.coordinates: not a valid polygon: Self-intersection"),
        (geom("Polygon", [HANGAR[:-1]]), r"features\[3\]\.geometry\.coordinates\[0\]: a linear ring must be closed"),
        (geom("Polygon", [HANGAR[:3]]), r"features\[3\]\.geometry\.coordinates\[0\]: expected a list of at least 4"),
        (
            geom("Polygon", [HANGAR, ring(100, 100, 110, 110)]),
            r"features\[3\]\.geometry\.coordinates: not a valid polygon: Hole lies outside shell",
        ),
        (
            geom("Polygon", [[*HANGAR[:2], ["a", 1], *HANGAR[2:]]]),
            r"features\[3\]\.geometry\.coordinates\[0\]\[2\]: expected a position",
        ),
        (geom("Point", [200.0, -35.0], radius=1, height=3), r"features\[3\]\.geometry\.coordinates: longitude must be"),
        (
            geom("MultiPolygon", [[HANGAR], [[*HANGAR[:-1]]]]),
            r"features\[3\]\.geometry\.coordinates\[1\]\[0\]: a linear ring must be closed",
        ),
        (geom("Point", point, height=3), r"features\[3\]\.properties\.radius: missing \(a Point needs a radius"),
        (geom("Point", point, height=3, radius=0), r"features\[3\]\.properties\.radius: expected a number > 0, got 0"),
        (
            geom("LineString", [point, lon_lat([(5, 5)])[0]], height=3),
            r"features\[3\]\.properties\.width: missing \(a LineString needs a width",
        ),
        (
            geom("LineString", [point, point], height=3, width=1),
            r"features\[3\]\.geometry\.coordinates: the line has zero length",
        ),
    ]


@pytest.mark.parametrize("bad, message", feature_error_cases())
def test_a_bad_feature_names_the_file_its_index_and_the_property(tmp_path, bad, message):
    good = polygon(HANGAR, height=12)
    with pytest.raises(WorldError, match=r"^" + str(tmp_path / "site.geojson").replace("\\", "\\\\") + ": " + message):
        load(tmp_path, collection(good, good, good, bad))


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"type": "FeatureCollection", "features": [}', r"line 1, column 44: Expecting value"),
        ("[]", r"expected a GeoJSON FeatureCollection object"),
        ('{"type": "Feature", "geometry": null}', r'type: expected "FeatureCollection", got "Feature"'),
        ('{"type": "FeatureCollection"}', r"features: expected a list of Feature objects, got null"),
        (
            '{"type": "FeatureCollection", "features": [], "crs": {"type": "name", "properties": {"name": "EPSG:3857"}}}',
            r"crs: .*only WGS-84",
        ),
        ('{"type": "FeatureCollection", "features": []}', r"a map world needs a home"),
        (
            '{"type": "FeatureCollection", "features": [], "companion": {"colour": 1}}',
            r"companion\.colour: unknown key",
        ),
        (
            '{"type": "FeatureCollection", "features": [], "companion": {"home": [149, -35]}}',
            r"companion\.home: expected \[longitude, latitude, metres\]",
        ),
        (
            '{"type": "FeatureCollection", "features": [], "companion": {"home": [149, -35, 500], "bounds": [149.1, -35, 149, -34]}}',
            r"companion\.bounds: expected west < east",
        ),
        (
            '{"type": "FeatureCollection", "features": [], "companion": {"home": [149, -35, 500], "margin_m": -1}}',
            r"companion\.margin_m: expected a number >= 0",
        ),
    ],
)
def test_a_bad_collection_names_the_file_and_the_key(tmp_path, text, message):
    with pytest.raises(WorldError, match=r"^" + str(tmp_path / "site.geojson").replace("\\", "\\\\") + ": " + message):
        load(tmp_path, text)


@pytest.mark.parametrize(
    "body, message",
    [
        ("<Placemark><Polygon>", r"line 2, column \d+: not well-formed XML"),
        ("", r"no Placemark"),
        (
            f"<Placemark><name>shed</name>{kml_polygon([SQUARE_NE], 5, extrude='0')}</Placemark>",
            r"Placemark\[0\] 'shed': Polygon\.extrude: expected 1",
        ),
        (
            f"<Placemark>{kml_polygon([SQUARE_NE], 5, mode='clampToGround')}</Placemark>",
            r"Placemark\[0\]: Polygon\.altitudeMode: expected relativeToGround or absolute, got 'clampToGround'",
        ),
        (
            f"<Placemark>{kml_polygon([SQUARE_NE], 0)}</Placemark>",
            r"Placemark\[0\]: Polygon\.outerBoundaryIs\.LinearRing\.coordinates: .*expected a number > 0, got 0",
        ),
        (
            f"<Placemark>{kml_polygon([SQUARE_NE], 5)}</Placemark><Placemark><Point><coordinates>149,-35</coordinates></Point></Placemark>",
            r"Placemark\[1\]: geometry Point: unsupported",
        ),
        (
            f"<Placemark>{kml_polygon([SQUARE_NE[:-1]], 5)}</Placemark>",
            r"Placemark\[0\]: Polygon\.outerBoundaryIs\.LinearRing\.coordinates: a LinearRing needs at least 4",
        ),
        (
            "<Placemark><Polygon><extrude>1</extrude><altitudeMode>absolute</altitudeMode><outerBoundaryIs><LinearRing>"
            "<coordinates>149.1,-35.3,600 x,y</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>",
            r"Placemark\[0\]: Polygon\.outerBoundaryIs\.LinearRing\.coordinates: tuple 1: expected lon,lat\[,alt\], got 'x,y'",
        ),
        (
            f"<Placemark>{kml_polygon([[(0, 0), (10, 10), (10, 0), (0, 10), (0, 0)]], 5)}</Placemark>",
            r"Placemark\[0\]: Polygon: not a valid polygon: Self-intersection",
        ),
        (
            f"<Placemark>{kml_polygon([SQUARE_NE], HOME[2] - 1, mode='absolute')}</Placemark>",
            r"Placemark\[0\]: Polygon: the top \(583\.00 m AMSL\) is not above the bottom",
        ),
    ],
)
def test_a_bad_kml_names_the_file_the_placemark_and_the_element(tmp_path, body, message):
    text = (
        kml(body)
        if not body.startswith("<Placemark><Polygon>") or body.endswith("</Placemark>")
        else '<?xml version="1.0"?>\n<kml><Document>' + body
    )
    with pytest.raises(WorldError, match=r"^" + str(tmp_path / "site.kml").replace("\\", "\\\\") + ": " + message):
        load(tmp_path, text, name="site.kml", home_lla=HOME)


def test_toml_worlds_do_not_need_shapely():
    code = (
        "import sys, companion.world as w; w.load_world('mission_files/worlds/city_3d.toml'); "
        "assert 'shapely' not in sys.modules, 'shapely imported'"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
