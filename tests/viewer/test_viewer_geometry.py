"""Pure geometry of the 3D view: frustums, polyline segments, picking by click ray."""

from pathlib import Path

import numpy as np
import pytest

from app.viewer.geometry import LocalFrame, frustum_segments, pick_element, polyline_segments
from cama_pipeline.semantics import Semantic


def test_frustum_has_its_apex_at_the_camera_centre_and_far_corners_at_depth() -> None:
    pose = np.eye(4)
    pose[:3, 3] = [10.0, 5.0, 2.0]
    intrinsic = np.array([[100.0, 0, 50], [0, 100.0, 25], [0, 0, 1]])
    segments = frustum_segments(pose, intrinsic, 100, 50, depth_m=2.0)
    assert segments.shape == (8, 2, 3)
    np.testing.assert_allclose(segments[:4, 0], np.tile([10.0, 5.0, 2.0], (4, 1)))
    np.testing.assert_allclose(segments[:4, 1, 2], 4.0)  # depth along +z of the camera
    np.testing.assert_allclose(segments[0, 1], [10.0 - 1.0, 5.0 - 0.5, 4.0])  # pixel (0, 0) at 2 m


def test_polygon_segments_close_the_ring_once() -> None:
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    assert len(polyline_segments(square)) == 3
    closed = polyline_segments(square, closed=True)
    assert len(closed) == 4
    np.testing.assert_allclose(closed[-1], [[0, 1, 0], [0, 0, 0]])
    assert len(polyline_segments(np.vstack([square, square[:1]]), closed=True)) == 4


def test_pick_returns_the_nearest_polyline_within_reach() -> None:
    lines = {
        "a": np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]),
        "b": np.array([[0.0, 3.0, 0.0], [10.0, 3.0, 0.0]]),
    }
    down = np.array([0.0, 0.0, -1.0])
    assert pick_element(lines, np.array([5.0, 2.6, 20.0]), down, max_distance_m=1.0) == "b"
    assert pick_element(lines, np.array([5.0, 0.4, 20.0]), 7 * down, max_distance_m=1.0) == "a"
    assert pick_element(lines, np.array([5.0, 1.5, 20.0]), down, max_distance_m=1.0) is None
    assert pick_element(lines, np.array([5.0, 0.0, 20.0]), np.zeros(3), max_distance_m=1.0) is None
    # a ray pointing away from the lines does not reach back behind its origin
    assert pick_element(lines, np.array([5.0, 0.0, 20.0]), -down, max_distance_m=1.0) is None


def test_local_frame_subtracts_its_origin() -> None:
    frame = LocalFrame(np.array([1000.0, 2000.0, 10.0]))
    np.testing.assert_allclose(frame.from_global(np.array([[1001.0, 1999.0, 10.5]])), [[1.0, -1.0, 0.5]])


@pytest.mark.parametrize("faces", [50, 5000])
def test_raster_mesh_keeps_to_its_face_budget(faces: int) -> None:
    from annotations.schema import Georeference
    from app.viewer.content import Surface, raster_mesh

    elevation = np.fromfunction(lambda r, c: 0.01 * c, (60, 80))
    unobserved = np.zeros_like(elevation, dtype=bool)
    unobserved[:, :10] = True
    geo = Georeference(site_origin_xy=(0, 0), origin_xy=(100.0, 200.0), resolution=0.5, width=80, height=60)
    surface = Surface(elevation, unobserved, geo, folder=None, reconstructed=True)  # type: ignore[arg-type]
    photometric = np.full((60, 80, 3), 128, np.uint8)
    mesh = raster_mesh(surface, photometric, LocalFrame(np.array([100.0, 200.0, 0.0])), max_faces=faces)
    assert 0 < len(mesh.faces) <= faces
    assert mesh.vertices[:, 0].min() >= 10 * 0.5 - 1e-9  # unobserved columns are not meshed
    np.testing.assert_allclose(mesh.vertices[:, 2], 0.01 * mesh.vertices[:, 0] / 0.5, atol=1e-9)


def test_raster_mesh_stands_on_the_kerb_steps_and_vectors_stay_on_the_road(tmp_path: Path) -> None:
    from annotations.schema import Georeference
    from app.viewer.content import load_surface, raster_mesh
    from cama_pipeline.bev import BevRasters, RasterGeoreference, write_bev
    from cama_pipeline.surface.outputs import write_kerb_step
    from cama_pipeline.workspace import Workspace

    raster_geo = RasterGeoreference(origin_xy=(0.0, 40.0), resolution=0.5, width=40, height=30)
    semantic = np.full((30, 40), int(Semantic.ROAD), np.uint8)
    semantic[:, 20:] = int(Semantic.BACKGROUND)
    step = np.where(semantic == int(Semantic.BACKGROUND), 0.13, 0.0).astype(np.float32)
    step[0, 0] = np.nan  # an unobserved cell has no step
    elevation = np.full((30, 40), 2.0, np.float32)
    photometric = np.zeros((30, 40, 3), np.uint8)
    workspace = Workspace(tmp_path / "ws")
    write_bev(
        workspace.surface_bev("site-001"),
        BevRasters(raster_geo, semantic, photometric, elevation, np.ones((30, 40), np.uint16)),
    )
    write_kerb_step(workspace.surface_kerb_step("site-001"), step)
    surface = load_surface(workspace.surface_bev("site-001"), reconstructed=True)
    assert np.array_equal(surface.elevation, elevation)  # what vectors are lifted through: the road alone
    mesh = raster_mesh(surface, photometric, LocalFrame(np.zeros(3)), max_faces=10_000)
    sidewalk = mesh.vertices[:, 0] >= 20 * 0.5 - 1e-9
    np.testing.assert_allclose(mesh.vertices[sidewalk, 2], 2.13, atol=1e-6)
    np.testing.assert_allclose(mesh.vertices[~sidewalk, 2], 2.0, atol=1e-6)
    assert Georeference.of(raster_geo, site_origin_xy=(0.0, 0.0)) == surface.georeference
