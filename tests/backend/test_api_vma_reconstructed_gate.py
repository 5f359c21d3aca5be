"""The retrain gate on reconstructed validation sites (CAMA_VMA_VALIDATION_RECONSTRUCTED): the candidate and the
promoted network are scored on the surface stage's rasters of a synthetic site, and a configured site without a
reconstruction fails the job with the site named."""

import json
import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from cama_studio.pipeline import PipelineResult
from models.vma.shipped import SHIPPED_MASK_REGISTRY, shipped_registry
from tests.backend.backend_helpers import register_site
from tests.backend.test_api_vma_loop import (
    HANG_S,
    TINY_RETRAIN,
    Headers,
    bulk,
    loop_settings,
    review,
    submit,
    wait_for,
)
from tests.backend.vma_loop_site import DIVIDER_Y, write_site
from tests.conftest import GeneratedSite


def site_with_its_workspace(tiny_site: GeneratedSite, workspace: Path, where: Path) -> Path:
    """The tiny site as `cama synth` + `cama run` leave it (the workspace beside the data set), made of links."""
    where.mkdir(parents=True)
    for name in ("ground_truth", "nuscenes", "manifest.json"):
        (where / name).symlink_to(tiny_site.result.out_dir / name)
    (where / "workspace").symlink_to(workspace)
    return where


@pytest.fixture
def reconstructed_site(tiny_site: GeneratedSite, whole_path: PipelineResult, tmp_path: Path) -> Path:
    return site_with_its_workspace(tiny_site, whole_path.workspace, tmp_path / "reconstructed")


@pytest.fixture
def settings(tmp_path: Path, database_url: str | None, reconstructed_site: Path) -> Settings:
    """An element-mask registry gated on the tiny site's reconstruction only."""
    registry = tmp_path / "mask-registry"
    shutil.copytree(shipped_registry(*SHIPPED_MASK_REGISTRY), registry)
    write_site(tmp_path / "site")
    return loop_settings(
        tmp_path, database_url, vma_registry=registry, vma_validation_reconstructed=(reconstructed_site,)
    )


def corrected_site(client: TestClient, headers: Headers, tmp_path: Path) -> int:
    """The loop's BEV site with one fixed divider."""
    site_id = register_site(client, headers["lead"], tmp_path / "site" / "ground_truth" / "bev", "loop")
    drawn = bulk(
        client, headers, site_id, [{"class": "divider", "points": [[5.0, DIVIDER_Y], [95.0, DIVIDER_Y]]}]
    )
    review(client, headers, site_id, drawn[0], "fixed", "annotator")
    return site_id


@pytest.mark.slow  # a spawned child imports torch, fine-tunes and evaluates twice
def test_the_gate_scores_both_networks_on_the_reconstruction(
    client: TestClient, headers: Headers, settings: Settings, tmp_path: Path, reconstructed_site: Path
) -> None:
    site_id = corrected_site(client, headers, tmp_path)
    job = submit(client, headers, site_id, "retrain", **TINY_RETRAIN)
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "succeeded", done["message"]
    outcome = json.loads(client.get(done["download_url"], headers=headers["lead"]).content)
    for metrics in (outcome["current_metrics"], outcome["candidate_metrics"]):
        (site,) = metrics["sites"]
        assert site.startswith(str(reconstructed_site)) and "reconstructed: " in site and "surface" in site
        assert metrics["review"]["speed_up"] is not None
    meta = json.loads(
        (Path(settings.vma_registry or "") / outcome["candidate"] / "checkpoint.json").read_text()
    )
    assert meta["data"]["validation_sites"] == [site]
    assert "validation mAP" in done["message"] and "simulated annotator" in done["message"]
    assert "on 1 validation site(s), 1 of them reconstructed" in done["message"], done["message"]


def test_a_reconstructed_validation_site_without_a_reconstruction_fails_the_job_named(
    client: TestClient, headers: Headers, settings: Settings, tmp_path: Path, reconstructed_site: Path
) -> None:
    (reconstructed_site / "workspace").unlink()
    site_id = corrected_site(client, headers, tmp_path)
    job = submit(client, headers, site_id, "retrain", **TINY_RETRAIN)
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "failed"
    assert str(reconstructed_site) in done["message"] and "cama run" in done["message"]


def test_the_reconstructed_validation_sites_come_from_the_environment(tmp_path: Path) -> None:
    environ = {"CAMA_VMA_VALIDATION_RECONSTRUCTED": f"{tmp_path / 'a'}:{tmp_path / 'b'}"}
    settings = Settings.from_env(environ, data_dir=tmp_path)
    assert settings.vma_validation_reconstructed == (tmp_path / "a", tmp_path / "b")
