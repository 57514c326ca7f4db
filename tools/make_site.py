#!/usr/bin/env python3
"""Write the example map site ``mission_files/sites/<name>/`` (``--check``: only compare).

Usage: ``.venv/bin/python tools/make_site.py [--name cmac] [--check]``.

The site is made here, not downloaded, and is the same on every run: a yard next to ArduPilot's
SITL home (CMAC, Canberra: -35.363261, 149.165230, 584 m) with buildings drawn in local
north-east metres about that home and converted to WGS-84 with ``heli_common.frames.LocalFrame``:

- ``buildings.geojson``: a hangar (``height``), an L-shaped office (``building:levels`` as
  OpenStreetMap writes it, a string), a workshop round a courtyard (a hole), a canopy on
  pillars (``min_height``), two sheds (a MultiPolygon), a radio mast (a Point with ``radius``),
  a power line on two poles (a LineString with ``width`` and ``min_height``) and a garden wall;
- ``hangar.kml``: the hangar again, as Google Earth writes an extruded building;
- ``mission.plan``: a QGroundControl mission at 10 m above home whose straight legs cross the
  hangar, the office, the workshop, the power line, the canopy, the mast and the sheds.

Exit status 1 with ``--check`` when a file differs from what this script writes.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from shapely.geometry import MultiPoint  # noqa: E402

from companion.mission.model import (  # noqa: E402
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MissionItem,
    MissionPlan,
)
from companion.mission.plan_file import plan_to_document  # noqa: E402
from companion.world.mapdata import flat_ground, footprint_deg  # noqa: E402
from heli_common.frames import LocalFrame  # noqa: E402

log = logging.getLogger("make_site")

HOME_LLA = (-35.363261, 149.165230, 584.0)  # ArduPilot SITL's default home (CMAC)
CRUISE_ALT_M = 10.0  # the mission's altitude above home
MARGIN_M = 3.0  # as the companion's mission.margin_m
DIGITS = 8  # degrees to 1e-8 (about 1 mm)

#: (name, GeoJSON geometry type, north-east metres, properties). Rings are closed.
FEATURES_NE_M = (
    (
        "hangar",
        "Polygon",
        [[(55, -25), (55, 15), (75, 15), (75, -25), (55, -25)]],
        {"building": "hangar", "height": 12},
    ),
    (
        "office",
        "Polygon",
        [[(105, -30), (105, 10), (120, 10), (120, -15), (135, -15), (135, -30), (105, -30)]],
        {"building": "office", "building:levels": "4"},
    ),
    (
        "workshop",
        "Polygon",
        [
            [(160, -20), (160, 10), (190, 10), (190, -20), (160, -20)],
            [(168, -12), (182, -12), (182, 2), (168, 2), (168, -12)],
        ],
        {"building": "industrial", "building:levels": 3},
    ),
    (
        "canopy",
        "Polygon",
        [[(80, 44), (80, 56), (100, 56), (100, 44), (80, 44)]],
        {"building": "roof", "min_height": 5, "height": 9},
    ),
    (
        "sheds",
        "MultiPolygon",
        [
            [[(128, 50), (128, 58), (136, 58), (136, 50), (128, 50)]],
            [[(140, 50), (140, 58), (146, 58), (146, 50), (140, 50)]],
        ],
        {"building": "shed", "height": "4 m"},
    ),
    ("radio mast", "Point", (110, 52), {"man_made": "mast", "radius": 1.5, "height": 30}),
    ("power line", "LineString", [(40, 28), (40, 64)], {"power": "line", "width": 0.5, "min_height": 8, "height": 14}),
    ("pole west", "Point", (40, 28), {"power": "pole", "radius": 0.3, "height": 14}),
    ("pole east", "Point", (40, 64), {"power": "pole", "radius": 0.3, "height": 14}),
    ("garden wall", "LineString", [(0, -40), (20, -40), (30, -50)], {"barrier": "wall", "width": 0.4, "height": 2.5}),
)
#: The mission's waypoints (north, east) at CRUISE_ALT_M, then a landing at home.
WAYPOINTS_NE_M = ((200.0, 0.0), (200.0, 60.0), (20.0, 45.0))
START_NE_M, GOAL_NE_M = (0.0, 0.0), (200.0, 0.0)
NUMBER_LIST_RE = re.compile(r"\[\s*-?[\d.]+(?:,\s*-?[\d.]+)*\s*\]")


def lon_lat(frame: LocalFrame, points_ne_m) -> list[list[float]]:
    """``(K, 2)`` north-east metres on the (flat) ground -> ``[[lon, lat], ...]`` degrees, the
    inverse of the conversion the companion reads them with."""
    ground = footprint_deg(MultiPoint([(float(n), float(e)) for n, e in points_ne_m]), frame, flat_ground(frame))
    return [[round(p.x, DIGITS), round(p.y, DIGITS)] for p in ground.geoms]


def geometry(frame: LocalFrame, kind: str, coords_ne_m) -> dict:
    """A GeoJSON geometry from north-east metres."""
    if kind == "Point":
        return {"type": kind, "coordinates": lon_lat(frame, [coords_ne_m])[0]}
    if kind == "LineString":
        return {"type": kind, "coordinates": lon_lat(frame, coords_ne_m)}
    if kind == "Polygon":
        return {"type": kind, "coordinates": [lon_lat(frame, ring) for ring in coords_ne_m]}
    return {"type": kind, "coordinates": [[lon_lat(frame, ring) for ring in poly] for poly in coords_ne_m]}


def position(frame: LocalFrame, point_ne_m, height_m: float) -> list[float]:
    """A GeoJSON position ``[lon, lat, height]`` of the ``companion`` member."""
    return lon_lat(frame, [point_ne_m])[0] + [height_m]


def buildings_geojson(frame: LocalFrame, name: str) -> dict:
    """The FeatureCollection, with the world's settings in its ``companion`` member."""
    features = [
        {"type": "Feature", "properties": {"name": label, **props}, "geometry": geometry(frame, kind, coords)}
        for label, kind, coords, props in FEATURES_NE_M
    ]
    header = {
        "name": name,
        "home": [HOME_LLA[1], HOME_LLA[0], HOME_LLA[2]],
        "margin_m": MARGIN_M,
        "ceiling_m": 60.0,
        "padding_m": 30.0,
        "start": position(frame, START_NE_M, CRUISE_ALT_M),
        "goal": position(frame, GOAL_NE_M, CRUISE_ALT_M),
    }
    return {"type": "FeatureCollection", "companion": header, "features": features}


