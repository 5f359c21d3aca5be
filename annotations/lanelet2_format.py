"""Lanelet2 export: the annotation set as one OSM XML file with Lanelet2's tagging (boundaries and crosswalks).

The map holds linestrings and areas only, no lanelets: a lanelet (a drivable lane with a left and a right bound,
its direction, topology and speed limit) needs lane-level structure the annotation model does not hold. The file
is a valid map that `lanelet2.io.load` reads, but it is not routable.

What each class becomes (tag values lowercase, as Lanelet2 asks; our own tags are prefixed `cama:`):

- `divider` -> a way `type=line_thin` with no `subtype`: the annotation model (annotations/schema.py
  `MapElement`) has no marking pattern (solid / dashed / double), so rather than guess one the way says
  `cama:marking_pattern=unknown`. Lanelet2 reads a boundary whose type it cannot resolve as one that forbids lane
  changes, the safe reading.
- `boundary` -> a way whose type says whether a kerb is there. A boundary element does not say whether a kerb
  was seen or the road just ends (VMA's `boundary_source="road_edge"` is a way of extracting boundaries from the
  rasters, not an attribute of the element); the site's semantic raster does, read by
  `annotations.kerb_evidence` and given as `kerbs` (element id -> verdict):
  `observed` -> `type=curbstone`, `subtype=high`, `cama:kerb=observed` (curb cells along it);
  `none` -> `type=road_border`, `cama:kerb=none` (Lanelet2's end of the passable area without a kerb: road on
  one side, no curb);
  `unobserved`, or no verdict (no raster) -> `type=curbstone`, `subtype=high`, `cama:kerb=assumed`: written as a
  kerb, the safe reading (nothing drives over it), and the tag says it was not seen.
- `ped_crossing` -> an area: a relation `type=multipolygon`, `subtype=crosswalk` (a subtype Lanelet2 lists for
  lanelets and areas) whose single `outer` member is a closed way `type=zebra_marking` (its first node repeated
  at its end), its points in clockwise order as Lanelet2 wants an area's outer bound (a counter-clockwise ring is
  written reversed). An area rather than a lanelet of subtype crosswalk, because our crosswalk is a polygon: a lanelet
  needs a left and a right bound, which would mean guessing which sides of the ring run kerb to kerb.

Every way (and the crosswalk relation) carries `cama:id` (the element id); ways also carry `cama:class`,
`cama:source`, `cama:review_state` and `cama:lifted` (`yes` / `no`).

Coordinates. `origin_lat_lon` is the geographic position of the (0, 0) of the site's global frame (the frame
of `site_origin_xy`: global = site + site_origin_xy, z global); a point more than `MAX_FROM_ORIGIN_M` from
that (0, 0) is refused (ValueError), since the frame is then not one anchored at the origin. `projection` says
how the frame's x, y lie on the Earth (`MapProjection`):

- `local`: a local tangent plane at the origin, x east, y north (`lanelet2.projection.LocalCartesianProjector`, on
  the WGS84 ellipsoid): the frame of a map made in local metres around a reference point, as nuScenes' maps are
  (`cama_pipeline.data.map_origins` holds their origins). The nuScenes devkit derives its poses' latitude and
  longitude from the same origins on a sphere of the equatorial radius; this frame differs from that derivation
  by up to 0.22 % of the distance from the origin at boston-seaport (1.5 m east, 2.2 m north per km) and 0.67 %
  in Singapore (6.7 m north per km), the sphere's error, not this frame's.
- `utm`: the UTM grid's easting and northing at the origin (`lanelet2.projection.UtmProjector`): the frame of a
  map made in UTM coordinates less the origin's. Grid north differs from true north by the meridian convergence
  (about 1.4 degrees at boston-seaport: 24 m at 1 km if a local frame were written this way); the grid's scale is
  within 0.04 % of true.

Each node has:

- `local_x`, `local_y` tags: the point's global-frame x, y in metres (site x, y + `site_origin_xy`), i.e. metres
  from the origin along the frame's axes. These are not Autoware's MGRS-grid coordinates.
- `lat`, `lon`: the projection's `reverse((local_x, local_y, z))` written with 12 decimals (about 0.1 um), so
  `lanelet2.io.load(path, <that projector at the origin>)` gives back local_x, local_y; a reader with the other
  projector gets points off by the difference above.
- `ele`: the point's lifted z (global metres): the map's height, as a site frame built from odometry and images
  is level along the Earth's surface. `UtmProjector` reads it back unchanged; `LocalCartesianProjector`, a
  Euclidean tangent frame, reads it as the altitude and gives z less the Earth's curvature drop, d^2 / 2R at
  distance d from the origin (8 cm at 1 km). An element without 3D points
  (`points_3d` None, e.g. proposals not lifted) is written at ele 0 from its 2D points with `cama:lifted=no` on
  its way and listed in `Lanelet2Result.unlifted` (and a warning is logged); `require_lifted=True` refuses such
  a set instead (ValueError naming the elements). Lifted elements take x, y, z from `points_3d`.

Ids are positive and unique across the file (Lanelet2 keeps one id space): nodes 1..N in element order, then
ways, then relations; the same set and origin give byte-identical files.
"""

