"""MapTR vectors export: clipping at the perception range, 20 points, metadata, import back, bad files."""

import json
from pathlib import Path

import numpy as np
import pytest

from annotations import MAPTR_RANGE, AnnotationSet, Georeference, MapElement, resample_fixed
from annotations.maptr_format import export_maptr, import_maptr, read_maptr
from annotations.poses import coarse_pose
from cama_pipeline.data import Dataset, load_dataset
from tests.annotations.annotation_helpers import element_kwargs
from tests.data.nuscenes_fixture import write_nuscenes_fixture

INSIDE = [(5.0, 2.0, 3.0), (10.0, 3.0, 3.1), (15.0, 1.0, 3.2)]
CROSSING = [(-10.0, -5.0, 3.0), (60.0, -5.0, 3.0)]


@pytest.fixture()
def dataset(tmp_path: Path) -> Dataset:
    """A one-scene, 2-sample data set; the ego starts at global (100, 200, 3), the site origin."""
    fixture = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2, with_can=False, with_lidar=False)
    return load_dataset(fixture.root)


def _element(element_id: str, points_3d: list[tuple[float, float, float]]) -> MapElement:
    """A divider with these 3D site points."""
    return MapElement.model_validate(
        element_kwargs(id=element_id, points_2d=[p[:2] for p in points_3d], points_3d=points_3d)
    )


def _export(tmp_path: Path, georef: Georeference, dataset: Dataset) -> tuple[AnnotationSet, Path]:
    """Export a set with one vector inside the range and one crossing it."""
    annotations = AnnotationSet(
        site_id="site-a", georeference=georef, elements=[_element("in", INSIDE), _element("cross", CROSSING)]
    )
    return annotations, export_maptr(annotations, dataset, tmp_path / "maptr.json", poses=coarse_pose)


def test_crossing_vector_clipped_at_boundary(tmp_path: Path, georef: Georeference, dataset: Dataset) -> None:
    """A vector leaving the range is cut at x = 30 m (ego) and resampled to 20 points."""
    _, path = _export(tmp_path, georef, dataset)
    data = read_maptr(path)
    assert [s.sample_token for s in data.samples] == [f.token for f in dataset.scenes[0].frames]
    for sample in data.samples:
        pieces = [v for v in sample.vectors if v.source_id == "cross"]
        assert len(pieces) == 1 and len(pieces[0].points) == 20
        points = np.asarray(pieces[0].points)
        assert points[:, 0].max() == pytest.approx(MAPTR_RANGE.xmax, abs=1e-9)
        assert (points[:, 0] >= MAPTR_RANGE.xmin - 1e-9).all() and (np.abs(points[:, 1]) <= 15 + 1e-9).all()


def test_metadata(tmp_path: Path, georef: Georeference, dataset: Dataset) -> None:
    """File and sample metadata: range, points per vector, scene, timestamp, ego pose = CAM_FRONT's."""
    _, path = _export(tmp_path, georef, dataset)
    raw = json.loads(path.read_text())
    assert raw["meta"]["points_per_vector"] == 20
    assert raw["meta"]["perception_range"] == {"xmin": -30.0, "xmax": 30.0, "ymin": -15.0, "ymax": 15.0}
    sample = raw["samples"][0]
    frame = dataset.scenes[0].frames[0]
    assert sample["scene"] == dataset.scenes[0].name and sample["timestamp"] == frame.timestamp_us
    pose = frame.images["CAM_FRONT"].global_from_ego
    np.testing.assert_allclose(sample["ego_pose"]["translation"], pose.translation)
    np.testing.assert_allclose(sample["ego_pose"]["rotation"], pose.rotation)
    assert {v["class"] for v in sample["vectors"]} == {"divider"}


def test_inside_vector_round_trips(tmp_path: Path, georef: Georeference, dataset: Dataset) -> None:
    """A vector inside the range comes back at its resampled points within 1e-6 m (site coordinates)."""
    _, path = _export(tmp_path, georef, dataset)
    back = import_maptr(path)
    assert back.site_id == "site-a" and back.georeference == georef
    expected = resample_fixed(np.asarray(INSIDE), 20)
    for frame in dataset.scenes[0].frames:
        element = back.by_id(f"{frame.token}/in/0")
        assert element.cls == "divider"
        np.testing.assert_allclose(element.xyz(), expected, atol=1e-6)


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (
            lambda d: d["samples"][0]["vectors"][0].update({"class": "lane"}),
            "samples[0].vectors[0].class: unknown class",
        ),
        (lambda d: d["samples"][0]["vectors"][0]["points"].pop(), "expected 20"),
        (lambda d: d["samples"][1].pop("ego_pose"), "maptr.json: samples[1].ego_pose: Field required"),
        (lambda d: d.update(samples={}), "maptr.json: samples: Input should be a valid list"),
        (lambda d: d["samples"][0]["vectors"][0]["points"][0].__setitem__(2, float("nan")), "points[0][2]"),
    ],
)
def test_bad_files_name_file_and_field(
    tmp_path: Path, georef: Georeference, dataset: Dataset, edit: object, expected: str
) -> None:
    """Unknown class, wrong point count, missing field, not a list, NaN: ValueError naming file and field."""
    _, path = _export(tmp_path, georef, dataset)
    raw = json.loads(path.read_text())
    edit(raw)  # type: ignore[operator]
    path.write_text(json.dumps(raw))
    with pytest.raises(ValueError) as caught:
        import_maptr(path)
    assert "maptr.json" in str(caught.value) and expected in str(caught.value)
