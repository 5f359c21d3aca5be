"""MapElement, Georeference and AnnotationSet: validation messages that name the field, and JSON round trips."""

import json
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from annotations import AnnotationSet, Georeference, MapElement
from cama_pipeline.bev import GEOREFERENCE_FILE, RasterGeoreference
from tests.annotations.annotation_helpers import SQUARE, element_kwargs

NAN = float("nan")


def _messages(error: ValidationError) -> list[str]:
    """Each error as 'loc: message' so a test can check which field it names."""
    return [".".join(map(str, e["loc"])) + ": " + e["msg"] for e in error.errors()]


BAD_ELEMENTS: list[tuple[str, dict[str, Any], str, str]] = [
    ("nan", {"points_2d": [[0.0, 0.0], [NAN, 1.0]]}, "points_2d", "not finite"),
    ("inf", {"points_2d": [[0.0, 0.0], [1.0, float("inf")]]}, "points_2d", "not finite"),
    ("one point", {"points_2d": [[0.0, 0.0]]}, "points_2d", "at least 2 points"),
    ("zero length", {"points_2d": [[1.0, 1.0], [1.0, 1.0]]}, "points_2d", "zero length"),
    (
        "self-intersecting crosswalk",
        {"class": "ped_crossing", "points_2d": [[0, 0], [2, 2], [2, 0], [0, 2], [0, 0]]},
        "points_2d",
        "crosses itself",
    ),
    ("open crosswalk", {"class": "ped_crossing", "points_2d": SQUARE[:-1]}, "points_2d", "not closed"),
    (
        "flat crosswalk",
        {"class": "ped_crossing", "points_2d": [[0, 0], [1, 0], [1, 0], [0, 0]]},
        "points_2d",
        "polygon",
    ),
    ("unknown class", {"class": "lane"}, "class", "divider"),
    (
        "confidence above 1",
        {"source": "proposal", "confidence": 1.5},
        "confidence",
        "less than or equal to 1",
    ),
    (
        "confidence below 0",
        {"source": "proposal", "confidence": -0.1},
        "confidence",
        "greater than or equal to 0",
    ),
    ("confidence nan", {"source": "proposal", "confidence": NAN}, "confidence", ""),
    ("proposal without confidence", {"source": "proposal"}, "confidence", "required"),
    ("unknown source", {"source": "robot"}, "source", ""),
    ("unknown review state", {"review_state": "done"}, "review_state", ""),
    ("version 0", {"version": 0}, "version", "greater than or equal to 1"),
    ("empty id", {"id": ""}, "id", ""),
    ("3d nan", {"points_3d": [[0.0, 0.0, 1.0], [1.0, 0.0, NAN]]}, "points_3d", "not finite"),
    ("3d wrong arity", {"points_3d": [[0.0, 0.0], [1.0, 0.0]]}, "points_3d", ""),
    ("unknown field", {"colour": "yellow"}, "colour", ""),
    (
        "updated before created",
        {"updated_at": datetime(2024, 4, 1, tzinfo=UTC)},
        "updated_at",
        "before created_at",
    ),
]


@pytest.mark.parametrize(
    ("changes", "field", "text"), [b[1:] for b in BAD_ELEMENTS], ids=[b[0] for b in BAD_ELEMENTS]
)
def test_bad_element_is_rejected_naming_the_field(changes: dict[str, Any], field: str, text: str) -> None:
    with pytest.raises(ValidationError) as info:
        MapElement.model_validate(element_kwargs(**changes))
    messages = _messages(info.value)
    assert any(field in m and text in m for m in messages), messages


def test_valid_elements_and_defaults() -> None:
    proposal = MapElement.model_validate(element_kwargs(source="proposal", confidence=0.25, author=None))
    assert proposal.review_state == "proposed" and proposal.version == 1
    crossing = MapElement.model_validate(element_kwargs(**{"class": "ped_crossing", "points_2d": SQUARE}))
    assert crossing.closed and not proposal.closed
    assert crossing.xy().shape == (5, 2) and crossing.xyz() is None


def test_element_accepts_field_name_and_serialises_alias() -> None:
    element = MapElement(id="a", cls="boundary", points_2d=[(0.0, 0.0), (1.0, 0.0)], source="human")
    dumped = element.model_dump(mode="json")
    assert dumped["class"] == "boundary" and "cls" not in dumped
    assert element.created_at.tzinfo is not None


def test_element_json_round_trip() -> None:
    element = MapElement.model_validate(
        element_kwargs(points_3d=[[0.0, 0.0, 1.5], [10.0, 2.0, 1.25]], source="proposal", confidence=0.7)
    )
    text = element.model_dump_json()
    assert '"class":"divider"' in text
    assert MapElement.model_validate_json(text) == element


def test_times_are_stored_in_utc() -> None:
    plus_two = timezone(timedelta(hours=2))
    element = MapElement.model_validate(
        element_kwargs(
            created_at=datetime(2024, 5, 1, 14, 0, tzinfo=plus_two), updated_at=datetime(2024, 5, 1, 12, 30)
        )
    )
    assert element.created_at == datetime(2024, 5, 1, 12, 0, tzinfo=UTC)
    assert element.created_at.utcoffset() == timedelta(0)
    assert element.updated_at.tzinfo is UTC