import logging
import math
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Literal

import lanelet2.core
import lanelet2.io
import lanelet2.projection
import numpy as np

from annotations.kerb_evidence import KERB_VERDICTS, KerbVerdict
from annotations.schema import AnnotationSet, ElementClass, MapElement
from annotations.transforms import global_from_site_points
from cama_pipeline.io import atomic_write_bytes

logger = logging.getLogger(__name__)

Lanelet2Tag = Literal["line_thin", "curbstone", "road_border", "crosswalk"]
LANELET2_TAGS: tuple[Lanelet2Tag, ...] = ("line_thin", "curbstone", "road_border", "crosswalk")
"""What each class is counted as in `Lanelet2Result.counts` (the way's type; the area's subtype)."""

CLASS_TAG: dict[ElementClass, Lanelet2Tag] = {
    "divider": "line_thin",
    "boundary": "curbstone",
    "ped_crossing": "crosswalk",
}

WAY_TAGS: dict[ElementClass, dict[str, str]] = {
    "divider": {"type": "line_thin", "cama:marking_pattern": "unknown"},
    "boundary": {"type": "curbstone", "subtype": "high", "cama:kerb": "assumed"},
    "ped_crossing": {"type": "zebra_marking"},
}
"""Lanelet2 tags of each class's way (see the module docstring for why); a boundary's are `KERB_TAGS`'s."""

KerbTag = Literal["observed", "none", "assumed"]
KERB_TAGS: dict[KerbTag, dict[str, str]] = {
    "observed": {"type": "curbstone", "subtype": "high", "cama:kerb": "observed"},
    "none": {"type": "road_border", "cama:kerb": "none"},
    "assumed": WAY_TAGS["boundary"],
}
"""A boundary's tags by what the semantic raster says (`cama:kerb`); `assumed` where it says nothing."""
KERB_FROM_VERDICT: dict[KerbVerdict, KerbTag] = {
    "observed": "observed",
    "none": "none",
    "unobserved": "assumed",
}

AREA_TAGS: dict[str, str] = {"type": "multipolygon", "subtype": "crosswalk"}
"""Tags of a crosswalk's area relation."""

DEGREE_DECIMALS = 12
METRE_DECIMALS = 6
MAX_FROM_ORIGIN_M = 100_000.0
"""Points farther from the origin than this are refused: the global frame is then not one whose (0, 0) sits at
the origin (e.g. UTM coordinates given with a site's origin), and the projection would be meaningless."""


class MapProjection(StrEnum):
    """How the site's global frame lies on the Earth around the origin (the module docstring's Coordinates)."""

    local = "local"
    """A local tangent plane at the origin, x east, y north (nuScenes' maps)."""
    utm = "utm"
    """The UTM grid at the origin: easting, northing less the origin's."""


@dataclass(frozen=True)
class Lanelet2Result:
    """What `export_lanelet2` wrote."""

    path: Path
    """The .osm file."""
    counts: dict[str, int] = field(default_factory=dict)
    """Elements written per Lanelet2 tag: line_thin (dividers), curbstone and road_border (boundaries), crosswalk
    (areas)."""
    nodes: int = 0
    """Nodes written (a crosswalk ring's closing point is its first node again)."""
    unlifted: tuple[str, ...] = ()
    """Ids of the elements without 3D points, written at ele 0 (`cama:lifted=no`)."""
    kerbs: dict[str, int] = field(default_factory=dict)
    """Boundaries per `cama:kerb` value: observed (curbstone), none (road_border), assumed (curbstone)."""
    projection: MapProjection = MapProjection.utm
    """The projection the nodes' lat / lon were written with."""


