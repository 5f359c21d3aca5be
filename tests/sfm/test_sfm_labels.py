"""Per-point labels: the majority class of the masks at a point's observations, in BEV raster classes."""

import numpy as np
import pycolmap

from cama_pipeline.semantics import Semantic
from cama_pipeline.sfm.labels import point_labels, sparse_points

WIDTH, HEIGHT = 40, 30


def two_view_model(n_points: int) -> pycolmap.Reconstruction:
    """Two images that both observe points 0..n-1 at pixel (k + 0.5, 10.5) (column k)."""
    model = pycolmap.Reconstruction()
    camera = pycolmap.Camera(
        camera_id=1, model="PINHOLE", width=WIDTH, height=HEIGHT, params=[20, 20, 20, 15]
    )
    model.add_camera_with_trivial_rig(camera)
    for image_id in (1, 2):
        points = [pycolmap.Point2D(np.array([k + 0.5, 10.5])) for k in range(n_points)]
        image = pycolmap.Image(name=f"im{image_id}.jpg", camera_id=1, image_id=image_id, points2D=points)
        model.add_image_with_trivial_frame(image, pycolmap.Rigid3d())
    for k in range(n_points):
        track = pycolmap.Track()
        track.add_element(1, k)
        track.add_element(2, k)
        model.add_point3D(np.array([k, 0.0, 5.0]), track)
    return model


def test_majority_of_mask_classes_mapped_to_raster_classes() -> None:
    model = two_view_model(4)
    first = np.full((HEIGHT, WIDTH), Semantic.ROAD, np.uint8)
    first[:, 1] = Semantic.LANE_MARKING
    first[:, 2] = Semantic.SKY
    second = first.copy()
    second[:, 0] = Semantic.CROSSWALK  # tie road/crosswalk: the lower class id wins
    second[:, 3] = Semantic.CURB  # tie road/curb on point 3
    masks = {"im1.jpg": first, "im2.jpg": second}
    labels = point_labels(model, sorted(model.point3D_ids()), masks.get)
    assert labels.dtype == np.uint8
    assert labels.tolist() == [Semantic.ROAD, Semantic.LANE_MARKING, Semantic.BACKGROUND, Semantic.ROAD]


def test_points_seen_by_no_mask_are_background() -> None:
    model = two_view_model(3)
    labels = point_labels(model, sorted(model.point3D_ids()), lambda name: None)
    assert labels.tolist() == [0, 0, 0]


def test_sparse_points_keep_point_order_with_labels_and_tracks() -> None:
    model = two_view_model(3)
    masks = {"im1.jpg": np.full((HEIGHT, WIDTH), Semantic.CROSSWALK, np.uint8)}
    points = sparse_points(model, masks.get)
    np.testing.assert_allclose(points.xyz[:, 0], [0.0, 1.0, 2.0])
    assert points.label.tolist() == [Semantic.CROSSWALK] * 3
    assert points.track_length.tolist() == [2, 2, 2] and points.error_px.shape == (3,)
