"""The Lanelet2 export: the written OSM file loaded with the `lanelet2` package itself, point by point.

`lanelet2` is imported plainly (not through require_module): it is a dependency of the export, so a missing one
is a collection error here, locally and under CI alike.
"""

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import lanelet2
import lanelet2.io
import numpy as np
import pytest

from annotations import AnnotationSet, Georeference, MapElement
from annotations.kerb_evidence import kerb_evidence
from annotations.lanelet2_format import Lanelet2Result, MapProjection, export_lanelet2, origin_projector
from tests.annotations.annotation_helpers import SITE_ORIGIN_XY, SQUARE, element_kwargs
from tests.annotations.kerb_helpers import kerb_raster, kerb_set

BOSTON = (42.336849169438615, -71.05785369873047)
SINGAPORE = (1.2882100868743724, 103.78475189208984)
TOLERANCE_M = 1e-3
BOUNDARY = {"class": "boundary"}
CROSSING = {"class": "ped_crossing"}


def lifted(points_2d: list[list[float]], z0: float) -> list[list[float]]:
    """3D points over the 2D ones, z rising along the element (a ring's closing point keeps its first z)."""
    zs = [z0 + 0.01 * index for index in range(len(points_2d))]
    if points_2d[0] == points_2d[-1]:
        zs[-1] = zs[0]
    return [[x, y, z] for (x, y), z in zip(points_2d, zs, strict=True)]


@pytest.fixture()
def annotation_set(georef: Georeference) -> AnnotationSet:
    """One element per class, all lifted, plus an unlifted boundary."""
    divider_2d = [[0.0, 0.0], [5.0, 0.0], [10.0, 2.0], [15.5, 2.25]]
    kerb_2d = [[0.0, 6.0], [7.5, 6.5], [19.0, 7.0]]
    unlifted_2d = [[0.0, -6.0], [19.0, -6.5]]
    return AnnotationSet(
        site_id="s",
        georeference=georef,
        elements=[
            MapElement(**element_kwargs(id="div", points_2d=divider_2d, points_3d=lifted(divider_2d, 2.0))),
            MapElement(
                **element_kwargs(id="kerb", points_2d=kerb_2d, points_3d=lifted(kerb_2d, 2.2), **BOUNDARY)
            ),
            MapElement(**element_kwargs(id="flat", points_2d=unlifted_2d, **BOUNDARY)),
            MapElement(
                **element_kwargs(id="zebra", points_2d=SQUARE, points_3d=lifted(SQUARE, 1.9), **CROSSING)
            ),
        ],
    )


def global_xyz(element: MapElement) -> np.ndarray:
    """What the file should hold for an element: global x, y (site + origin) and its z (0 when unlifted)."""
    xyz = element.xyz()
    if xyz is None:
        xyz = np.column_stack([element.xy(), np.zeros(len(element.points_2d))])
    return xyz + np.array([*SITE_ORIGIN_XY, 0.0])


def load(
    path: Path, origin: tuple[float, float], projection: MapProjection = MapProjection.utm
) -> lanelet2.core.LaneletMap:
    """The file loaded by lanelet2 with the export's projector; no load errors."""
    lanelet_map, errors = lanelet2.io.loadRobust(str(path), origin_projector(origin, projection))
    assert errors == []
    return lanelet_map


def linestrings(lanelet_map: lanelet2.core.LaneletMap) -> dict[str, lanelet2.core.LineString3d]:
    return {ls.attributes["cama:id"]: ls for ls in lanelet_map.lineStringLayer}


def xyz_of(linestring: lanelet2.core.LineString3d) -> np.ndarray:
    return np.array([[point.x, point.y, point.z] for point in linestring])


def test_every_point_loads_back_within_a_millimetre(annotation_set: AnnotationSet, tmp_path: Path) -> None:
    out = tmp_path / "map.osm"
    export_lanelet2(annotation_set, out, origin_lat_lon=BOSTON)
    loaded = linestrings(load(out, BOSTON))
    assert sorted(loaded) == sorted(element.id for element in annotation_set.elements)
    for element in annotation_set.elements:
        expected = global_xyz(element)
        got = xyz_of(loaded[element.id])
        if element.closed and not np.allclose(got, expected, atol=TOLERANCE_M):
            expected = expected[::-1]  # the ring is written clockwise
        assert got.shape == expected.shape, element.id
        np.testing.assert_allclose(got, expected, atol=TOLERANCE_M, rtol=0, err_msg=element.id)
        local = np.array(
            [[float(p.attributes["local_x"]), float(p.attributes["local_y"])] for p in loaded[element.id]]
        )
        np.testing.assert_allclose(local, expected[:, :2], atol=1e-6, rtol=0, err_msg=element.id)


