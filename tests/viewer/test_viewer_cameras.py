"""Camera views in the 3D review, following an in-process backend on the tiny site's reconstruction (`whole_path`):
a selected element gets one frustum per best view, at the camera centre the backend's `/camera` gives, looking the
way that camera looks (the element it sees lies in front of it, inside its image, with the image's down axis
pointing down), textured with the image; the number follows the slider; a site without images only says so."""

import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser
import viser.transforms as vtf
from fastapi.testclient import TestClient

from annotations.schema import AnnotationSet
from app.backend.cameras.context import NO_DATASET
from app.backend.config import Settings
from app.backend.main import create_app
from app.demo import site_request
from app.viewer.cameras import (
    ELEMENT_LIFT_M,
    HINT,
    IMAGE_WIDTH,
    CameraViews,
    PosedCamera,
    attach_camera_views,
    decode_jpeg,
)
from app.viewer.content import load_surface, local_frame_of
from app.viewer.geometry import polyline_segments
from app.viewer.review import show_vectors
from app.viewer.scene import ReviewScene
from app.viewer.sources import ApiVectorSource, VectorSourceError
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite

PASSWORD = "correct horse battery"
ELEMENTS = 6


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture()
def backend(
    tmp_path: Path, tiny_site: GeneratedSite, whole_path: PipelineResult
) -> Iterator[tuple[TestClient, dict[str, str]]]:
    """An in-process backend (SQLite) whose data roots hold the tiny site and its reconstruction."""
    settings = Settings(
        data_dir=tmp_path / "data",
        data_roots=(tmp_path, tiny_site.result.out_dir, whole_path.workspace),
        scrypt_n=2**4,
        admin_username="root",
        admin_password=PASSWORD,
    )
    with TestClient(create_app(settings)) as client:
        login = client.post("/api/auth/login", json={"username": "root", "password": PASSWORD})
        yield client, {"Authorization": f"Bearer {login.json()['access_token']}"}
    client.app.state.engine.dispose()  # type: ignore[attr-defined]


def _register(
    client: TestClient, headers: dict[str, str], whole_path: PipelineResult, dataset_root: Path | None
) -> int:
    """A site on the reconstruction's rasters (with the data set when given) holding the first proposals."""
    recon_site, proposals = sorted(whole_path.proposals.items())[0]
    bev = Workspace(whole_path.workspace).surface_bev(recon_site)
    body = site_request(bev, bev, proposals, "junction").model_dump(mode="json", exclude_none=True)
    if dataset_root is not None:
        body["dataset_root"] = str(dataset_root)
    response = client.post("/api/sites", json=body, headers=headers)
    assert response.status_code == 201, response.text
    site_id = int(response.json()["id"])
    for element in AnnotationSet.read_json(proposals).elements[:ELEMENTS]:
        element_body = {"class": element.cls, "points": [list(p) for p in element.points_2d]}
        made = client.post(f"/api/sites/{site_id}/elements", json=element_body, headers=headers)
        assert made.status_code == 201, made.text
    return site_id


@pytest.fixture()
def server() -> Iterator[viser.ViserServer]:
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def _review(
    server: viser.ViserServer, client: TestClient, site_id: int, whole_path: PipelineResult
) -> tuple[ReviewScene, CameraViews]:
    """The review of the site on the reconstruction's surface, with its camera views."""
    bev = Workspace(whole_path.workspace).surface_bev(sorted(whole_path.proposals)[0])
    surface = load_surface(bev, reconstructed=True)
    source = ApiVectorSource("http://testserver", site_id, "root", PASSWORD, client=client)
    scene = show_vectors(ReviewScene(server, local_frame_of(surface), surface), source)
    views = attach_camera_views(scene, source)
    assert views is not None
    return scene, views


def _json(client: TestClient, headers: dict[str, str], url: str) -> Any:
    response = client.get(url, headers=headers)
    assert response.status_code == 200, response.text
    return response.json()


