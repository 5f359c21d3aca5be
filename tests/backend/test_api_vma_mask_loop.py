"""The VMA loop with an element-mask registry: the server's refresh proposes with the network the registry holds,
and a retrain job fine-tunes that network (its candidate is an element-mask version that names what it saw)."""

import json
import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from models.vma.checkpoint import checkpoint_kind
from models.vma.element_masks.checkpoint import KIND
from models.vma.shipped import SHIPPED_MASK_REGISTRY, shipped_registry
from tests.backend.backend_helpers import register_site
from tests.backend.test_api_vma_loop import (
    HANG_S,
    TINY_RETRAIN,
    Headers,
    bulk,
    live,
    loop_settings,
    review,
    submit,
    wait_for,
)
from tests.backend.vma_loop_site import DIVIDER_Y, write_site


@pytest.fixture
def loop_site(tmp_path: Path) -> Path:
    write_site(tmp_path / "site")
    return tmp_path / "site"


@pytest.fixture
def settings(tmp_path: Path, database_url: str | None, loop_site: Path) -> Settings:
    """Settings whose registry is a copy of the shipped element-mask registry."""
    registry = tmp_path / "mask-registry"
    shutil.copytree(shipped_registry(*SHIPPED_MASK_REGISTRY), registry)
    return loop_settings(
        tmp_path,
        database_url,
        vma_registry=registry,
        vma_validation_sites=(write_site(tmp_path / "validation").parents[1],),
    )


@pytest.fixture
def site_id(client: TestClient, headers: Headers, loop_site: Path) -> int:
    return register_site(client, headers["lead"], loop_site / "ground_truth" / "bev", "loop")


def test_refresh_proposes_with_the_registrys_element_mask_network(
    client: TestClient, headers: Headers, site_id: int, settings: Settings
) -> None:
    job = submit(client, headers, site_id, "refresh_proposals")
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "succeeded", done["message"]
    elements = live(client, headers, site_id)
    version = json.loads((Path(settings.vma_registry or "") / "current.json").read_text())["version"]
    assert elements and {e["proposed_by"] for e in elements} == {f"vma-masks-{version}"}
    on_paint = [
        e
        for e in elements
        if e["class"] == "divider" and all(abs(p[1] - DIVIDER_Y) < 0.5 for p in e["points"])
    ]
    assert on_paint and on_paint[0]["points"][-1][0] - on_paint[0]["points"][0][0] > 80.0


@pytest.mark.slow  # a spawned child imports torch, fine-tunes and evaluates twice
def test_retrain_fine_tunes_the_element_mask_network(
    client: TestClient, headers: Headers, site_id: int, settings: Settings
) -> None:
    drawn = bulk(
        client, headers, site_id, [{"class": "divider", "points": [[5.0, DIVIDER_Y], [95.0, DIVIDER_Y]]}]
    )
    review(client, headers, site_id, drawn[0], "fixed", "annotator")
    job = submit(client, headers, site_id, "retrain", **TINY_RETRAIN, replay_share=0.5)
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "succeeded", done["message"]
    outcome = json.loads(client.get(done["download_url"], headers=headers["lead"]).content)
    candidate = Path(settings.vma_registry or "") / outcome["candidate"]
    assert checkpoint_kind(candidate) == KIND and outcome["labels"] == 1
    meta = json.loads((candidate / "checkpoint.json").read_text())
    assert meta["train_config"]["steps"] == TINY_RETRAIN["steps"] and len(meta["data"]["corrections"]) == 1
    # it rehearsed four of the shipped network's own training sites
    assert meta["replay"]["share"] == 0.5 and len(meta["replay"]["sites"]) == 4
    assert "validation mAP" in done["message"] and "simulated annotator" in done["message"]
    assert "on 1 validation site(s), 0 of them reconstructed" in done["message"], done["message"]


@pytest.mark.parametrize("share", [1.0, -0.5])
def test_a_replay_share_outside_0_to_1_is_refused_with_the_field_named(
    client: TestClient, headers: Headers, site_id: int, share: float
) -> None:
    body = {"kind": "retrain", "params": {"replay_share": share}}
    response = client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["lead"])
    assert response.status_code == 422 and "replay_share" in response.text
