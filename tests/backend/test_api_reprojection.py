"""Per-element reprojection figures and the worst-reprojection queue (issue 25.2), on a site registered on the
tiny site's reconstruction (`whole_path`) with its data set: a true divider (the ground-truth vector map) agrees
with the lane masks, the same divider 1 m aside does not; figures are cached per element version and inputs."""

import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from annotations.schema import AnnotationSet
from app.backend.cameras.reprojection import NOT_SCORED
from app.backend.config import Settings
from app.backend.crud import reprojection
from app.demo import site_request
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.backend.backend_helpers import crosswalk, divider, with_reconstruction
from tests.conftest import GeneratedSite

Headers = dict[str, dict[str, str]]
SHIFT_M = 1.0
INSET_M = 2.0
"""The true divider is taken where it lies this far inside the site's extent."""


@pytest.fixture
def settings(settings: Settings, tiny_site: GeneratedSite, whole_path: PipelineResult) -> Settings:
    """The conftest settings with the tiny site's data set and its reconstruction inside the data roots."""
    return with_reconstruction(settings, tiny_site, whole_path)


@pytest.fixture
def reconstructed(
    client: TestClient, headers: Headers, tiny_site: GeneratedSite, whole_path: PipelineResult
) -> tuple[int, np.ndarray]:
    """A site on the reconstruction's surface rasters with the tiny site's data set; its id and the longest true
    divider that lies inside it (site metres)."""
    site, proposals = sorted(whole_path.proposals.items())[0]
    bev = Workspace(whole_path.workspace).surface_bev(site)
    body = site_request(bev, bev, proposals, "junction").model_dump(mode="json", exclude_none=True)
    body["dataset_root"] = str(tiny_site.result.out_dir / "nuscenes")
    response = client.post("/api/sites", json=body, headers=headers["lead"])
    assert response.status_code == 201, response.text
    site_id = int(response.json()["id"])
    extent = client.get(f"/api/sites/{site_id}", headers=headers["lead"]).json()["extent"]
    origin = np.array(AnnotationSet.read_json(proposals).georeference.site_origin_xy)
    truth = json.loads((tiny_site.result.out_dir / "ground_truth" / "vector_map.json").read_text())
    low = np.array([extent["xmin"], extent["ymin"]]) + INSET_M
    high = np.array([extent["xmax"], extent["ymax"]]) - INSET_M
    runs = [
        run
        for element in truth["elements"]
        if element["class"] == "divider"
        for run in inside_runs(np.asarray(element["points"])[:, :2] - origin, low, high)
    ]
    assert runs, "no true divider inside the reconstruction's extent"
    return site_id, max(runs, key=length_m)


