"""The `cama` SRE protocol on hand-made images and polylines, beside the `strict` one where they differ."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cama_pipeline.data import CameraCalibration, CameraImage, Pose
from cama_pipeline.evaluate.inputs import VectorElement
from cama_pipeline.evaluate.projection import ProjectedPiece
from cama_pipeline.evaluate.sre import ProjectedInstance, SreConfig, extract_instances, match_image
from cama_pipeline.evaluate.sre_cama_config import CamaProtocolConfig
from cama_pipeline.evaluate.sre_cama_geometry import normal_distances, pixel_polyline, spline_normals
from cama_pipeline.evaluate.sre_cama_protocol import (
    CamaProjection,
    crop_to_ego,
    densify_map,
    match_cama,
    project_camera,
    resample_mask,
)
from cama_pipeline.evaluate.sre_report import ImageSre, summarise

W, H = 960, 540
CAMA = CamaProtocolConfig()
STRICT = SreConfig()


def line_mask(row: int, cols: tuple[int, int], value: int = 3001) -> np.ndarray:
    """An instance mask with one horizontal 3-px-wide marking."""
    mask = np.zeros((H, W), np.uint16)
    mask[row - 1 : row + 2, cols[0] : cols[1]] = value
    return mask


def cama_projection(element_id: str, row: float, cols: tuple[float, float]) -> CamaProjection:
    """A horizontal projected divider as CAMA's code sees it: the integer pixels it passes through."""
    u = np.linspace(cols[0], cols[1], 4000)
    return CamaProjection(element_id, pixel_polyline(np.column_stack([u, np.full_like(u, row)]), W, H))


def strict_projection(element_id: str, row: float, cols: tuple[float, float]) -> ProjectedInstance:
    """The same divider for the strict protocol (closed ends: the map ends there)."""
    piece = ProjectedPiece(np.array([[cols[0], row], [cols[1], row]]), False, False)
    return ProjectedInstance(element_id, "divider", (piece,))


def cama_image(projections: list[CamaProjection], mask: np.ndarray) -> ImageSre:
    """Score one image under the cama protocol."""
    instances = extract_instances(mask, {3}, CAMA.min_points)
    match = match_cama(projections, instances, CAMA)
    return ImageSre("s", "f", "CAM_FRONT", "img", W, match, require_match=True)


def strict_image(projected: list[ProjectedInstance], mask: np.ndarray) -> ImageSre:
    """Score one image under the strict protocol."""
    instances = extract_instances(mask, {3}, STRICT.min_skeleton_px)
    return ImageSre("s", "f", "CAM_FRONT", "img", W, match_image(projected, instances, STRICT, W))


def test_shorter_proposal_costs_nothing_beyond_its_end_in_cama_only() -> None:
    mask = line_mask(200, (100, 800))  # the painted line runs to column 800, the proposal stops at 700
    cama = cama_image([cama_projection("a", 203.5, (100, 700))], mask)
    strict = strict_image([strict_projection("a", 203.0, (100, 700))], mask)
    assert cama.sre_px == pytest.approx(3.0, abs=0.05)
    assert strict.sre_px is not None and strict.sre_px > 8.0  # skeleton pixels past column 700 count
    full = cama_image([cama_projection("a", 203.5, (100, 800))], mask)
    assert full.sre_px == pytest.approx(3.0, abs=0.05)


@pytest.mark.parametrize("case", ["no_image_lane", "no_projected_lane", "no_match"])
def test_camera_with_lanes_on_one_side_is_skipped_in_cama_counted_in_strict(case: str) -> None:
    good_mask = line_mask(200, (100, 800))
    good_cama = cama_image([cama_projection("a", 201.5, (100, 800))], good_mask)
    good_strict = strict_image([strict_projection("a", 201.0, (100, 800))], good_mask)
    mask = np.zeros((H, W), np.uint16) if case == "no_image_lane" else good_mask
    row = {"no_image_lane": 201.0, "no_projected_lane": None, "no_match": 400.0}[case]
    cama_bad = cama_image([] if row is None else [cama_projection("b", row + 0.5, (100, 800))], mask)
    strict_bad = strict_image([] if row is None else [strict_projection("b", row, (100, 800))], mask)
    assert cama_bad.precision is None and cama_bad.recall is None and cama_bad.sre_px is None
    cama_summary = summarise([good_cama, cama_bad])
    strict_summary = summarise([good_strict, strict_bad])
    assert cama_summary.precision == 1.0 and cama_summary.recall == 1.0 and cama_summary.scored_images == 1
    assert strict_summary.f1 is not None and strict_summary.f1 < 1.0  # the bad camera counts as a miss