def hangar_kml(frame: LocalFrame, name: str) -> str:
    """The hangar as an extruded KML polygon (Google Earth's form of a building)."""
    label, _, rings, props = FEATURES_NE_M[0]
    height_m = float(props["height"])
    coords = " ".join(f"{x},{y},{height_m:g}" for x, y in lon_lat(frame, rings[0]))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2">
  <Document>
    <name>{name} {label}</name>
    <Placemark>
      <name>{label}</name>
      <Polygon>
        <extrude>1</extrude>
        <altitudeMode>relativeToGround</altitudeMode>
        <outerBoundaryIs>
          <LinearRing>
            <coordinates>{coords}</coordinates>
          </LinearRing>
        </outerBoundaryIs>
      </Polygon>
    </Placemark>
  </Document>
</kml>
"""


def mission(frame: LocalFrame) -> MissionPlan:
    """Take off at home, fly the waypoints at CRUISE_ALT_M above home, land at home."""
    items = [MissionItem(MAV_CMD_NAV_TAKEOFF, alt_m=CRUISE_ALT_M)]
    for point in WAYPOINTS_NE_M:
        lon, lat = lon_lat(frame, [point])[0]
        items.append(
            MissionItem(MAV_CMD_NAV_WAYPOINT, param2=2.0, param4=math.nan, lat_deg=lat, lon_deg=lon, alt_m=CRUISE_ALT_M)
        )
    items.append(MissionItem(MAV_CMD_NAV_LAND, param4=math.nan, lat_deg=HOME_LLA[0], lon_deg=HOME_LLA[1]))
    return MissionPlan(items=tuple(items), planned_home=HOME_LLA, cruise_speed_m_s=5.0, hover_speed_m_s=3.0)


def json_text(document: dict) -> str:
    """Indented JSON with every list of numbers (a position) on one line."""
    text = json.dumps(document, indent=1)
    return NUMBER_LIST_RE.sub(lambda m: "[" + ", ".join(m.group(0)[1:-1].split()).replace(",,", ",") + "]", text) + "\n"


def site_files(name: str) -> dict[str, str]:
    """File name -> text of the site."""
    frame = LocalFrame(*HOME_LLA)
    return {
        "buildings.geojson": json_text(buildings_geojson(frame, name)),
        "hangar.kml": hangar_kml(frame, name),
        "mission.plan": json.dumps(plan_to_document(mission(frame)), indent=4) + "\n",
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", default="cmac", help="the site's folder under mission_files/sites/ (default cmac)")
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    folder = ROOT / "mission_files" / "sites" / args.name
    stale = []
    for filename, text in site_files(args.name).items():
        path = folder / filename
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(path)
            continue
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        log.info("wrote %s", path.relative_to(ROOT))
    for path in stale:
        log.error("%s differs from what tools/make_site.py writes: run it", path.relative_to(ROOT))
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
