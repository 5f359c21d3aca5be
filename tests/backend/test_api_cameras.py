"""The camera panel's endpoints (issue 25) on a site registered on the rasters `cama run` made of the tiny site
(`whole_path`) with its data set: status, views that see the element, images scaled with immutable cache
headers, camera parameters that agree with the server's projection, lane-mask overlays, and the refusals
(unknown or malformed tokens, a symlink out of the data set root, unknown sites and elements)."""

import logging
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from annotations.schema import AnnotationSet
from app.backend.cameras import NO_LANE_MASK, NO_RECONSTRUCTION
from app.backend.config import Settings
from app.backend.models import Site
from app.demo import site_request
from cama_pipeline.data import load_dataset
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.backend.backend_helpers import divider, with_reconstruction
from tests.conftest import GeneratedSite

Headers = dict[str, dict[str, str]]
ELEMENTS = 6


@pytest.fixture
def settings(settings: Settings, tiny_site: GeneratedSite, whole_path: PipelineResult) -> Settings:
    """The conftest settings with the tiny site's data set and its reconstruction inside the data roots."""
    return with_reconstruction(settings, tiny_site, whole_path)


def register(
    client: TestClient, lead: dict[str, str], whole_path: PipelineResult, name: str, dataset_root: Path
) -> int:
    """A site on the reconstruction's surface rasters with `dataset_root`; its id."""
    site, proposals = sorted(whole_path.proposals.items())[0]
    bev = Workspace(whole_path.workspace).surface_bev(site)
    body = site_request(bev, bev, proposals, name).model_dump(mode="json", exclude_none=True)
    response = client.post("/api/sites", json={**body, "dataset_root": str(dataset_root)}, headers=lead)
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


@pytest.fixture
def site(
    client: TestClient, headers: Headers, whole_path: PipelineResult, tiny_site: GeneratedSite
) -> tuple[int, list[dict[str, Any]]]:
    """The reconstructed site holding the first proposals as elements: its id and the elements."""
    site_id = register(client, headers["lead"], whole_path, "junction", tiny_site.result.out_dir / "nuscenes")
    proposals = sorted(whole_path.proposals.values())[0]
    made = []
    for element in AnnotationSet.read_json(proposals).elements[:ELEMENTS]:
        body = {"class": element.cls, "points": [list(point) for point in element.points_2d]}
        answer = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
        assert answer.status_code == 201, answer.text
        made.append(answer.json())
    return site_id, made


def get(client: TestClient, headers: Headers, url: str, **extra: Any) -> Any:
    response = client.get(url, headers={**headers["annotator"], **extra})
    assert response.status_code == 200, response.text
    return response


def seen_element(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> tuple[int, Any]:
    """The first element some view sees, and its views (n=4)."""
    site_id, elements = site
    for element in elements:
        views = get(client, headers, f"/api/sites/{site_id}/views?element_id={element['id']}&n=4").json()
        if views["views"]:
            return element["id"], views
    raise AssertionError("no element of the tiny site is seen by any view")


def test_registration_fills_the_camera_sources_and_the_status_counts_posed_images(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]], whole_path: PipelineResult
) -> None:
    site_id, _ = site
    with client.app.state.sessionmaker() as session:  # type: ignore[attr-defined]
        stored = session.get(Site, site_id)
        assert stored is not None
        assert stored.workspace_dir == str(whole_path.workspace.resolve())
        assert stored.recon_site_id == sorted(whole_path.proposals)[0]
        assert stored.dataset_root is not None and stored.dataset_root.endswith("nuscenes")
    status = get(client, headers, f"/api/sites/{site_id}/cameras").json()
    assert status["available"] is True and status["notice"] is None
    assert 0 < status["posed"] <= status["images"]
    assert status["mask_source"] == "dataset"


def test_a_site_without_a_reconstruction_says_so(
    client: TestClient, headers: Headers, tiny_site: GeneratedSite
) -> None:
    body = {"name": "synthetic", "synthetic_dir": str(tiny_site.result.out_dir)}
    response = client.post("/api/sites", json=body, headers=headers["lead"])
    assert response.status_code == 201, response.text
    site_id = response.json()["id"]
    status = get(client, headers, f"/api/sites/{site_id}/cameras").json()
    assert status["available"] is False and status["notice"] == NO_RECONSTRUCTION
    assert status["images"] > 0 and status["posed"] == 0
    element = client.post(
        f"/api/sites/{site_id}/elements", json=divider(), headers=headers["annotator"]
    ).json()
    views = get(client, headers, f"/api/sites/{site_id}/views?element_id={element['id']}").json()
    assert views == {"notice": NO_RECONSTRUCTION, "views": []}