def test_tags_per_class_and_the_counts(annotation_set: AnnotationSet, tmp_path: Path) -> None:
    out = tmp_path / "map.osm"
    result = export_lanelet2(annotation_set, out, origin_lat_lon=BOSTON)
    assert result == Lanelet2Result(
        out,
        {"line_thin": 1, "curbstone": 2, "road_border": 0, "crosswalk": 1},
        nodes=4 + 3 + 2 + 4,
        unlifted=("flat",),
        kerbs={"observed": 0, "none": 0, "assumed": 2},
    )
    lanelet_map = load(out, BOSTON)
    tags = {key: dict(ls.attributes) for key, ls in linestrings(lanelet_map).items()}
    assert tags["div"]["type"] == "line_thin"
    assert "subtype" not in tags["div"]  # no marking pattern in the model: not guessed
    assert tags["div"]["cama:marking_pattern"] == "unknown"
    for kerb in ("kerb", "flat"):
        assert (tags[kerb]["type"], tags[kerb]["subtype"], tags[kerb]["cama:kerb"]) == (
            "curbstone",
            "high",
            "assumed",
        )
    assert tags["zebra"]["type"] == "zebra_marking"
    assert {key: tag["cama:lifted"] for key, tag in tags.items()} == {
        "div": "yes",
        "kerb": "yes",
        "flat": "no",
        "zebra": "yes",
    }
    assert all(tag["cama:source"] == "human" and tag["cama:class"] for tag in tags.values())
    areas = list(lanelet_map.areaLayer)
    assert len(areas) == 1 and len(lanelet_map.laneletLayer) == 0  # boundaries and crosswalks, no lanelets
    area = dict(areas[0].attributes)
    assert (area["type"], area["subtype"], area["cama:id"]) == ("multipolygon", "crosswalk", "zebra")


def test_the_crosswalk_is_a_closed_clockwise_ring(annotation_set: AnnotationSet, tmp_path: Path) -> None:
    out = tmp_path / "map.osm"
    export_lanelet2(annotation_set, out, origin_lat_lon=BOSTON)
    (way,) = [w for w in ET.parse(out).getroot().iter("way") if _tag(w, "cama:id") == "zebra"]
    refs = [nd.get("ref") for nd in way.iter("nd")]
    assert refs[0] == refs[-1] and len(set(refs)) == len(SQUARE) - 1
    (area,) = load(out, BOSTON).areaLayer
    (outer,) = area.outerBound
    ring = xyz_of(outer)
    np.testing.assert_allclose(ring[0], ring[-1], atol=0)
    x, y = ring[:-1, 0], ring[:-1, 1]
    assert np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) < 0  # clockwise, as Lanelet2 wants


def _tag(element: ET.Element, key: str) -> str | None:
    return next((tag.get("v") for tag in element.iter("tag") if tag.get("k") == key), None)


def node_table(path: Path) -> dict[str, tuple[str, ...]]:
    """node id -> (lat, lon, ele, local_x, local_y) as written."""
    return {
        node.get("id", ""): (
            node.get("lat", ""),
            node.get("lon", ""),
            *(_tag(node, key) or "" for key in ("ele", "local_x", "local_y")),
        )
        for node in ET.parse(path).getroot().iter("node")
    }


def test_the_origin_moves_lat_lon_but_not_the_local_coordinates(
    annotation_set: AnnotationSet, tmp_path: Path
) -> None:
    boston, singapore = tmp_path / "boston.osm", tmp_path / "singapore.osm"
    export_lanelet2(annotation_set, boston, origin_lat_lon=BOSTON)
    export_lanelet2(annotation_set, singapore, origin_lat_lon=SINGAPORE)
    at_boston, at_singapore = node_table(boston), node_table(singapore)
    assert at_boston.keys() == at_singapore.keys()
    for node_id, (lat, lon, *local) in at_boston.items():
        assert local == list(at_singapore[node_id][2:])
        assert abs(float(lat) - BOSTON[0]) < 0.01 and abs(float(lon) - BOSTON[1]) < 0.01
        assert abs(float(at_singapore[node_id][0]) - SINGAPORE[0]) < 0.01
    for one, other in ((boston, BOSTON), (singapore, SINGAPORE)):
        points = {key: xyz_of(ls) for key, ls in linestrings(load(one, other)).items()}
        np.testing.assert_allclose(points["div"], global_xyz(annotation_set.by_id("div")), atol=TOLERANCE_M)