def test_normals_not_crossing_the_projection_once_are_ignored() -> None:
    skeleton = np.array([[u, 100.0] for u in range(100, 301)])
    normals = spline_normals(skeleton, CAMA)
    assert normals is not None and len(normals[0]) == 60
    centres = normals[0]
    # near for u < 200, beyond the +-20 px search after: only the first part is measured
    near_then_far = np.array([[100.0, 103.0], [200.0, 103.0], [200.0, 150.0], [300.0, 150.0]])
    distances = normal_distances(*normals, CAMA.search_px, near_then_far)
    assert np.allclose(distances, 3.0) and len(distances) == int((centres[:, 0] < 200).sum())
    # a polyline that doubles back crosses every normal twice: none of them counts
    doubled = np.array([[100.0, 103.0], [300.0, 103.0], [100.0, 105.0]])
    assert normal_distances(*normals, CAMA.search_px, doubled).size == 0
    # a polyline wholly beyond the search length: no pair cost, no match
    far = cama_image([cama_projection("a", 240.5, (100, 800))], line_mask(200, (100, 800)))
    assert far.match.pairs == ()


def test_pixel_polyline_is_the_distinct_floored_pixels_in_row_order() -> None:
    points = np.array([[5.7, 2.2], [5.1, 2.9], [1.5, 3.0], [0.2, 2.5], [-1.0, 1.0], [4.0, 600.0]])
    assert pixel_polyline(points, W, H).tolist() == [[0.0, 2.0], [5.0, 2.0], [1.0, 3.0]]


def forward_camera(width: int = W, height: int = H) -> CameraImage:
    """A camera at the ego origin, 1.5 m up, looking along ego x (OpenCV axes)."""
    ego_axes = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    x, y, z, w = Rotation.from_matrix(ego_axes).as_quat()
    K = np.array([[600.0, 0.0, width / 2], [0.0, 600.0, height / 2], [0.0, 0.0, 1.0]])
    calibration = CameraCalibration(
        "c", "CAM_FRONT", Pose(np.array([0.0, 0.0, 1.5]), np.array([w, x, y, z])), K, width, height
    )
    return CameraImage("img", "sample", "CAM_FRONT", 0, True, Path("img.jpg"), Pose.identity(), calibration)


def test_projections_under_ten_pixels_are_dropped() -> None:
    # both lie 20 m ahead on the ground; at 600 px focal length 1 cm is 0.3 px, 1 m is 30 px
    short = np.column_stack([np.full(50, 20.0), np.linspace(0.0, 0.2, 50), np.zeros(50)])
    long = np.column_stack([np.full(50, 20.0), np.linspace(2.0, 3.0, 50), np.zeros(50)])
    points = np.vstack([short, long])
    owner = np.repeat([0, 1], 50)
    projections = project_camera(points, owner, ("short", "long"), forward_camera(), CAMA)
    assert [p.element_id for p in projections] == ["long"]
    assert len(projections[0].polyline_px) >= CAMA.min_points


def test_crop_keeps_the_ego_box_and_gives_flat_elements_the_ego_height() -> None:
    ego_at = Pose(np.array([100.0, 200.0, 5.0]), np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]))
    # ego x points along global +y (yaw 90 deg): ego (x, y) = (global y - 200, 100 - global x)
    inside = VectorElement("in", "divider", np.array([[100.0, 249.0], [100.0, 250.5]]))
    sideways = VectorElement("side", "divider", np.array([[199.0, 200.0], [201.0, 200.0], [201.0, 200.01]]))
    dense = densify_map([inside, sideways], CamaProtocolConfig(densify_m=0.5))
    ego, owner = crop_to_ego(dense, ego_at, CamaProtocolConfig())
    assert np.all(ego[:, 0] <= 50.0) and np.all(ego[:, 1] >= -100.0)
    assert ego[owner == 0, 0].tolist() == pytest.approx([49.0, 49.5, 50.0])  # the box is closed
    assert ego[owner == 1, 1].tolist() == pytest.approx([-99.0, -99.5, -100.0])
    assert np.allclose(ego[:, 2], 0.0)


def test_masks_are_resampled_to_960x540_with_the_scaled_pinhole() -> None:
    small = forward_camera(480, 270)
    mask = np.zeros((270, 480), np.uint16)
    mask[100:103, 50:60] = 3001
    big = resample_mask(mask, small, CAMA)
    rows, cols = np.nonzero(big == 3001)
    # target pixel (u, v) samples source (u / 2, v / 2), OpenCV's nearest rounds halves to even, as in CAMA's remap
    assert big.shape == (H, W) and (rows.min(), rows.max()) == (199, 205)
    assert (cols.min(), cols.max()) == (99, 118)
