"""KML map files: extruded polygons (Google Earth buildings) -> a :class:`MapDocument`.

Reading and checking only (``xml.etree.ElementTree``; the namespace is not fixed: KML 2.2
``http://www.opengis.net/kml/2.2``, Google's older ``http://earth.google.com/kml/2.x`` and
no namespace all read). Every ``Placemark`` of the file must hold ``Polygon`` elements, directly
or in a ``MultiGeometry``; each polygon is one obstacle::

    <Placemark><name>Hangar</name>
      <Polygon>
        <extrude>1</extrude>
        <altitudeMode>relativeToGround</altitudeMode>
        <outerBoundaryIs><LinearRing><coordinates>
          149.1650,-35.3627,9 149.1653,-35.3627,9 149.1653,-35.3625,9 149.1650,-35.3627,9
        </coordinates></LinearRing></outerBoundaryIs>
      </Polygon>
    </Placemark>

- ``extrude`` must be 1: the walls reach down to the ground (an obstacle without a bottom);
- ``altitudeMode`` ``relativeToGround``: the highest coordinate altitude is the height above
  ground; ``absolute``: it is the top's altitude AMSL. ``clampToGround`` (KML's default) lies
  flat on the ground and is refused, as are Google's sea-floor modes;
- ``innerBoundaryIs`` rings are holes (courtyards).

Errors name the placemark and the element, e.g.
``Placemark[2] "Hangar": Polygon.altitudeMode: expected relativeToGround or absolute, got
"clampToGround"``; :func:`parse_kml` prefixes the file.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from shapely.geometry import Polygon
from shapely.validation import explain_validity

from companion.errors import WorldError
from companion.world.mapdata import MapDocument, MapFeature

__all__ = ["parse_kml"]

_MODES = ("relativeToGround", "absolute")
_GEOMETRY_TAGS = ("Point", "LineString", "LinearRing", "Polygon", "MultiGeometry", "Model", "Track", "MultiTrack")


def _local(tag: str) -> str:
    """An element's tag without its namespace (``{ns}Polygon`` -> ``Polygon``)."""
    return tag.rsplit("}", 1)[-1]


def _children(element: ET.Element, name: str) -> list[ET.Element]:
    return [child for child in element if _local(child.tag) == name]


def _child_text(element: ET.Element, name: str) -> str | None:
    found = _children(element, name)
    return None if not found or found[0].text is None else found[0].text.strip()


def _coordinates(ring: ET.Element, where: str) -> list[tuple[float, float, float]]:
    """A LinearRing's ``coordinates`` text -> (lon_deg, lat_deg, alt_m) tuples (alt 0 if absent)."""
    text = _child_text(ring, "coordinates")
    if not text:
        raise WorldError(f"{where}.coordinates: missing or empty")
    out = []
    for k, word in enumerate(text.split()):
        parts = word.split(",")
        try:
            values = [float(v) for v in parts]
        except ValueError:
            values = []
        if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
            raise WorldError(f"{where}.coordinates: tuple {k}: expected lon,lat[,alt], got {word!r}")
        lon, lat, alt = values[0], values[1], values[2] if len(values) == 3 else 0.0
        if not -180.0 <= lon <= 180.0 or not -90.0 <= lat <= 90.0:
            raise WorldError(
                f"{where}.coordinates: tuple {k}: longitude must be -180..180 and "
                f"latitude -90..90 degrees, got {word!r}"
            )
        out.append((lon, lat, alt))
    if len(out) < 4 or out[0][:2] != out[-1][:2]:
        raise WorldError(
            f"{where}.coordinates: a LinearRing needs at least 4 tuples, the last equal to the first, got {len(out)}"
        )
    return out


def _ring(boundary: ET.Element, where: str) -> list[tuple[float, float, float]]:
    rings = _children(boundary, "LinearRing")
    if len(rings) != 1:
        raise WorldError(f"{where}: expected one LinearRing, got {len(rings)}")
    return _coordinates(rings[0], f"{where}.LinearRing")


def _extruded_mode(polygon: ET.Element, where: str) -> str:
    """The polygon's altitude mode, after checking that it is extruded."""
    extrude = _child_text(polygon, "extrude")
    if extrude not in ("1", "true"):
        raise WorldError(
            f"{where}.extrude: expected 1 (walls down to the ground), got {extrude!r}: a flat polygon is no obstacle"
        )
    mode = _child_text(polygon, "altitudeMode") or "clampToGround"
    if mode not in _MODES:
        raise WorldError(
            f"{where}.altitudeMode: expected relativeToGround or absolute, got "
            f"{mode!r} (a clamped polygon has no height)"
        )
    return mode


