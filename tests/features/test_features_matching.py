"""Descriptor matching by matrix products: the mutual ratio test, BLAS threads, and the matcher on a database."""

from pathlib import Path

import numpy as np
import pycolmap
import pytest

from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.matching import BlasMatcher, cosines, mutual_ratio_matches


def unit_rows(rows: list[list[float]]) -> np.ndarray:
    data = np.asarray(rows, dtype=np.float32)
    return data / np.linalg.norm(data, axis=1, keepdims=True)


def test_mutual_ratio_matches_keep_only_distinct_mutual_neighbours() -> None:
    first = unit_rows([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1], [0, 0, 1, 0.9]])
    second = unit_rows([[0, 1, 0, 0.05], [1, 0.05, 0, 0], [0, 0, 1, 0.95], [0.1, 0.1, 0.1, 0.1]])
    matches = mutual_ratio_matches(first @ second.T, max_ratio=0.8, max_distance=0.7)
    # rows 2 and 3 are both close to column 2: ambiguous both ways, so neither is matched
    assert sorted(map(tuple, matches.tolist())) == [(0, 1), (1, 0)]
    assert matches.dtype == np.uint32


def test_mutual_ratio_matches_drop_far_and_one_sided_neighbours() -> None:
    first = unit_rows([[1, 0, 0], [0, 1, 0]])
    second = unit_rows([[1, 1, 0.2], [0, 0, 1]])
    cos = first @ second.T
    # row 0 and row 1 both prefer column 0 at 45 degrees: column 0 has no unique best, and 0.79 rad > 0.7
    assert len(mutual_ratio_matches(cos.copy(), max_ratio=0.8, max_distance=0.7)) == 0
    near = unit_rows([[1, 0.1, 0], [0, 1, 0.1]])
    assert len(mutual_ratio_matches(first @ near.T, max_ratio=0.8, max_distance=0.05)) == 0
    assert len(mutual_ratio_matches(first @ near.T, max_ratio=0.8, max_distance=0.7)) == 2
    assert len(mutual_ratio_matches(np.zeros((1, 5), np.float32), max_ratio=0.8, max_distance=0.7)) == 0


def test_cosines_normalise_uint8_descriptors() -> None:
    data = np.array([[3, 4, 0], [0, 0, 0]], dtype=np.uint8)
    out = cosines(data, data)
    assert out[0, 0] == pytest.approx(1.0) and out[1, 1] == 0.0


def synthetic_database(path: Path, rng: np.random.Generator) -> tuple[list[str], np.ndarray]:
    """Three 640 x 480 images; image b sees a's points shifted by 30 px (a clean translation), c is noise."""
    names = ["a.jpg", "b.jpg", "c.jpg"]
    points = rng.uniform([40, 40], [560, 440], size=(300, 2)).astype(np.float32)
    descriptors = rng.integers(0, 256, size=(300, 128)).astype(np.uint8)
    shifted = points + np.float32([30, 5])
    database = pycolmap.Database.open(str(path))
    camera = pycolmap.Camera(model="PINHOLE", width=640, height=480, params=[500, 500, 320, 240])
    camera_id = database.write_camera(camera)
    for name, xy, desc in (
        ("a.jpg", points, descriptors),
        ("b.jpg", shifted, descriptors),
        ("c.jpg", points[::-1].copy(), rng.integers(0, 256, size=(300, 128)).astype(np.uint8)),
    ):
        image_id = database.write_image(pycolmap.Image(name=name, camera_id=camera_id))
        database.write_keypoints(image_id, xy)
        database.write_descriptors(
            image_id, pycolmap.FeatureDescriptors(pycolmap.FeatureExtractorType.SIFT, desc)
        )
    database.close()
    return names, points


def test_blas_matcher_matches_verifies_and_skips_what_is_done(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "database.db"
    synthetic_database(path, np.random.default_rng(0))
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("a.jpg b.jpg\na.jpg c.jpg\n")
    matcher = BlasMatcher(FeaturesConfig(num_threads=2))
    matcher.match(path, pairs)
    database = pycolmap.Database.open(str(path))
    try:
        assert len(database.read_matches(1, 2)) == 300
        assert len(database.read_two_view_geometry(1, 2).inlier_matches) == 300
        assert len(database.read_two_view_geometry(1, 3).inlier_matches) == 0  # unrelated: rejected
    finally:
        database.close()
    matched: list[tuple[int, int]] = []

    def counting(cos: np.ndarray, **kwargs: float) -> np.ndarray:
        matched.append(cos.shape)
        return np.asarray(mutual_ratio_matches(cos, **kwargs))

    monkeypatch.setattr("cama_pipeline.features.matching.mutual_ratio_matches", counting)
    pairs.write_text("a.jpg b.jpg\na.jpg c.jpg\nb.jpg c.jpg\n")
    matcher.match(path, pairs)  # a-b verified, a-c rejected (COLMAP dropped its matches): only b-c is new
    assert len(matched) == 1
    database = pycolmap.Database.open(str(path))
    try:
        assert database.exists_two_view_geometry(2, 3)
    finally:
        database.close()


def test_blas_matcher_names_unknown_images_in_the_pair_list(tmp_path: Path) -> None:
    path = tmp_path / "database.db"
    synthetic_database(path, np.random.default_rng(1))
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("a.jpg missing.jpg\n")
    with pytest.raises(ValueError, match="missing.jpg"):
        BlasMatcher(FeaturesConfig()).match(path, pairs)
