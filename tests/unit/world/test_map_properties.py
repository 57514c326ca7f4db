"""Map worlds, property-tested (hypothesis) against the source shapes, not the World's copy.

- Paths planned by GART and smoothed (G1, G2 with the world's repair) in a world read from a
  random GeoJSON file keep the margin from every obstacle: densely sampled path points are
  measured with shapely against the footprints the file was made from (the test's own
  north-east polygons, circles and buffered lines, with their heights).
- lon/lat -> local -> lon/lat (and local -> lon/lat -> local) round-trips, anywhere on Earth.
- A polygon with holes is cut into simple pieces whose union is the polygon.
- ``companion plan`` on the example site gives a path clear of its buildings, measured the same
  way from ``buildings.geojson`` itself.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import shapely
import shapely.affinity
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, MultiPoint, Point, Polygon

from companion.cli import main
from companion.planning import GartSettings, gart
from companion.smoothing import smooth_g1, smooth_g2
from companion.world import read_world_file
from companion.world.mapdata import flat_ground, footprint_deg, footprint_ne_m, simple_pieces_ne_m
from heli_common.frames import LocalFrame

ROOT = Path(__file__).resolve().parents[3]
SITE = ROOT / "mission_files" / "sites" / "cmac"
HOME = (-35.363261, 149.165230, 584.0)
FRAME = LocalFrame(*HOME)
MARGIN_M = 2.0
KAPPA_MAX_1_M = 0.2
SAMPLE_STEP_M = 0.05
#: Conversion slack: the limits are taken along the local vertical at the footprint (the tangent
#: plane falls away by r^2 / 2R, under 2 mm here) and vertices are rounded by nothing else.
TOLERANCE_M = 0.01


@dataclass(frozen=True)
class Solid:
    """A source obstacle: a north-east footprint (m) between two altitudes above home (m)."""

    footprint_ne_m: object  # shapely geometry: Polygon, or a Point with radius_m
    bottom_m: float
    top_m: float
    radius_m: float = 0.0


def clearance_m(points_ned_m: np.ndarray, solid: Solid) -> np.ndarray:
    """Exact distance (m) from points (K, 3) to the solid: horizontal and vertical gaps combined."""
    horizontal = shapely.distance(shapely.points(points_ned_m[:, :2]), solid.footprint_ne_m) - solid.radius_m
    alt_m = -points_ned_m[:, 2]
    vertical = np.maximum.reduce([alt_m - solid.top_m, solid.bottom_m - alt_m, np.zeros(len(alt_m))])
    return np.hypot(np.maximum(horizontal, 0.0), vertical)


def sample_polyline(path: np.ndarray, step_m: float = SAMPLE_STEP_M) -> np.ndarray:
    """Points every ``step_m`` along a polyline (M, 3), ends included."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step_m)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(out)


def lon_lat(geometry_ne_m):
    return footprint_deg(geometry_ne_m, FRAME, flat_ground(FRAME))


# ----------------------------------------------------------------------------- random sites


@st.composite
def star_polygon_ne(draw, max_radius_m: float = 12.0) -> Polygon:
    """A simple (often concave) polygon about a centre inside the 15..85 m square."""
    cn, ce = draw(st.floats(15, 85)), draw(st.floats(15, 85))
    k = draw(st.integers(5, 9))
    radii = draw(st.lists(st.floats(3.0, max_radius_m), min_size=k, max_size=k))
    jitter = draw(st.lists(st.floats(-0.3, 0.3), min_size=k, max_size=k))
    angles = [2 * math.pi * (i + j) / k for i, j in enumerate(jitter)]
    poly = Polygon([(cn + r * math.cos(a), ce + r * math.sin(a)) for r, a in zip(radii, angles)])
    if draw(st.booleans()):
        hole = Point(cn, ce).buffer(draw(st.floats(0.5, 1.5)), quad_segs=2)
        if hole.within(poly.buffer(-0.5)):
            poly = Polygon(poly.exterior.coords, [hole.exterior.coords])
    return poly