def _polygon_feature(polygon: ET.Element, where: str) -> MapFeature:
    """One extruded ``Polygon`` -> a MapFeature (top from its highest coordinate)."""
    mode = _extruded_mode(polygon, where)
    outer = _children(polygon, "outerBoundaryIs")
    if len(outer) != 1:
        raise WorldError(f"{where}.outerBoundaryIs: expected one, got {len(outer)}")
    shell = _ring(outer[0], f"{where}.outerBoundaryIs")
    holes = [_ring(b, f"{where}.innerBoundaryIs[{i}]") for i, b in enumerate(_children(polygon, "innerBoundaryIs"))]
    shape = Polygon([p[:2] for p in shell], [[p[:2] for p in h] for h in holes])
    if not shape.is_valid or shape.area <= 0.0:
        reason = explain_validity(shape) if not shape.is_valid else "zero area"
        raise WorldError(f"{where}: not a valid polygon: {reason}")
    top_m = max(p[2] for p in shell)
    if mode == "relativeToGround" and not top_m > 0.0:
        raise WorldError(
            f"{where}.outerBoundaryIs.LinearRing.coordinates: the altitudes give "
            f"the height above ground; expected a number > 0, got {top_m:g}"
        )
    return MapFeature(where=where, geometry_deg=shape, height_m=top_m, top_is_amsl=(mode == "absolute"))


def _placemark_polygons(placemark: ET.Element, where: str) -> list[tuple[ET.Element, str]]:
    """The placemark's Polygon elements with their paths (direct or in MultiGeometry)."""
    found = [(p, f"{where}: Polygon") for p in _children(placemark, "Polygon")]
    for m, multi in enumerate(_children(placemark, "MultiGeometry")):
        polygons = _children(multi, "Polygon")
        found += [(p, f"{where}: MultiGeometry[{m}].Polygon[{k}]") for k, p in enumerate(polygons)]
        others = sorted({_local(c.tag) for c in multi} & set(_GEOMETRY_TAGS) - {"Polygon"})
        if others:
            raise WorldError(
                f"{where}: MultiGeometry[{m}].{others[0]}: unsupported geometry (only extruded Polygons are obstacles)"
            )
    if not found:
        kinds = sorted({_local(c.tag) for c in placemark} & set(_GEOMETRY_TAGS))
        what = kinds[0] if kinds else "none"
        raise WorldError(
            f"{where}: geometry {what}: unsupported (only extruded Polygons are "
            "obstacles; remove the placemark or draw it as a polygon)"
        )
    return found


def _placemark_features(placemark: ET.Element, index: int) -> list[MapFeature]:
    name = _child_text(placemark, "name")
    where = f"Placemark[{index}]" + (f" {name!r}" if name else "")
    return [_polygon_feature(p, at) for p, at in _placemark_polygons(placemark, where)]


def parse_kml(content: bytes | str, source: str = "map", default_name: str | None = None) -> MapDocument:
    """KML text -> :class:`MapDocument` (every Placemark an extruded polygon or several).

    Parameters
    ----------
    content : bytes or str
        The file's content.
    source : str
        The file, for errors (every message starts with it).
    default_name : str, optional
        The world's name when the Document has no ``name`` (default ``source``).

    Raises
    ------
    WorldError
        ``"<source>: Placemark[i] 'name': <element>: <what is wrong>"``, or an XML syntax error
        with its line and column.
    """
    try:
        root = ET.fromstring(content)
    except ET.ParseError as exc:
        line, column = exc.position
        raise WorldError(
            f"{source}: line {line}, column {column}: not well-formed XML ({str(exc).split(':')[0]})"
        ) from None
    try:
        if _local(root.tag) != "kml":
            raise WorldError(f"root element: expected kml, got {_local(root.tag)}")
        placemarks = [el for el in root.iter() if _local(el.tag) == "Placemark"]
        if not placemarks:
            raise WorldError("no Placemark: nothing to read")
        features: list[MapFeature] = []
        for i, placemark in enumerate(placemarks):
            features += _placemark_features(placemark, i)
    except WorldError as exc:
        raise WorldError(f"{source}: {exc}") from None
    documents = [el for el in root.iter() if _local(el.tag) == "Document"]
    name = (_child_text(documents[0], "name") if documents else None) or default_name or source
    return MapDocument(source=source, name=name, features=tuple(features))