def origin_projector(
    origin_lat_lon: tuple[float, float], projection: MapProjection = MapProjection.utm
) -> lanelet2.projection.Projector:
    """Lanelet2's projector of `projection` at the geographic origin; ValueError naming `origin_lat_lon` or
    `projection` when it is bad."""
    try:
        lat, lon = (float(value) for value in origin_lat_lon)
    except (TypeError, ValueError) as error:
        raise ValueError(f"origin_lat_lon: expected (latitude, longitude), got {origin_lat_lon!r}") from error
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ValueError(f"origin_lat_lon: latitude {lat} is not in [-90, 90] degrees")
    if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
        raise ValueError(f"origin_lat_lon: longitude {lon} is not in [-180, 180] degrees")
    try:
        kind = MapProjection(projection)
    except ValueError:
        raise ValueError(
            f"projection: {projection!r} is not one of {[choice.value for choice in MapProjection]}"
        ) from None
    projector = (
        lanelet2.projection.LocalCartesianProjector
        if kind is MapProjection.local
        else lanelet2.projection.UtmProjector
    )
    try:
        return projector(lanelet2.io.Origin(lat, lon))
    except RuntimeError as error:  # GeographicLib's own checks
        raise ValueError(f"origin_lat_lon: ({lat}, {lon}) cannot be projected: {error}") from error


def element_global_xyz(element: MapElement, site_origin_xy: tuple[float, float]) -> tuple[np.ndarray, bool]:
    """(N, 3) global points of an element (its 3D points, else its 2D points at z 0) and whether it was lifted."""
    xyz = element.xyz()
    lifted = xyz is not None
    if xyz is None:
        xyz = np.column_stack([element.xy(), np.zeros(len(element.points_2d))])
    return global_from_site_points(xyz, site_origin_xy), lifted


def _number(value: float, decimals: int) -> str:
    """A fixed-decimal string (deterministic, never '-0.000')."""
    text = f"{value:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _clockwise(ring: np.ndarray) -> np.ndarray:
    """An open ring's points in clockwise order (x east, y north), as Lanelet2 wants an area's outer bound."""
    x, y = ring[:, 0], ring[:, 1]
    twice_area = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    return np.concatenate([ring[:1], ring[:0:-1]]) if twice_area > 0 else ring  # reversed from the same start


def _tags(parent: ET.Element, tags: dict[str, str]) -> None:
    for key, value in tags.items():
        ET.SubElement(parent, "tag", k=key, v=value)


class _OsmBuilder:
    """Collects nodes, ways and relations with ids in file order (nodes, then ways, then relations)."""

    def __init__(self, projector: lanelet2.projection.Projector) -> None:
        self.projector = projector
        self.nodes: list[ET.Element] = []
        self.ways: list[tuple[list[int], dict[str, str]]] = []
        self.relations: list[tuple[int, dict[str, str]]] = []  # (way index, tags)

    def add_node(self, x: float, y: float, z: float) -> int:
        """A node at global (x, y, z); returns its id."""
        gps = self.projector.reverse(lanelet2.core.BasicPoint3d(x, y, z))
        node = ET.Element(
            "node",
            id=str(len(self.nodes) + 1),
            lat=_number(gps.lat, DEGREE_DECIMALS),
            lon=_number(gps.lon, DEGREE_DECIMALS),
        )
        _tags(node, {k: _number(v, METRE_DECIMALS) for k, v in (("ele", z), ("local_x", x), ("local_y", y))})
        self.nodes.append(node)
        return len(self.nodes)

    def add_element(
        self, element: MapElement, site_origin_xy: tuple[float, float], class_tags: dict[str, str]
    ) -> bool:
        """The element's nodes, way (`class_tags` first) and (crosswalk) area; returns whether it was lifted."""
        xyz, lifted = element_global_xyz(element, site_origin_xy)
        far = float(np.abs(xyz[:, :2]).max())
        if far > MAX_FROM_ORIGIN_M:
            raise ValueError(
                f"element {element.id!r}: a point {far:.0f} m from the global frame's (0, 0), more than "
                f"{MAX_FROM_ORIGIN_M:.0f} m: origin_lat_lon must be where that (0, 0) lies"
            )
        ring = element.closed
        points = _clockwise(xyz[:-1]) if ring else xyz  # a ring's closing point is its first node again
        refs = [self.add_node(float(x), float(y), float(z)) for x, y, z in points.tolist()]
        if ring:
            refs.append(refs[0])
        tags = {
            **class_tags,
            "cama:id": element.id,
            "cama:class": element.cls,
            "cama:source": element.source,
            "cama:review_state": element.review_state,
            "cama:lifted": "yes" if lifted else "no",
        }
        self.ways.append((refs, tags))
        if ring:
            self.relations.append((len(self.ways) - 1, {**AREA_TAGS, "cama:id": element.id}))
        return lifted

    def tree(self) -> ET.Element:
        """The <osm> element: nodes, ways, relations, with ids unique across all three."""
        root = ET.Element("osm", version="0.6", generator="cama-studio")
        root.extend(self.nodes)
        way_ids = [len(self.nodes) + 1 + index for index in range(len(self.ways))]
        for way_id, (refs, tags) in zip(way_ids, self.ways, strict=True):
            way = ET.SubElement(root, "way", id=str(way_id))
            for ref in refs:
                ET.SubElement(way, "nd", ref=str(ref))
            _tags(way, tags)
        first_relation = len(self.nodes) + len(self.ways) + 1
        for index, (way_index, tags) in enumerate(self.relations):
            relation = ET.SubElement(root, "relation", id=str(first_relation + index))
            ET.SubElement(relation, "member", type="way", ref=str(way_ids[way_index]), role="outer")
            _tags(relation, tags)
        return root


