"""SRE matching on hand-made images with known answers, and one projection -> mask -> SRE round trip."""

import cv2
import numpy as np
import pytest

from cama_pipeline.evaluate.projection import (
    PinholeCamera,
    ProjectedPiece,
    ProjectionConfig,
    project_polyline,
)
from cama_pipeline.evaluate.skeleton import skeletonize, zhang_suen_thinning
from cama_pipeline.evaluate.sre import (
    ProjectedInstance,
    SreConfig,
    extract_instances,
    match_image,
)
from cama_pipeline.evaluate.sre_report import ImageSre, SreReport, hierarchical_mean
from cama_pipeline.semantics import Semantic

W, H = 960, 540
CONFIG = SreConfig()


def mask_with_lines(rows: dict[int, int], cols: tuple[int, int] = (100, 800)) -> np.ndarray:
    """An instance mask with horizontal 3-px-wide lane markings: {instance value: centre row}."""
    mask = np.zeros((H, W), np.uint16)
    for value, row in rows.items():
        mask[row - 1 : row + 2, cols[0] : cols[1]] = value
    return mask


def line_instance(
    element_id: str, row: float, cols: tuple[float, float] = (50, 900), **ends: bool
) -> ProjectedInstance:
    """A projected horizontal divider at `row`."""
    piece = ProjectedPiece(
        np.array([[cols[0], row], [cols[1], row]]), ends.get("start_open", False), ends.get("end_open", False)
    )
    return ProjectedInstance(element_id, "divider", (piece,))


def run(projected: list[ProjectedInstance], mask: np.ndarray, config: SreConfig = CONFIG) -> ImageSre:
    """Match one image and wrap it as an ImageSre."""
    instances = extract_instances(mask, {3}, config.min_skeleton_px)
    return ImageSre("s", "f", "CAM_FRONT", "img", W, match_image(projected, instances, config, W))


@pytest.mark.parametrize("shift_px", [0, 2, 5])
def test_shifted_line_gives_sre_k(shift_px: int) -> None:
    result = run([line_instance("a", 200 + shift_px)], mask_with_lines({3001: 200}))
    assert result.sre_px == pytest.approx(shift_px, abs=0.01)  # skeleton ends may bend by a pixel
    assert result.sre_ref_px == pytest.approx(shift_px, abs=0.01)
    assert result.precision == 1.0 and result.recall == 1.0


def test_reference_scale_rescales_pixels() -> None:
    image = ImageSre(
        "s", "f", "CAM_FRONT", "img", 480, run([line_instance("a", 203)], mask_with_lines({3001: 200})).match
    )
    assert image.sre_px == pytest.approx(3.0, abs=0.01)
    assert image.sre_ref_px == pytest.approx(6.0, abs=0.02)


def test_swapped_instances_are_matched_correctly() -> None:
    mask = mask_with_lines({3001: 100, 3002: 300})
    result = run([line_instance("near_300", 303), line_instance("near_100", 98)], mask)
    assert {(p.element_id, p.instance_value) for p in result.match.pairs} == {
        ("near_300", 3002),
        ("near_100", 3001),
    }
    assert result.sre_px == pytest.approx(2.5, abs=0.01)


def test_extra_projected_instance_lowers_precision() -> None:
    mask = mask_with_lines({3001: 100, 3002: 300})
    result = run([line_instance("a", 101), line_instance("b", 301), line_instance("extra", 450)], mask)
    assert result.precision == pytest.approx(2 / 3)
    assert result.recall == 1.0


def test_missing_projected_instance_lowers_recall() -> None:
    result = run([line_instance("a", 101)], mask_with_lines({3001: 100, 3002: 300}))
    assert result.precision == 1.0
    assert result.recall == pytest.approx(0.5)


def test_gate_rejects_far_pairs() -> None:
    result = run([line_instance("a", 250)], mask_with_lines({3001: 200}))
    assert result.match.pairs == () and result.sre_px is None and result.precision == 0.0


