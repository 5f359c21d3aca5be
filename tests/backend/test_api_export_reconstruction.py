"""The editor's export job with a real reconstruction (issue 24.9): a site registered on the rasters `cama run`
made of the tiny site (`whole_path`) exports refined poses (MapTR vectors, CAMA's release layout in both modes),
and a site without one exports the data set's logged poses when asked for."""

import io
import json
import re
import time
import zipfile
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import update

from annotations.poses import POSE_SOURCES
from annotations.schema import AnnotationSet
from app.backend.config import Settings
from app.backend.jobs import export as export_job
from app.backend.jobs.runner import REPORT_INTERVAL_S, JobContext
from app.backend.models_jobs import Job
from app.demo import site_request
from cama_pipeline import refined_poses
from cama_pipeline.data import load_dataset
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.backend.backend_helpers import divider, with_reconstruction
from tests.conftest import GeneratedSite

Headers = dict[str, dict[str, str]]
POLL_TIMEOUT_S = 300.0
"""Generous: a CAMA export of the tiny site takes seconds, more on a loaded machine."""
ELEMENTS = 4


@pytest.fixture
def settings(settings: Settings, tiny_site: GeneratedSite, whole_path: PipelineResult) -> Settings:
    """The conftest settings with the tiny site's data set and its reconstruction inside the data roots."""
    return with_reconstruction(settings, tiny_site, whole_path)


@pytest.fixture
def dataset_root(tiny_site: GeneratedSite) -> str:
    return str(tiny_site.result.out_dir / "nuscenes")


@pytest.fixture
def reconstructed(client: TestClient, headers: Headers, whole_path: PipelineResult) -> tuple[int, str]:
    """A site named `junction` on the surface rasters of the reconstruction (its site id differs), holding
    the first proposals as elements; the backend site id and the reconstruction's site id."""
    site, proposals = sorted(whole_path.proposals.items())[0]
    bev = Workspace(whole_path.workspace).surface_bev(site)
    body = site_request(bev, bev, proposals, "junction").model_dump(mode="json", exclude_none=True)
    response = client.post("/api/sites", json=body, headers=headers["lead"])
    assert response.status_code == 201, response.text
    site_id = int(response.json()["id"])
    for element in AnnotationSet.read_json(proposals).elements[:ELEMENTS]:
        made = {"class": element.cls, "points": [list(point) for point in element.points_2d]}
        answer = client.post(f"/api/sites/{site_id}/elements", json=made, headers=headers["annotator"])
        assert answer.status_code == 201, answer.text
    return site_id, site


def run_export(client: TestClient, headers: Headers, site_id: int, **params: Any) -> dict[str, Any]:
    """Submit an export as the lead and wait for its end; the job."""
    body = {"kind": "export", "params": params}
    response = client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["lead"])
    assert response.status_code == 202, response.text
    deadline = time.monotonic() + POLL_TIMEOUT_S
    while (job := client.get(f"/api/jobs/{response.json()['id']}", headers=headers["lead"]).json())[
        "state"
    ] in ("queued", "running"):
        assert time.monotonic() < deadline, job
        time.sleep(0.05)
    return dict(job)


def archive_of(client: TestClient, headers: Headers, job: dict[str, Any]) -> zipfile.ZipFile:
    assert job["state"] == "succeeded", job["message"]
    workdir = client.app.state.jobs.workdir(job["id"])  # type: ignore[attr-defined]
    assert sorted(path.name for path in workdir.iterdir()) == ["export.zip"]  # no staging, no folder left
    response = client.get(job["download_url"], headers=headers["lead"])
    assert response.status_code == 200
    return zipfile.ZipFile(io.BytesIO(response.content))


def pose_sources(bundle: zipfile.ZipFile) -> dict[str, set[str]]:
    """The pose sources of a MapTR file's samples, by scene."""
    sources: dict[str, set[str]] = {}
    for sample in json.loads(bundle.read("maptr.json"))["samples"]:
        sources.setdefault(sample["scene"], set()).add(sample["pose_source"])
    return sources


def test_refined_maptr_export_of_a_reconstructed_site(
    client: TestClient,
    headers: Headers,
    reconstructed: tuple[int, str],
    dataset_root: str,
    whole_path: PipelineResult,
) -> None:
    site_id, site = reconstructed
    job = run_export(client, headers, site_id, format="maptr", dataset_root=dataset_root)
    assert f"exported {ELEMENTS} elements of junction (maptr, refined poses, 1 files" in job["message"]
    lifted = re.search(rf"\b[1-9][0-9]* of {ELEMENTS} lifted", job["message"])  # heights from the surface
    assert lifted, job["message"]
    with archive_of(client, headers, job) as bundle:
        assert bundle.namelist() == ["maptr.json"]
        sources = pose_sources(bundle)
    site_scenes = set(refined_poses.site_scenes(Workspace(whole_path.workspace), site))
    assert site_scenes and site_scenes <= set(sources)
    refined = set().union(*(sources[scene] for scene in site_scenes))
    assert refined <= set(POSE_SOURCES) - {"coarse"} and "sfm" in refined, sources