def test_refused_camera_sources(
    client: TestClient, headers: Headers, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    synthetic = str(tiny_site.result.out_dir)
    for dataset_root in ("/", str(tmp_path)):  # outside the data roots; inside but not a data set
        body = {"name": "refused", "synthetic_dir": synthetic, "dataset_root": dataset_root}
        response = client.post("/api/sites", json=body, headers=headers["lead"])
        assert response.status_code == 422 and "dataset_root" in response.text, response.text
        assert str(tmp_path) not in response.text


def test_views_see_the_element_and_respect_n(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> None:
    site_id, _ = site
    element_id, views = seen_element(client, headers, site)
    every = get(client, headers, f"/api/sites/{site_id}/views?element_id={element_id}&all=1").json()["views"]
    assert len(views["views"]) == min(4, len(every))
    stations = [view["station_m"] for view in every]
    assert stations == sorted(stations)
    two = get(client, headers, f"/api/sites/{site_id}/views?element_id={element_id}&n=2").json()["views"]
    assert len(two) == min(2, len(every))
    for view in views["views"]:
        assert view["distance_m"] <= 40.0 and 0.0 <= view["obliqueness_deg"] < 90.0
        url = f"/api/sites/{site_id}/elements/{element_id}/projection?image={view['token']}"
        pieces = get(client, headers, url).json()["pieces"]
        assert pieces, view
        uv = np.array([point for piece in pieces for point in piece])
        assert (uv >= -0.5 - 1e-6).all() and (uv[:, 0] <= view["width"] - 0.5 + 1e-6).all()
        assert (uv[:, 1] <= view["height"] - 0.5 + 1e-6).all()
    first = views["views"][0]
    projection = get(
        client, headers, f"/api/sites/{site_id}/elements/{element_id}/projection?image={first['token']}"
    ).json()
    x, y = projection["points_3d"][len(projection["points_3d"]) // 2][:2]
    at_point = get(client, headers, f"/api/sites/{site_id}/views?x={x}&y={y}&n=3").json()["views"]
    assert 0 < len(at_point) <= 3 and all(view["station_m"] == 0.0 for view in at_point)


@pytest.mark.parametrize(
    "query",
    [
        "element_id={e}&n=1",
        "element_id={e}&n=7",
        "",
        "x=1",
        "element_id={e}&x=1&y=2",
        "x=nan&y=1",
        "x=1e300&y=1",
        "element_id=0",
    ],
)
def test_bad_view_parameters_are_422(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]], query: str
) -> None:
    site_id, elements = site
    url = f"/api/sites/{site_id}/views?" + query.format(e=elements[0]["id"])
    response = client.get(url, headers=headers["annotator"])
    assert response.status_code == 422, (url, response.text)


def test_images_are_scaled_and_cached(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]], tiny_site: GeneratedSite
) -> None:
    site_id, _ = site
    _, views = seen_element(client, headers, site)
    token = views["views"][0]["token"]
    scaled = get(client, headers, f"/api/sites/{site_id}/images/{token}?width=240")
    assert scaled.headers["content-type"] == "image/jpeg"
    assert scaled.headers["cache-control"] == "private, max-age=31536000, immutable"
    image = np.asarray(cv2.imdecode(np.frombuffer(scaled.content, np.uint8), cv2.IMREAD_COLOR))
    full = load_dataset(tiny_site.result.out_dir / "nuscenes").image(token)
    assert image.shape[1] == 240
    assert abs(image.shape[0] - 240 * full.calibration.height / full.calibration.width) <= 1
    etag = scaled.headers["etag"]
    again = client.get(
        f"/api/sites/{site_id}/images/{token}?width=240",
        headers={**headers["annotator"], "If-None-Match": etag},
    )
    assert again.status_code == 304 and again.headers["etag"] == etag and not again.content
    whole = get(client, headers, f"/api/sites/{site_id}/images/{token}")
    assert whole.content == full.path.read_bytes() and whole.headers["etag"] != etag
    bad_width = client.get(f"/api/sites/{site_id}/images/{token}?width=100", headers=headers["annotator"])
    assert bad_width.status_code == 422