def test_pixels_past_a_range_cut_are_ignored() -> None:
    mask = mask_with_lines({3001: 200})
    # the projected curve bends away after x = 400; its end there is a range cut
    open_end = line_instance("a", 202, cols=(50, 400), end_open=True)
    closed_end = line_instance("a", 202, cols=(50, 400))
    assert run([open_end], mask).sre_px == pytest.approx(2.0, abs=0.01)
    assert run([closed_end], mask).sre_px is None  # pixels past a real end count: mean far over the gate


def test_other_classes_are_not_matched() -> None:
    mask = mask_with_lines({int(Semantic.CURB) * 1000 + 1: 200})
    result = run([line_instance("a", 200)], mask)
    assert result.match.image_instances == 0 and result.recall is None


def test_projection_mask_round_trip_is_near_zero() -> None:
    """A ground line projected into a tilted camera, drawn as a mask, evaluates to (almost) no error."""
    pitch = np.radians(10.0)
    cam_axes_in_global = np.array(  # OpenCV camera looking along +x (global), tilted down
        [[0.0, -np.sin(pitch), np.cos(pitch)], [-1.0, 0.0, 0.0], [0.0, -np.cos(pitch), -np.sin(pitch)]]
    )
    K = np.array([[800.0, 0.0, 480.0], [0.0, 800.0, 270.0], [0.0, 0.0, 1.0]])
    camera = PinholeCamera(cam_axes_in_global, np.array([0.0, 0.0, 1.5]), K, W, H)
    lines = {
        3001: np.array([[3.0, 1.75, 0.0], [60.0, 1.75, 0.0]]),
        3002: np.array([[3.0, -1.75, 0.0], [60.0, -1.75, 0.0]]),
    }
    mask = np.zeros((H, W), np.uint16)
    projected = []
    for value, line in lines.items():
        pieces = project_polyline(line, camera, ProjectionConfig())
        for piece in pieces:
            cv2.polylines(mask, [np.round(piece.points_px).astype(np.int32)], False, value, thickness=5)
        projected.append(ProjectedInstance(f"e{value}", "divider", tuple(pieces)))
    result = run(projected, mask)
    assert len(result.match.pairs) == 2
    assert result.sre_px < 0.8


def test_hierarchical_mean_is_camera_then_frame_then_scene() -> None:
    match = run([line_instance("a", 201)], mask_with_lines({3001: 200})).match
    far = run([line_instance("a", 205)], mask_with_lines({3001: 200})).match
    images = [
        ImageSre("s1", "f1", "CAM_FRONT", "i1", W, match),
        ImageSre("s1", "f1", "CAM_BACK", "i2", W, far),
        ImageSre("s1", "f2", "CAM_FRONT", "i3", W, match),
        ImageSre("s2", "f3", "CAM_FRONT", "i4", W, far),
    ]
    # s1: frames (1 + 5) / 2 = 3 and 1 -> 2; s2: 5; overall 3.5
    assert hierarchical_mean(images, lambda im: im.sre_px) == pytest.approx(3.5, abs=0.01)
    report = SreReport.from_images(images, CONFIG)
    assert report.per_scene["s2"].sre_px == pytest.approx(5.0, abs=0.01)
    assert report.overall.f1 == pytest.approx(1.0)
    assert report.to_json()["per_camera"]["CAM_BACK"]["matched"] == 1


def test_skeleton_fallback_thins_a_bar() -> None:
    bar = np.zeros((20, 60), bool)
    bar[8:13, 5:55] = True
    for skeleton in (skeletonize(bar), zhang_suen_thinning(bar)):
        rows, cols = np.nonzero(skeleton)
        assert set(rows.tolist()) <= {9, 10, 11} and cols.max() - cols.min() > 35


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"class_pairs": (("lane", 3),)}, "unknown map class"),
        ({"class_pairs": (("divider", 42),)}, "not a mask class"),
        ({"class_pairs": ()}, "at least one"),
        ({"gate_px": 0.0}, "gate_px"),
        ({"min_skeleton_px": 0}, "min_skeleton_px"),
    ],
)
def test_bad_config_raises(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SreConfig(**kwargs)