def test_a_selected_element_shows_its_views_as_posed_frusta(
    backend: tuple[TestClient, dict[str, str]],
    server: viser.ViserServer,
    whole_path: PipelineResult,
    tiny_site: GeneratedSite,
) -> None:
    client, headers = backend
    site_id = _register(client, headers, whole_path, tiny_site.result.out_dir / "nuscenes")
    scene, views = _review(server, client, site_id, whole_path)
    assert views.notice.content == HINT and views.frusta == []
    api = f"/api/sites/{site_id}"
    seen = {
        element_id: len(_json(client, headers, f"{api}/views?element_id={element_id}&all=1")["views"])
        for element_id in scene._vectors
    }
    element_id = max(seen, key=lambda e: seen[e])
    assert seen[element_id] >= 3, seen
    site = _json(client, headers, api)
    offset = np.append(site["site_origin_xy"], 0.0) - scene.frame.origin
    views.count.value = 3  # type: ignore[misc]  # viser's setter, hidden from mypy by its stubs
    scene.select(element_id)
    expected = _json(client, headers, f"{api}/views?element_id={element_id}&n=3")["views"]
    assert len(expected) == 3 and len(views.frusta) == 3
    projection = _json(
        client, headers, f"{api}/elements/{element_id}/projection?image={expected[0]['token']}"
    )
    element = np.asarray(projection["points_3d"]) + offset  # the lifted element in the review's frame
    for view, frustum in zip(expected, views.frusta, strict=True):
        camera = PosedCamera.from_json(
            view["token"], _json(client, headers, f"{api}/images/{view['token']}/camera")
        )
        rotation, translation = camera.cam_from_site[:3, :3], camera.cam_from_site[:3, 3]
        centre = -rotation.T @ translation + offset
        assert np.linalg.norm(np.asarray(frustum.position) - centre) < 1e-3
        axes = vtf.SO3(np.asarray(frustum.wxyz)).as_matrix()
        assert np.allclose(axes[:, 2], rotation[2], atol=1e-6)  # the frustum's forward = the camera's
        assert axes[2, 1] < 0.0  # the image's down axis points down: an upright camera on a car
        in_camera = (element - np.asarray(frustum.position)) @ axes  # the frustum's own frame
        front = in_camera[in_camera[:, 2] > 0.1]
        uv = front @ camera.intrinsic.T
        uv = uv[:, :2] / uv[:, 2:]
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
        assert inside.any(), view["token"]  # the element the view sees lies in front, inside its image
        assert frustum.image is not None  # the image, at most IMAGE_WIDTH wide (the tiny site's are smaller)
        height, width = frustum.image.shape[:2]
        assert (
            width == min(IMAGE_WIDTH, camera.width)
            and abs(width / height - camera.width / camera.height) < 0.02
        )
        assert abs(frustum.aspect - camera.width / camera.height) < 1e-9 and 0.1 < frustum.fov < np.pi
    lifted = element + np.array([0.0, 0.0, ELEMENT_LIFT_M])
    drawn = [node for node in views._nodes if isinstance(node, viser.LineSegmentsHandle)]
    assert len(drawn) == 1 and np.allclose(drawn[0].points, polyline_segments(lifted), atol=1e-3)
    assert f"**Element {element_id}:** 3 views" in views.notice.content

    views.count.value = 2  # type: ignore[misc]  # the slider redraws the selection
    assert len(views.frusta) == 2
    stored = _json(client, headers, f"{api}/elements/{element_id}")
    moved = [[x + 0.5, y] for x, y in stored["points"]]
    body = {"version": stored["version"], "points": moved}
    assert client.patch(f"{api}/elements/{element_id}", json=body, headers=headers).is_success
    scene.apply_changes(views.api.changes())  # the follow loop's poll: the selection is redrawn
    line = [node for node in views._nodes if isinstance(node, viser.LineSegmentsHandle)][0]
    shift = np.asarray(line.points)[:, :, 0].mean() - drawn[0].points[:, :, 0].mean()
    assert abs(shift - 0.5) < 0.05 and len(views.frusta) == 2
    scene.select(None)
    assert views.frusta == [] and views._nodes == [] and views.notice.content == HINT


def test_a_site_without_images_shows_the_notice_and_no_frusta(
    backend: tuple[TestClient, dict[str, str]], server: viser.ViserServer, whole_path: PipelineResult
) -> None:
    client, headers = backend
    site_id = _register(client, headers, whole_path, None)
    scene, views = _review(server, client, site_id, whole_path)
    assert NO_DATASET in views.notice.content
    assert scene._vectors
    scene.select(next(iter(scene._vectors)))
    assert views.frusta == [] and views._nodes == []
    assert NO_DATASET in views.notice.content


def test_malformed_answers_are_named() -> None:
    with pytest.raises(VectorSourceError, match="image t1: malformed camera parameters"):
        PosedCamera.from_json("t1", {"width": 10, "height": 10, "K": [[1, 0], [0, 1]], "cam_from_site": []})
    with pytest.raises(VectorSourceError, match="image t2: the backend's answer is not an image"):
        decode_jpeg("t2", b"<html>not a jpeg</html>")