def _check_kerbs(annotations: AnnotationSet, kerbs: Mapping[str, KerbVerdict]) -> None:
    """ValueError naming `kerbs` and the element when a verdict is unknown or not about a boundary of the set."""
    boundaries = {element.id for element in annotations.by_class("boundary")}
    for element_id, verdict in kerbs.items():
        if element_id not in boundaries:
            raise ValueError(
                f"kerbs: element {element_id!r} is not a boundary of site {annotations.site_id!r}"
            )
        if verdict not in KERB_VERDICTS:
            raise ValueError(
                f"kerbs: element {element_id!r}: verdict {verdict!r} is not one of {KERB_VERDICTS}"
            )


def lanelet2_osm_bytes(
    annotations: AnnotationSet,
    *,
    origin_lat_lon: tuple[float, float],
    projection: MapProjection = MapProjection.utm,
    kerbs: Mapping[str, KerbVerdict] | None = None,
) -> tuple[bytes, Lanelet2Result]:
    """The OSM XML of the set (UTF-8, indented) and its counts (`path` left empty for the caller); `projection`
    and `kerbs` as in `export_lanelet2`."""
    kerbs = kerbs or {}
    _check_kerbs(annotations, kerbs)
    builder = _OsmBuilder(origin_projector(origin_lat_lon, projection))
    site_origin_xy = annotations.georeference.site_origin_xy
    counts: Counter[str] = Counter({tag: 0 for tag in LANELET2_TAGS})
    kerb_counts: Counter[str] = Counter({kerb: 0 for kerb in KERB_TAGS})
    unlifted = []
    for element in annotations.elements:
        tags = WAY_TAGS[element.cls]
        if element.cls == "boundary":
            kerb = KERB_FROM_VERDICT[kerbs.get(element.id, "unobserved")]
            tags = KERB_TAGS[kerb]
            kerb_counts[kerb] += 1
        if not builder.add_element(element, site_origin_xy, tags):
            unlifted.append(element.id)
        counts[tags["type"] if element.cls == "boundary" else CLASS_TAG[element.cls]] += 1
    root = builder.tree()
    ET.indent(root)
    data = ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"
    result = Lanelet2Result(
        Path(),
        {tag: counts[tag] for tag in LANELET2_TAGS},
        len(builder.nodes),
        tuple(unlifted),
        dict(kerb_counts),
        MapProjection(projection),
    )
    return data, result


def export_lanelet2(
    annotations: AnnotationSet,
    out: Path,
    *,
    origin_lat_lon: tuple[float, float],
    projection: MapProjection = MapProjection.utm,
    require_lifted: bool = False,
    kerbs: Mapping[str, KerbVerdict] | None = None,
) -> Lanelet2Result:
    """Write the set as a Lanelet2 OSM file at `out` (atomically; its folder must exist).

    `origin_lat_lon` is the latitude, longitude of the site's global frame's (0, 0) (ValueError when out of
    range), `projection` how that frame lies on the Earth around it (local: a tangent plane, as nuScenes' maps;
    utm: the UTM grid). Elements without 3D points are written at ele 0 and tagged `cama:lifted=no`, or refused with a
    ValueError naming them when `require_lifted`. `kerbs` (boundary id -> verdict, `kerb_evidence.kerb_evidence`)
    decides each boundary's type; a boundary without one, or with no mapping at all, is an assumed kerb.
    """
    out = Path(out)
    missing = [element.id for element in annotations.elements if element.points_3d is None]
    if missing and require_lifted:
        shown = ", ".join(repr(element_id) for element_id in missing[:5])
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise ValueError(f"{len(missing)} elements have no 3D points (not lifted): {shown}{more}")
    data, result = lanelet2_osm_bytes(
        annotations, origin_lat_lon=origin_lat_lon, projection=projection, kerbs=kerbs
    )
    if missing:
        logger.warning("%d elements have no 3D points: written at ele 0 with cama:lifted=no", len(missing))
    atomic_write_bytes(out, data)
    logger.info("wrote %d elements (%s) to %s", len(annotations.elements), result.counts, out)
    return Lanelet2Result(out, result.counts, result.nodes, result.unlifted, result.kerbs, result.projection)