@st.composite
def solid_and_feature(draw):
    """(the test's source solid, its GeoJSON feature)."""
    kind = draw(st.sampled_from(["Polygon", "Point", "LineString"]))
    top_m = draw(st.floats(4.0, 25.0))
    bottom_m = draw(st.sampled_from([0.0, 0.0, None]))
    bottom_m = draw(st.floats(1.0, top_m - 2.0)) if bottom_m is None else bottom_m
    props = {"height": top_m, **({"min_height": bottom_m} if bottom_m > 0 else {})}
    if kind == "Polygon":
        shape = draw(star_polygon_ne())
        coords = [[list(p) for p in lon_lat(LineString(r.coords)).coords] for r in [shape.exterior, *shape.interiors]]
        solid = Solid(shape, bottom_m, top_m)
    elif kind == "Point":
        centre = Point(draw(st.floats(15, 85)), draw(st.floats(15, 85)))
        props["radius"] = radius_m = draw(st.floats(0.5, 4.0))
        coords = list(lon_lat(centre).coords[0])
        solid = Solid(centre, bottom_m, top_m, radius_m)
    else:
        pts = draw(st.lists(st.tuples(st.floats(15, 85), st.floats(15, 85)), min_size=2, max_size=3, unique=True))
        line = LineString(pts)
        assume(line.length > 1.0 and line.is_simple)
        props["width"] = width_m = draw(st.floats(0.3, 2.0))
        coords = [list(p) for p in lon_lat(line).coords]
        solid = Solid(line.buffer(0.5 * width_m, cap_style="flat", join_style="mitre"), bottom_m, top_m)
    return solid, {"type": "Feature", "properties": props, "geometry": {"type": kind, "coordinates": coords}}


BOUNDS_DEG = [*lon_lat(Point(-15.0, -15.0)).coords[0], *lon_lat(Point(115.0, 115.0)).coords[0]]


@st.composite
def blocker_and_feature(draw):
    """A building across the diagonal from start to goal, taller than both: no straight line."""
    c = draw(st.floats(30.0, 70.0))
    shape = draw(star_polygon_ne()).buffer(0)
    shape = shapely.affinity.translate(shape, c - shape.centroid.x, c - shape.centroid.y)
    top_m = draw(st.floats(23.0, 30.0))
    coords = [[list(p) for p in lon_lat(LineString(r.coords)).coords] for r in [shape.exterior, *shape.interiors]]
    return Solid(shape, 0.0, top_m), {
        "type": "Feature",
        "properties": {"building:levels": top_m / 3.0},
        "geometry": {"type": "Polygon", "coordinates": coords},
    }


def write_site(tmp_path: Path, features: list[dict]) -> Path:
    path = tmp_path / "random.geojson"
    path.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": features,
                "companion": {
                    "home": [HOME[1], HOME[0], HOME[2]],
                    "margin_m": MARGIN_M,
                    "ceiling_m": 40.0,
                    "bounds": BOUNDS_DEG,
                },
            }
        )
    )
    return path


def assert_clear(points_ned_m: np.ndarray, solids: list[Solid], what: str) -> None:
    for k, solid in enumerate(solids):
        worst = float(clearance_m(points_ned_m, solid).min())
        assert worst >= MARGIN_M - TOLERANCE_M, f"{what}: {worst:.4f} m from obstacle {k}"


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.filter_too_much],
)
@given(
    site=st.lists(solid_and_feature(), min_size=0, max_size=4),
    blocker=blocker_and_feature(),
    start_alt_m=st.floats(3.0, 20.0),
    goal_alt_m=st.floats(3.0, 20.0),
    seed=st.integers(0, 2**16),
)
def test_planned_and_smoothed_paths_keep_the_margin_from_the_source_shapes(
    tmp_path, site, blocker, start_alt_m, goal_alt_m, seed
):
    site = [blocker, *site]
    solids = [s for s, _ in site]
    world = read_world_file(write_site(tmp_path, [f for _, f in site])).world
    start, goal = (0.0, 0.0, -start_alt_m), (100.0, 100.0, -goal_alt_m)
    result = gart(
        world,
        start,
        goal,
        rng=np.random.default_rng(seed),
        max_iterations=1500,
        max_time_s=10.0,
        settings=GartSettings(kappa_max_1_m=KAPPA_MAX_1_M),
    )  # refined: paths that hug obstacles
    assume(result.solved)
    assert_clear(sample_polyline(result.path), solids, "GART path")
    for name, curve in (
        ("G1", smooth_g1(result.path, world=world, kappa_max_1_m=KAPPA_MAX_1_M)),
        ("G2", smooth_g2(result.path, KAPPA_MAX_1_M, world=world)),
    ):
        assert_clear(curve.polyline(SAMPLE_STEP_M), solids, f"{name}-smoothed path")


# ----------------------------------------------------------------------------- round trips

homes = st.tuples(st.floats(-80.0, 80.0), st.floats(-180.0, 180.0), st.floats(-100.0, 4000.0))


@settings(max_examples=200, deadline=None)
@given(
    home=homes,
    offsets=st.lists(st.tuples(st.floats(-0.02, 0.02), st.floats(-0.02, 0.02)), min_size=1, max_size=8),
    hill_m=st.floats(-50.0, 300.0),
)
def test_lon_lat_to_local_and_back_round_trips(home, offsets, hill_m):
    frame = LocalFrame(*home)

    def ground(lat, lon):  # a slope: the ground is not the home's level everywhere
        return frame.alt0_m + hill_m * (np.asarray(lat) - frame.lat0_deg) / 0.02

    lon = np.clip(np.array([home[1] + d for _, d in offsets]), -180.0, 180.0)
    lat = np.array([home[0] + d for d, _ in offsets])
    points_deg = MultiPoint(np.column_stack([lon, lat]))
    local = footprint_ne_m(points_deg, frame, ground)
    back = shapely.get_coordinates(footprint_deg(local, frame, ground))
    np.testing.assert_allclose(back, shapely.get_coordinates(points_deg), rtol=0, atol=1e-9)
    again = shapely.get_coordinates(footprint_ne_m(footprint_deg(local, frame, ground), frame, ground))
    np.testing.assert_allclose(again, shapely.get_coordinates(local), rtol=0, atol=1e-5)