@pytest.mark.parametrize("mode", ["clip", "site"])
def test_refined_cama_export_has_the_release_layout(
    client: TestClient, headers: Headers, reconstructed: tuple[int, str], dataset_root: str, mode: str
) -> None:
    site_id, site = reconstructed
    job = run_export(client, headers, site_id, format="cama", mode=mode, dataset_root=dataset_root)
    assert "(cama, refined poses," in job["message"] and f"mode {mode}" in job["message"]
    with archive_of(client, headers, job) as bundle:
        names = bundle.namelist()
        sources = json.loads(bundle.read(next(n for n in names if n.endswith("odometry/pose_sources.json"))))
    tops = {name.split("/")[0] for name in names}
    assert tops == ({"all_clips"} if mode == "clip" else {"all_clips", "site2clip", "site2clip.json"})
    scenes = {name.split("/")[1] for name in names if name.startswith("all_clips/")}
    prefix = "scmv" if mode == "clip" else "mcmv"
    for scene in scenes:
        assert f"all_clips/{scene}/maps/map_labels.json" in names
        assert f"all_clips/{scene}/maps/vision_road_mlp_ft.npy" in names
        assert f"all_clips/{scene}/odometry/{prefix}_camera_front.txt" in names
    if mode == "site":
        assert f"site2clip/{site}_map_labels.json" in names  # named after the reconstruction's site
    assert "coarse" not in json.dumps(sources)


def test_coarse_maptr_export_of_a_site_without_reconstruction(
    client: TestClient, headers: Headers, site_id: int, dataset_root: str
) -> None:
    client.post(f"/api/sites/{site_id}/elements", json=divider(), headers=headers["annotator"])
    job = run_export(client, headers, site_id, format="maptr", poses="coarse", dataset_root=dataset_root)
    assert "exported 1 elements of s1 (maptr, coarse poses, 1 files" in job["message"]
    with archive_of(client, headers, job) as bundle:
        assert bundle.namelist() == ["maptr.json"]
        samples = json.loads(bundle.read("maptr.json"))["samples"]
    assert {sample["pose_source"] for sample in samples} == {"coarse"}
    scenes = {scene.name for scene in load_dataset(Path(dataset_root)).scenes}
    assert {sample["scene"] for sample in samples} == scenes  # no reconstruction: every scene of the data set


def test_a_failing_refined_export_names_no_server_path(
    client: TestClient, headers: Headers, reconstructed: tuple[int, str], tmp_path: Path
) -> None:
    """A folder inside the roots that is no data set: the export fails after submission, and its message says
    why with the request field in place of the path."""
    site_id, _site = reconstructed
    not_a_dataset = tmp_path / "not-a-dataset"
    not_a_dataset.mkdir()
    job = run_export(client, headers, site_id, format="maptr", dataset_root=str(not_a_dataset))
    assert job["state"] == "failed", job["message"]
    assert job["message"].startswith("ExportFailed: dataset_root: not a usable data set: <dataset_root>: ")
    assert str(tmp_path) not in job["message"], job["message"]
    workdir = client.app.state.jobs.workdir(job["id"])  # type: ignore[attr-defined]
    assert list(workdir.iterdir()) == []


def test_a_cancel_stops_the_export_at_its_next_progress_step_and_leaves_nothing(
    client: TestClient,
    headers: Headers,
    reconstructed: tuple[int, str],
    dataset_root: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    site_id, _site = reconstructed
    steps: list[str] = []
    real_observer = export_job.progress_observer

    def cancelled_at_first_step(context: JobContext) -> export_job.ProgressObserver:
        observe = real_observer(context)

        def step(text: str, completed: float, total: float | None) -> None:
            steps.append(text)
            with context.session() as session:  # what POST /api/jobs/{id}/cancel records
                session.execute(update(Job).where(Job.id == context.job_id).values(cancel_requested=True))
                session.commit()
            time.sleep(REPORT_INTERVAL_S)  # past the report throttle: this step reads the flag
            observe(text, completed, total)

        return step

    monkeypatch.setattr(export_job, "progress_observer", cancelled_at_first_step)
    job = run_export(client, headers, site_id, format="cama", dataset_root=dataset_root, with_clip_data=True)
    assert job["state"] == "cancelled", job["message"]
    assert steps == [steps[0]] and steps[0].startswith("cama export: "), steps  # stopped at the first step
    workdir = client.app.state.jobs.workdir(job["id"])  # type: ignore[attr-defined]
    assert not workdir.exists() or list(workdir.iterdir()) == []  # no export, staging or archive