def test_ids_are_positive_unique_and_the_file_deterministic(
    annotation_set: AnnotationSet, tmp_path: Path
) -> None:
    first, second = tmp_path / "a.osm", tmp_path / "b.osm"
    export_lanelet2(annotation_set, first, origin_lat_lon=BOSTON)
    export_lanelet2(annotation_set, second, origin_lat_lon=BOSTON)
    assert first.read_bytes() == second.read_bytes()
    root = ET.parse(first).getroot()
    ids = [int(item.get("id", "0")) for kind in ("node", "way", "relation") for item in root.iter(kind)]
    assert ids == list(range(1, len(ids) + 1))


@pytest.mark.parametrize(
    "origin", [(91.0, 0.0), (-90.5, 10.0), (float("nan"), 0.0), (45.0, 180.5), (45.0, float("inf"))]
)
def test_a_bad_origin_is_refused_naming_it(
    annotation_set: AnnotationSet, tmp_path: Path, origin: tuple[float, float]
) -> None:
    out = tmp_path / "map.osm"
    with pytest.raises(ValueError, match="origin_lat_lon"):
        export_lanelet2(annotation_set, out, origin_lat_lon=origin)
    assert list(tmp_path.iterdir()) == []


def test_a_point_far_from_the_origin_is_refused_naming_the_element(
    georef: Georeference, tmp_path: Path
) -> None:
    utm_like = georef.model_copy(update={"site_origin_xy": (330_000.0, 4_690_000.0)})
    far = AnnotationSet(site_id="s", georeference=utm_like, elements=[MapElement(**element_kwargs(id="far"))])
    with pytest.raises(ValueError, match="element 'far'.*origin_lat_lon"):
        export_lanelet2(far, tmp_path / "map.osm", origin_lat_lon=BOSTON)
    assert list(tmp_path.iterdir()) == []


def test_require_lifted_refuses_unlifted_elements_naming_them(
    annotation_set: AnnotationSet, tmp_path: Path
) -> None:
    with pytest.raises(ValueError, match="'flat'"):
        export_lanelet2(annotation_set, tmp_path / "map.osm", origin_lat_lon=BOSTON, require_lifted=True)
    assert list(tmp_path.iterdir()) == []


def test_an_empty_set_is_an_empty_map_that_loads(georef: Georeference, tmp_path: Path) -> None:
    out = tmp_path / "map.osm"
    result = export_lanelet2(AnnotationSet(site_id="s", georeference=georef), out, origin_lat_lon=BOSTON)
    assert result.counts == {"line_thin": 0, "curbstone": 0, "road_border": 0, "crosswalk": 0}
    assert result.nodes == 0
    assert len(load(out, BOSTON).lineStringLayer) == 0


def test_kerbs_from_the_semantic_raster_become_curbstone_or_road_border(tmp_path: Path) -> None:
    annotations = kerb_set()
    kerbs = kerb_evidence(annotations, kerb_raster()).verdicts
    out = tmp_path / "map.osm"
    result = export_lanelet2(annotations, out, origin_lat_lon=BOSTON, kerbs=kerbs)
    assert result.counts == {"line_thin": 1, "curbstone": 3, "road_border": 1, "crosswalk": 0}
    assert result.kerbs == {"observed": 1, "none": 1, "assumed": 2}
    tags = {key: dict(ls.attributes) for key, ls in linestrings(load(out, BOSTON)).items()}
    assert (tags["kerb"]["type"], tags["kerb"]["subtype"], tags["kerb"]["cama:kerb"]) == (
        "curbstone",
        "high",
        "observed",
    )
    assert (tags["border"]["type"], tags["border"]["cama:kerb"]) == ("road_border", "none")
    assert "subtype" not in tags["border"]
    for unseen in (
        "hidden",
        "inside",
    ):  # no evidence either way: the assumed kerb of an export without raster
        assert (tags[unseen]["type"], tags[unseen]["subtype"], tags[unseen]["cama:kerb"]) == (
            "curbstone",
            "high",
            "assumed",
        )
    assert tags["div"]["type"] == "line_thin" and "cama:kerb" not in tags["div"]
    without = export_lanelet2(annotations, tmp_path / "plain.osm", origin_lat_lon=BOSTON)
    assert without.kerbs == {"observed": 0, "none": 0, "assumed": 4}