def test_with_changes_revalidates() -> None:
    element = MapElement.model_validate(element_kwargs())
    moved = element.with_changes(points_2d=[(1.0, 1.0), (2.0, 2.0)], version=2)
    assert moved.version == 2 and moved.id == element.id
    with pytest.raises(ValidationError, match="points_2d"):
        element.with_changes(points_2d=[(1.0, 1.0)])
    with pytest.raises(ValidationError):
        element.with_changes(cls="ped_crossing")  # a 3-point open polyline is not a crosswalk polygon


def test_georeference_from_raster_georeference_and_back(georef: Georeference) -> None:
    raster = {
        "origin_xy": [342.0, 1155.0],
        "resolution": 0.1,
        "width": 1674,
        "height": 1351,
        "frame": "global",
        "row_axis": "-y",
        "col_axis": "+x",
    }
    built = Georeference.of(RasterGeoreference.from_json(raster), site_origin_xy=(412.0, 1085.0))
    assert built.shape == (1351, 1674)
    assert built.to_json() == raster
    assert built.as_raster() == RasterGeoreference.from_json(raster)
    assert list(json.loads(built.model_dump_json())) == ["site_origin_xy", *raster]  # the stored key order


def test_georeference_writes_only_the_raster_fields(tmp_path: Path) -> None:
    fixture = Path(__file__).parents[1] / "bev_fixture" / GEOREFERENCE_FILE
    raster = RasterGeoreference.read(fixture)
    annotation_geo = Georeference.of(raster, site_origin_xy=(1.0, 2.0))
    annotation_geo.write(tmp_path / GEOREFERENCE_FILE)
    assert (tmp_path / GEOREFERENCE_FILE).read_bytes() == fixture.read_bytes()
    assert annotation_geo.as_raster() == raster and type(annotation_geo.as_raster()) is RasterGeoreference


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"resolution": 0.0}, "resolution"),
        ({"width": 0}, "width"),
        ({"origin_xy": [float("nan"), 0.0]}, "origin_xy"),
        ({"row_axis": "+y"}, "row_axis"),
        ({"extra": 1}, "extra"),
    ],
)
def test_bad_georeference_is_rejected(changes: dict[str, Any], field: str) -> None:
    raster = {"origin_xy": [0.0, 0.0], "resolution": 0.1, "width": 10, "height": 10, **changes}
    with pytest.raises(ValidationError) as info:
        Georeference.model_validate({**raster, "site_origin_xy": (0.0, 0.0)})
    assert any(field in m for m in _messages(info.value))


def _annotation_set(georef: Georeference) -> AnnotationSet:
    """A set with two dividers and a crosswalk."""
    elements = [
        MapElement.model_validate(element_kwargs(id="d1")),
        MapElement.model_validate(element_kwargs(id="d2", source="proposal", confidence=0.4)),
        MapElement.model_validate(
            element_kwargs(**{"id": "c1", "class": "ped_crossing", "points_2d": SQUARE})
        ),
    ]
    return AnnotationSet(site_id="site-1", georeference=georef, elements=elements)


def test_annotation_set_helpers(georef: Georeference) -> None:
    annotation_set = _annotation_set(georef)
    assert [e.id for e in annotation_set.by_class("divider")] == ["d1", "d2"]
    assert annotation_set.by_class("boundary") == []
    assert annotation_set.by_id("c1").cls == "ped_crossing"
    with pytest.raises(KeyError, match="nope"):
        annotation_set.by_id("nope")
    with pytest.raises(ValueError, match="cls"):
        annotation_set.by_class("lane")  # type: ignore[arg-type]
    changed = annotation_set.upsert(annotation_set.by_id("d1").with_changes(version=2))
    assert changed.by_id("d1").version == 2 and len(changed.elements) == 3
    assert annotation_set.by_id("d1").version == 1
    added = annotation_set.upsert(MapElement.model_validate(element_kwargs(id="b1", **{"class": "boundary"})))
    assert [e.id for e in added.elements] == ["d1", "d2", "c1", "b1"]
    assert [e.id for e in added.remove("d2").elements] == ["d1", "c1", "b1"]


def test_annotation_set_rejects_duplicate_ids(georef: Georeference) -> None:
    element = MapElement.model_validate(element_kwargs())
    with pytest.raises(ValidationError, match="duplicate element id 'el-1'"):
        AnnotationSet(site_id="s", georeference=georef, elements=[element, element])


def test_annotation_set_json_round_trip(georef: Georeference, tmp_path: Path) -> None:
    annotation_set = _annotation_set(georef)
    assert AnnotationSet.model_validate_json(annotation_set.model_dump_json()) == annotation_set
    path = tmp_path / "annotations.json"
    annotation_set.write_json(path)
    assert AnnotationSet.read_json(path) == annotation_set
    path.write_text(path.read_text().replace('"ped_crossing"', '"lane"'))
    with pytest.raises(ValueError, match="annotations.json"):
        AnnotationSet.read_json(path)