def inside_runs(points: np.ndarray, low: np.ndarray, high: np.ndarray) -> list[np.ndarray]:
    """The runs of consecutive vertices inside a box, each of at least two vertices."""
    inside = ((points > low) & (points < high)).all(axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(int), [0]])))
    return [points[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


def length_m(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def aside(points: np.ndarray, metres: float) -> np.ndarray:
    """The polyline moved sideways (perpendicular to its chord)."""
    chord = points[-1] - points[0]
    normal = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)
    return points + metres * normal


def make(client: TestClient, headers: Headers, site_id: int, points: np.ndarray) -> dict[str, Any]:
    body = {"class": "divider", "points": np.round(points, 3).tolist()}
    response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
    assert response.status_code == 201, response.text
    return dict(response.json())


def figures(client: TestClient, headers: Headers, site_id: int, element_id: int) -> dict[str, Any]:
    response = client.get(
        f"/api/sites/{site_id}/elements/{element_id}/reprojection", headers=headers["annotator"]
    )
    assert response.status_code == 200, response.text
    return dict(response.json())


@pytest.fixture
def computations(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every element whose figures are computed (the cache's misses), in order."""
    calls: list[str] = []
    compute = reprojection.element_figures

    def counted(*args: Any, **kwargs: Any) -> reprojection.ReprojectionFigures:
        calls.append(kwargs["element_id"])
        return compute(*args, **kwargs)

    monkeypatch.setattr(reprojection, "element_figures", counted)
    return calls


def test_a_true_divider_agrees_with_the_masks_and_one_moved_aside_does_not(
    client: TestClient, headers: Headers, reconstructed: tuple[int, np.ndarray], computations: list[str]
) -> None:
    site_id, truth = reconstructed
    true = figures(client, headers, site_id, make(client, headers, site_id, truth)["id"])
    moved = figures(client, headers, site_id, make(client, headers, site_id, aside(truth, SHIFT_M))["id"])
    assert true["images"] >= 4 and true["element_version"] == 1 and true["notice"] is None
    assert true["sre_px"] is not None and true["sre_px"] < 8.0, true
    assert true["matched_share"] >= 0.5, true
    assert moved["sre_px"] is None or moved["sre_px"] > true["sre_px"] + 3.0, (true, moved)
    assert moved["matched_share"] is None or moved["matched_share"] <= true["matched_share"], (true, moved)
    assert len(computations) == 2


def test_figures_are_cached_until_the_element_or_the_inputs_change(
    client: TestClient,
    headers: Headers,
    reconstructed: tuple[int, np.ndarray],
    computations: list[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    site_id, truth = reconstructed
    element = make(client, headers, site_id, truth)
    first = figures(client, headers, site_id, element["id"])
    assert figures(client, headers, site_id, element["id"]) == first
    assert computations == [str(element["id"])]  # the second answer came from the cache
    body = {"version": element["version"], "points": np.round(aside(truth, SHIFT_M), 3).tolist()}
    edited = client.patch(
        f"/api/sites/{site_id}/elements/{element['id']}", json=body, headers=headers["annotator"]
    )
    assert edited.status_code == 200, edited.text
    after = figures(client, headers, site_id, element["id"])
    assert len(computations) == 2 and after["element_version"] == 2
    assert after["sre_px"] is None or after["sre_px"] > first["sre_px"] + 3.0, (first, after)
    monkeypatch.setattr(reprojection, "inputs_digest", lambda context: "other poses")
    assert figures(client, headers, site_id, element["id"])["sre_px"] == after["sre_px"]
    assert len(computations) == 3  # new poses (another digest): computed again


def test_the_queue_puts_the_moved_divider_first_and_computes_within_its_budget(
    client: TestClient,
    headers: Headers,
    reconstructed: tuple[int, np.ndarray],
    computations: list[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    site_id, truth = reconstructed
    true = make(client, headers, site_id, truth)
    moved = make(client, headers, site_id, aside(truth, SHIFT_M))
    crossing = client.post(
        f"/api/sites/{site_id}/elements", json=crosswalk(*truth[0]), headers=headers["annotator"]
    )
    assert crossing.status_code == 201, crossing.text
    assert figures(client, headers, site_id, crossing.json()["id"])["notice"] == NOT_SCORED
    url = f"/api/sites/{site_id}/queues/reprojection"
    monkeypatch.setattr(reprojection, "QUEUE_BUDGET_S", 0.0)  # one element per request
    page = client.get(url, headers=headers["lead"]).json()
    assert page["pending"] == 1 and [item["id"] for item in page["items"]] == [true["id"]]
    page = client.get(url, headers=headers["lead"], params={"limit": 50}).json()
    assert page["pending"] == 0 and page["total"] == 2 and page["unseen"] == 0
    assert [item["id"] for item in page["items"]] == [moved["id"], true["id"]]  # the crosswalk is not ranked
    assert page["items"][0]["class"] == "divider" and page["items"][0]["state"] == "proposed"
    assert computations == [str(true["id"]), str(moved["id"])]
    assert (
        client.get(url, headers=headers["lead"], params={"limit": 1}).json()["items"][0]["id"] == moved["id"]
    )
    assert len(computations) == 2  # all cached now


def test_a_site_without_reconstruction_answers_nulls_with_the_notice(
    client: TestClient, headers: Headers, site_id: int, make_element: Callable[..., dict[str, Any]]
) -> None:
    element = make_element(divider())
    answer = figures(client, headers, site_id, element["id"])
    assert answer == {
        "element_id": element["id"],
        "element_version": 1,
        "sre_px": None,
        "matched_share": None,
        "images": 0,
        "computed_at": None,
        "notice": answer["notice"],
    }
    cameras = client.get(f"/api/sites/{site_id}/cameras", headers=headers["annotator"]).json()
    assert answer["notice"] and answer["notice"] == cameras["notice"]  # the camera panel's notice
    page = client.get(f"/api/sites/{site_id}/queues/reprojection", headers=headers["lead"]).json()
    assert page == {"items": [], "total": 0, "pending": 0, "unseen": 0, "notice": answer["notice"]}


def test_unknown_elements_and_sites_are_404_and_bad_limits_422(
    client: TestClient, headers: Headers, site_id: int, make_element: Callable[..., dict[str, Any]]
) -> None:
    element = make_element(divider())
    lead = headers["lead"]
    assert client.get(f"/api/sites/{site_id}/elements/999999/reprojection", headers=lead).status_code == 404
    assert (
        client.get(f"/api/sites/999/elements/{element['id']}/reprojection", headers=lead).status_code == 404
    )
    assert client.get("/api/sites/999/queues/reprojection", headers=lead).status_code == 404
    url = f"/api/sites/{site_id}/queues/reprojection"
    assert client.get(url, headers=lead, params={"limit": 0}).status_code == 422
    assert client.get(url).status_code == 401