def test_camera_parameters_project_like_the_server(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> None:
    site_id, _ = site
    element_id, views = seen_element(client, headers, site)
    for view in views["views"]:
        camera = get(client, headers, f"/api/sites/{site_id}/images/{view['token']}/camera").json()
        assert camera["pose_source"] == "sfm" and (camera["width"], camera["height"]) == (
            view["width"],
            view["height"],
        )
        url = f"/api/sites/{site_id}/elements/{element_id}/projection?image={view['token']}"
        projection = get(client, headers, url).json()
        cam_from_site = np.array(camera["cam_from_site"])
        cam = np.array(projection["points_3d"]) @ cam_from_site[:3, :3].T + cam_from_site[:3, 3]
        uvw = cam @ np.array(camera["K"]).T
        uv = uvw[:, :2] / uvw[:, 2:3]
        inside = (cam[:, 2] > 0.5) & (np.linalg.norm(cam, axis=1) < 100.0)
        inside &= (uv > 0).all(axis=1) & (uv[:, 0] < view["width"] - 1) & (uv[:, 1] < view["height"] - 1)
        assert inside.any(), view
        drawn = np.array([point for piece in projection["pieces"] for point in piece])
        gaps = np.linalg.norm(uv[inside][:, None, :] - drawn[None, :, :], axis=2).min(axis=1)
        assert gaps.max() < 0.05, (view["token"], gaps.max())  # rounding of points_3d (mm) and pixels


def test_lane_mask_overlay(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> None:
    site_id, _ = site
    _, views = seen_element(client, headers, site)
    token = views["views"][0]["token"]
    response = get(client, headers, f"/api/sites/{site_id}/images/{token}/lane-mask?width=320")
    assert (
        response.headers["content-type"] == "image/png" and "immutable" in response.headers["cache-control"]
    )
    overlay = np.asarray(cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_UNCHANGED))
    assert overlay.ndim == 3 and overlay.shape[1] == 320 and overlay.shape[2] == 4
    assert set(np.unique(overlay[..., 3]).tolist()) == {0, 160}
    assert (overlay[..., :3][overlay[..., 3] == 0] == 0).all()
    assert len(np.unique(overlay[..., :3].reshape(-1, 3), axis=0)) >= 3  # background + two instances at least


def test_projection_with_neighbours(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> None:
    site_id, elements = site
    element_id, views = seen_element(client, headers, site)
    token = views["views"][0]["token"]
    url = f"/api/sites/{site_id}/elements/{element_id}/projection?image={token}&neighbours=1"
    projection = get(client, headers, url).json()
    assert np.isfinite(np.array(projection["points_3d"])).all()
    ids = {element["id"] for element in elements} - {element_id}
    assert projection["neighbours"] and {n["id"] for n in projection["neighbours"]} <= ids
    assert all(n["pieces"] and n["cls"] for n in projection["neighbours"])
    alone = get(client, headers, url.replace("&neighbours=1", "")).json()
    assert alone["neighbours"] == [] and alone["pieces"] == projection["pieces"]


def test_unknown_and_malformed_tokens_sites_and_elements(
    client: TestClient, headers: Headers, site: tuple[int, list[dict[str, Any]]]
) -> None:
    site_id, elements = site
    element_id, views = seen_element(client, headers, site)
    token = views["views"][0]["token"]
    for url in (
        f"/api/sites/{site_id}/images/notatoken0123",
        f"/api/sites/{site_id}/images/notatoken0123/camera",
        f"/api/sites/{site_id}/images/notatoken0123/lane-mask",
        f"/api/sites/{site_id}/elements/{element_id}/projection?image=notatoken0123",
        f"/api/sites/{site_id}/elements/999999/projection?image={token}",
        f"/api/sites/{site_id}/views?element_id=999999",
        "/api/sites/999/cameras",
        f"/api/sites/999/images/{token}",
    ):
        response = client.get(url, headers=headers["annotator"])
        assert response.status_code == 404, (url, response.text)
        assert "/" not in response.json()["detail"], response.text  # no server path
    for bad in ("bad.token", "x" * 129, "a%20b"):
        response = client.get(f"/api/sites/{site_id}/images/{bad}", headers=headers["annotator"])
        assert response.status_code == 422, (bad, response.text)
    response = client.get(
        f"/api/sites/{site_id}/elements/{element_id}/projection?image=..%2Fx", headers=headers["annotator"]
    )
    assert response.status_code == 422


def test_a_symlink_out_of_the_data_set_is_refused(
    client: TestClient,
    headers: Headers,
    site: tuple[int, list[dict[str, Any]]],
    tiny_site: GeneratedSite,
    whole_path: PipelineResult,
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    source = tiny_site.result.out_dir / "nuscenes"
    copy = tmp_path / "copy" / "nuscenes"
    for folder in ("v1.0-synth", "samples"):
        shutil.copytree(source / folder, copy / folder)
    copy_site = register(client, headers["lead"], whole_path, "copy", copy)
    _, views = seen_element(client, headers, site)
    escaping, kept = views["views"][0]["token"], views["views"][1]["token"]
    image = load_dataset(copy, check_files=False).image(escaping).path
    outside = tmp_path / "outside.jpg"
    shutil.copyfile(image, outside)
    image.unlink()
    image.symlink_to(outside)
    with caplog.at_level(logging.WARNING, logger="app.backend.cameras.images"):
        response = client.get(f"/api/sites/{copy_site}/images/{escaping}", headers=headers["annotator"])
    assert response.status_code == 404 and str(tmp_path) not in response.text
    assert any("refused escape" in record.getMessage() for record in caplog.records)
    assert (
        client.get(f"/api/sites/{copy_site}/images/{kept}", headers=headers["annotator"]).status_code == 200
    )
    no_mask = client.get(f"/api/sites/{copy_site}/images/{kept}/lane-mask", headers=headers["annotator"])
    assert no_mask.status_code == 404 and no_mask.json() == {"detail": NO_LANE_MASK}