@pytest.mark.parametrize(
    ("kerbs", "message"),
    [({"div": "observed"}, "'div' is not a boundary"), ({"kerb": "maybe"}, "verdict 'maybe'")],
)
def test_bad_kerb_verdicts_are_refused_naming_them(
    tmp_path: Path, kerbs: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValueError, match=f"kerbs: element .*{message}"):
        export_lanelet2(kerb_set(), tmp_path / "map.osm", origin_lat_lon=BOSTON, kerbs=kerbs)
    assert list(tmp_path.iterdir()) == []


def sphere_lat_lon(origin: tuple[float, float], east_m: float, north_m: float) -> tuple[float, float]:
    """The nuScenes devkit's derivation of a map point's latitude, longitude: the great-circle destination from
    the location's origin, bearing atan2(east, north) and distance |(east, north)|, on a sphere of the WGS84
    equatorial radius (written here from the spherical destination formula)."""
    radius_m = 6_378_137.0
    lat0, lon0 = np.radians(origin)
    bearing, angle = np.arctan2(east_m, north_m), np.hypot(east_m, north_m) / radius_m
    lat = np.arcsin(np.sin(lat0) * np.cos(angle) + np.cos(lat0) * np.sin(angle) * np.cos(bearing))
    lon = lon0 + np.arctan2(
        np.sin(bearing) * np.sin(angle) * np.cos(lat0), np.cos(angle) - np.sin(lat0) * np.sin(lat)
    )
    return float(np.degrees(lat)), float(np.degrees(lon))


def far_set(georef: Georeference, east_m: float, north_m: float) -> AnnotationSet:
    """One lifted divider from the global frame's (0, 0) to (east_m, north_m)."""
    site_xy = [
        [-SITE_ORIGIN_XY[0], -SITE_ORIGIN_XY[1]],
        [east_m - SITE_ORIGIN_XY[0], north_m - SITE_ORIGIN_XY[1]],
    ]
    element = MapElement(**element_kwargs(id="far", points_2d=site_xy, points_3d=lifted(site_xy, 0.0)))
    return AnnotationSet(site_id="s", georeference=georef, elements=[element])


@pytest.mark.parametrize("origin", [BOSTON, SINGAPORE])
def test_a_local_projection_keeps_the_frames_north_where_utm_turns_it(
    georef: Georeference, tmp_path: Path, origin: tuple[float, float]
) -> None:
    """A point 1 km east of a nuScenes origin: in the local frame it stays on the origin's parallel (within the
    Earth's curvature, 8 cm) and lies where the devkit's sphere puts it within its 0.67 % radius error; the UTM
    grid puts it 24 m north at Boston (meridian convergence), 0.5 m in Singapore."""
    east = far_set(georef, 1000.0, 0.0)
    local, utm = tmp_path / "local.osm", tmp_path / "utm.osm"
    result = export_lanelet2(east, local, origin_lat_lon=origin, projection=MapProjection.local)
    assert result.projection is MapProjection.local
    export_lanelet2(east, utm, origin_lat_lon=origin)
    metres_per_degree = 111_132.0
    (lat0, lon0, *_), (lat_local, lon_local, *_) = node_table(local).values()
    assert (float(lat0), float(lon0)) == pytest.approx(origin, abs=1e-9)
    assert abs(float(lat_local) - origin[0]) * metres_per_degree < 0.1
    sphere_lat, sphere_lon = sphere_lat_lon(origin, 1000.0, 0.0)
    east_error_m = (float(lon_local) - sphere_lon) * metres_per_degree * np.cos(np.radians(origin[0]))
    assert abs(float(lat_local) - sphere_lat) * metres_per_degree < 0.1 and abs(east_error_m) < 6.7
    lat_utm = float(list(node_table(utm).values())[1][0])
    expected_turn_m = 24.0 if origin == BOSTON else 0.5
    assert abs(lat_utm - origin[0]) * metres_per_degree == pytest.approx(expected_turn_m, rel=0.05)
    points = xyz_of(linestrings(load(local, origin, MapProjection.local))["far"])
    written = global_xyz(east.by_id("far"))
    np.testing.assert_allclose(points[:, :2], written[:, :2], atol=TOLERANCE_M)
    curvature_drop_m = np.hypot(*written[:, :2].T) ** 2 / (2 * 6_371_000.0)  # `ele` is the map's height
    np.testing.assert_allclose(points[:, 2], written[:, 2] - curvature_drop_m, atol=0.005)


def test_an_unknown_projection_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="projection: 'mercator' is not one of"):
        origin_projector(BOSTON, "mercator")  # type: ignore[arg-type]