@settings(max_examples=100, deadline=None)
@given(
    poly=star_polygon_ne(max_radius_m=20.0),
    extra_holes=st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6)), max_size=3),
)
def test_holes_are_cut_into_simple_pieces_that_tile_the_polygon(poly, extra_holes):
    centre = poly.centroid
    holes = [Point(centre.x + dn, centre.y + de).buffer(0.8, quad_segs=2) for dn, de in extra_holes]
    holes = [h for h in holes if h.within(poly.buffer(-0.3))]
    for h in holes:
        if h.disjoint(shapely.union_all([Polygon(i) for i in poly.interiors] + [Point(1e9, 1e9)]).buffer(0.3)):
            poly = Polygon(poly.exterior.coords, [*[i.coords for i in poly.interiors], h.exterior.coords])
    assume(poly.is_valid)
    pieces = simple_pieces_ne_m(poly)
    assert all(p.is_valid and not p.interiors and p.exterior.is_ccw for p in pieces)
    assert sum(p.area for p in pieces) == pytest.approx(poly.area, rel=1e-9)
    assert shapely.union_all(pieces).symmetric_difference(poly).area < 1e-6 * poly.area


# ----------------------------------------------------------------------------- the example site


def metres(value) -> float:
    return float(str(value).removesuffix(" m"))


def site_solids() -> list[Solid]:
    """The site's obstacles straight from buildings.geojson (height, levels x 3, min_height),
    projected by the test itself (pymap3d through LocalFrame, at the home's level)."""

    def to_ne(lon_lat_deg: np.ndarray) -> np.ndarray:
        north_m, east_m, _ = FRAME.to_ned(lon_lat_deg[:, 1], lon_lat_deg[:, 0], HOME[2])
        return np.column_stack([north_m, east_m])

    out = []
    for feature in json.loads((SITE / "buildings.geojson").read_text())["features"]:
        p = feature["properties"]
        top_m = metres(p["height"]) if "height" in p else 3.0 * metres(p["building:levels"])
        shape = shapely.transform(shapely.from_geojson(json.dumps(feature["geometry"])), to_ne)
        if "width" in p:
            shape = shape.buffer(0.5 * metres(p["width"]), cap_style="flat", join_style="mitre")
        out.append(Solid(shape, metres(p.get("min_height", 0)), top_m, metres(p.get("radius", 0))))
    return out


@pytest.mark.parametrize(
    "smooth, extra",
    [
        ("none", [f"--home={HOME[0]},{HOME[1]},{HOME[2]}", "--start", "0,0,-10", "--goal", "200,0,-10"]),
        ("g2", []),  # the file's home, start and goal: the same ones
    ],
)
def test_companion_plan_on_the_site_avoids_the_buildings(tmp_path, smooth, extra):
    out = tmp_path / "plan.json"
    rc = main(
        [
            "plan",
            "--world",
            str(SITE / "buildings.geojson"),
            "--smooth",
            smooth,
            "--no-feasibility",
            "--seed",
            "1",
            "--json",
            str(out),
            *extra,
        ]
    )
    assert rc == 0
    data = json.loads(out.read_text())
    assert data["home_lla"] == list(HOME)
    assert data["start"] == pytest.approx([0.0, 0.0, -10.0], abs=1e-3)
    assert data["goal"] == pytest.approx([200.0, 0.0, -10.0], abs=1e-2)
    solids = site_solids()
    margin_m = json.loads((SITE / "buildings.geojson").read_text())["companion"]["margin_m"]
    straight = sample_polyline(np.array([data["start"], data["goal"]]))
    assert sum(clearance_m(straight, s).min() == 0.0 for s in solids) == 2  # through hangar and office,
    assert sum(clearance_m(straight, s).min() < margin_m for s in solids) == 3  # 1 m over the workshop
    (entry,) = data["paths"]
    path = sample_polyline(np.array(entry["path"]))
    assert min(clearance_m(path, s).min() for s in solids) >= margin_m - TOLERANCE_M
    if smooth == "g2":
        curve = sample_polyline(np.array(entry["smoothed"]["polyline"]))  # the JSON's 1 m polyline, resampled
        assert min(clearance_m(curve, s).min() for s in solids) >= margin_m - TOLERANCE_M
