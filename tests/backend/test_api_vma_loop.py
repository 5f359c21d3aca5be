"""The VMA loop through HTTP: proposal refresh (only untouched proposals replaced, pre-accept and the QA sample),
retraining behind the gate with a tiny model, its cancellation, and auto-retrain after enough corrections."""

import json
import re
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from tests.backend.backend_helpers import PASSWORD, divider, register_site
from tests.backend.vma_loop_site import DIVIDER_Y, ROAD_Y, write_registry, write_site

Headers = dict[str, dict[str, str]]
HANG_S = 600.0
"""Longest wait for any job: a guard against a hung job, not a speed check (a spawned retrain child imports torch,
fine-tunes a few steps and evaluates twice, which on a loaded 2-core machine took past 90 s)."""
TINY_RETRAIN = {"steps": 2, "batch_size": 2, "learning_rate": 1e-3}


@pytest.fixture
def loop_site(tmp_path: Path) -> Path:
    """The drawn site folder (its rasters in ground_truth/bev)."""
    write_site(tmp_path / "site")
    return tmp_path / "site"


@pytest.fixture
def settings(tmp_path: Path, database_url: str | None, loop_site: Path) -> Settings:
    """Backend settings with a tiny registry, a copy of the drawn site as validation site (the retrain refuses
    to validate on the folder it trains on), auto-retrain after 2,
    pre-accept at confidence 0.9 (the rule-based proposer's clean lines score 1.0) and half of those to QA."""
    return loop_settings(
        tmp_path,
        database_url,
        vma_registry=write_registry(tmp_path / "registry"),
        vma_validation_sites=(write_site(tmp_path / "validation").parents[1],),
        retrain_after=2,
        qa_share=0.5,
        preaccept_threshold=0.9,
    )


def loop_settings(tmp_path: Path, database_url: str | None, **loop: Any) -> Settings:
    """Settings of a loop test under `tmp_path` (an admin, fast password hashing) with these VMA `loop` settings."""
    return Settings(
        data_dir=tmp_path / "data",
        data_roots=(tmp_path,),
        database_url=database_url,
        scrypt_n=2**4,
        extent_margin_m=10.0,
        admin_username="root",
        admin_password=PASSWORD,
        **loop,
    )


@pytest.fixture
def site_id(client: TestClient, headers: Headers, loop_site: Path) -> int:
    return register_site(client, headers["lead"], loop_site / "ground_truth" / "bev", "loop")


def submit(client: TestClient, headers: Headers, site_id: int, kind: str, **params: Any) -> dict[str, Any]:
    response = client.post(
        f"/api/sites/{site_id}/jobs", json={"kind": kind, "params": params}, headers=headers["lead"]
    )
    assert response.status_code == 202, response.text
    return dict(response.json())


def job_now(client: TestClient, headers: Headers, job_id: int) -> dict[str, Any]:
    return dict(client.get(f"/api/jobs/{job_id}", headers=headers["lead"]).json())


def wait_for(client: TestClient, headers: Headers, job_id: int, states: set[str], timeout_s: float) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(f"/api/jobs/{job_id}", headers=headers["lead"]).json()
        if job["state"] in states:
            return dict(job)
        time.sleep(0.05)
    raise AssertionError(f"job {job_id} still {job['state']} ({job['message']}) after {timeout_s} s")


def bulk(client: TestClient, headers: Headers, site_id: int, bodies: list[dict]) -> list[dict[str, Any]]:
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": bodies}, headers=headers["lead"]
    )
    assert response.status_code == 201, response.text
    return list(response.json())


def review(client: TestClient, headers: Headers, site_id: int, element: dict, state: str, who: str) -> dict:
    response = client.post(
        f"/api/sites/{site_id}/elements/{element['id']}/review",
        json={"state": state, "version": element["version"]},
        headers=headers[who],
    )
    assert response.status_code == 200, response.text
    return dict(response.json())


def live(client: TestClient, headers: Headers, site_id: int) -> list[dict[str, Any]]:
    return list(client.get(f"/api/sites/{site_id}/elements", headers=headers["lead"]).json())


def proposal(y: float, confidence: float, x0: float = 10.0) -> dict[str, Any]:
    return divider(x0, y, source="proposal", confidence=confidence)


def refresh(client: TestClient, headers: Headers, site_id: int) -> dict[str, Any]:
    job = submit(client, headers, site_id, "refresh_proposals", proposer="rule")
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "succeeded", done["message"]
    return done


def test_refresh_replaces_only_untouched_proposals(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    on_divider = {"class": "divider", "points": [[5.0, DIVIDER_Y], [95.0, DIVIDER_Y]]}
    leased, untouched, edited, reviewed = bulk(
        client,
        headers,
        site_id,
        [
            proposal(10.0, 0.05),
            proposal(20.0, 0.5),
            proposal(80.0, 0.6),
            {**on_divider, "source": "proposal", "confidence": 0.7},
        ],
    )
    lease = client.post(f"/api/sites/{site_id}/queue/next", headers=headers["annotator"]).json()
    assert lease["element_id"] == leased["id"]
    patched = client.patch(
        f"/api/sites/{site_id}/elements/{edited['id']}",
        json={"version": edited["version"], "confidence": 0.65},
        headers=headers["annotator"],
    )
    assert patched.status_code == 200, patched.text
    review(client, headers, site_id, reviewed, "accepted", "annotator")
    job = refresh(client, headers, site_id)
    assert "replaced 1 untouched proposals by 2" in job["message"] and "1 already covered" in job["message"]
    elements = {e["id"]: e for e in live(client, headers, site_id)}
    assert untouched["id"] not in elements
    assert {leased["id"], edited["id"], reviewed["id"]} <= set(elements)
    new = [e for e in elements.values() if e["author"] == "vma-loop"]
    assert sorted(e["class"] for e in new) == [
        "boundary",
        "boundary",
    ]  # the divider is covered by reviewed work
    assert all(e["state"] == "accepted" and e["preaccepted"] and e["source"] == "proposal" for e in new)
    assert {e["proposed_by"] for e in new} == {"vma-rule-based"}  # the proposer that made them
    assert sorted(round(e["points"][0][1]) for e in new) == [round(ROAD_Y[0] + 0.5), round(ROAD_Y[1] + 0.5)]
    history = client.get(f"/api/sites/{site_id}/elements/{untouched['id']}/history", headers=headers["lead"])
    assert [entry["action"] for entry in history.json()] == ["create", "refresh"]
    assert history.json()[-1]["after"]["deleted"] is True


def test_confident_proposals_enter_preaccepted_and_a_sample_goes_to_qa(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    refresh(client, headers, site_id)
    new = live(client, headers, site_id)
    assert len(new) == 3 and all(e["state"] == "accepted" and e["preaccepted"] for e in new)
    sampled = {e["id"] for e in new if e["qa_sample"]}
    assert len(sampled) == 2  # round(0.5 * 3)
    qa = client.get(f"/api/sites/{site_id}/queue/review?qa=true", headers=headers["lead"]).json()
    assert {item["id"] for item in qa["items"]} == sampled
    assert client.post(f"/api/sites/{site_id}/queue/next", headers=headers["annotator"]).status_code == 204
    diffs = f"/api/sites/{site_id}/diffs"
    assert client.get(diffs, headers=headers["lead"]).json() == []  # no person has reviewed them yet
    returned = review(
        client, headers, site_id, next(e for e in new if e["id"] in sampled), "returned", "lead"
    )
    lease = client.post(f"/api/sites/{site_id}/queue/next", headers=headers["annotator"]).json()
    assert lease["element_id"] == returned["id"]  # nobody's own work: anyone may take it
    assert sum(row["elements"] for row in client.get(diffs, headers=headers["lead"]).json()) == 1
    again = refresh(
        client, headers, site_id
    )  # the two untouched pre-accepted ones are replaced, no duplicates
    assert "replaced 2 untouched proposals by 2" in again["message"], again["message"]
    assert len(live(client, headers, site_id)) == 3


@pytest.mark.slow  # ~25 s: the child imports torch and the model's first steps warm up
def test_retrain_runs_the_gate_and_queues_a_refresh_after_promotion(
    client: TestClient, headers: Headers, site_id: int, settings: Settings, tmp_path: Path
) -> None:
    drawn = bulk(
        client, headers, site_id, [{"class": "divider", "points": [[5.0, DIVIDER_Y], [95.0, DIVIDER_Y]]}]
    )
    review(client, headers, site_id, drawn[0], "fixed", "annotator")
    other = register_site(
        client, headers["lead"], write_site(tmp_path / "other"), "other"
    )  # corrected elsewhere
    elsewhere = bulk(client, headers, other, [{"class": "boundary", "points": [[5.0, 30.0], [95.0, 30.0]]}])
    review(client, headers, other, elsewhere[0], "accepted", "annotator")
    job = submit(client, headers, site_id, "retrain", **TINY_RETRAIN)
    done = wait_for(client, headers, job["id"], {"succeeded", "failed"}, HANG_S)
    assert done["state"] == "succeeded", done["message"]
    outcome = json.loads(client.get(done["download_url"], headers=headers["lead"]).content)
    assert outcome["labels"] == 2 and outcome["candidate"] == "v0002"  # both sites' corrections
    corrections = json.loads((Path(settings.vma_registry or "") / "v0002" / "checkpoint.json").read_text())
    assert len(corrections["data"]["corrections"]) == 2
    assert "validation mAP" in done["message"] and ("promoted" in done["message"]) == outcome["promoted"]
    reviewed = outcome["current_metrics"]["review"], outcome["candidate_metrics"]["review"]
    assert all(r["drawing_s"] > 0 and r["correction_s"] > 0 for r in reviewed)  # the annotator gate ran
    assert "simulated annotator" in done["message"] and "faster than drawing" in done["message"]
    # each site's time, which the gate's confidence in a saving reads
    assert all(len(r["per_site_correction_s"]) == len(r["sites"]) for r in reviewed)
    saved = reviewed[1]["correction_s"] < reviewed[0]["correction_s"]
    assert ("of resamples of the sites (90% needed)" in done["message"]) == saved
    if outcome["promoted"]:  # both gates passed
        assert reviewed[1]["correction_s"] <= reviewed[0]["correction_s"]
    assert (Path(settings.vma_registry or "") / "v0002" / "checkpoint.json").is_file()
    if outcome["promoted"]:
        jobs = client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json()
        assert jobs[0]["kind"] == "refresh_proposals" and jobs[0]["created_by"] == f"job {job['id']}"


def test_retrain_without_labels_fails_clearly(client: TestClient, headers: Headers, site_id: int) -> None:
    bulk(client, headers, site_id, [proposal(20.0, 0.5)])
    done = wait_for(
        client,
        headers,
        submit(client, headers, site_id, "retrain", **TINY_RETRAIN)["id"],
        {"succeeded", "failed"},
        HANG_S,
    )
    assert done["state"] == "failed" and "no accepted, fixed or approved elements" in done["message"]


def test_retrain_reports_its_steps_and_is_cancellable(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    element = bulk(client, headers, site_id, [proposal(20.0, 0.5)])[0]
    review(client, headers, site_id, element, "accepted", "annotator")
    job = submit(client, headers, site_id, "retrain", steps=100_000)
    deadline = time.monotonic() + HANG_S
    while not re.search(
        r"step \d+/100000, loss \d", (running := job_now(client, headers, job["id"]))["message"]
    ):
        assert time.monotonic() < deadline, running["message"]
        time.sleep(0.1)
    assert 0.1 <= running["progress"] < 0.9  # the training steps' share of the job
    assert client.post(f"/api/jobs/{job['id']}/cancel", headers=headers["lead"]).status_code == 200
    done = wait_for(client, headers, job["id"], {"cancelled", "failed", "succeeded"}, HANG_S)
    assert done["state"] == "cancelled"


def test_auto_retrain_starts_once_after_enough_corrections(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    elements = bulk(client, headers, site_id, [proposal(y, 0.5) for y in (10.0, 20.0, 80.0)])
    review(client, headers, site_id, elements[0], "accepted", "annotator")
    assert client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json() == []
    review(client, headers, site_id, elements[1], "rejected", "annotator")  # not a correction that counts
    assert client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json() == []
    review(client, headers, site_id, elements[2], "fixed", "annotator")
    jobs = client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json()
    assert [(j["kind"], j["created_by"]) for j in jobs] == [("retrain", "auto-retrain")]
    assert jobs[0]["state"] in ("queued", "running")
    more = bulk(client, headers, site_id, [proposal(y, 0.5, x0=60.0) for y in (10.0, 20.0)])
    for element in more:
        review(client, headers, site_id, element, "accepted", "annotator")
    assert len(client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json()) == 1


def test_bulk_proposals_above_the_configured_threshold_enter_preaccepted(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    stored = bulk(client, headers, site_id, [proposal(10.0, 0.95), proposal(20.0, 0.9), proposal(80.0, 0.5)])
    assert [(e["state"], e["preaccepted"], e["version"]) for e in stored] == [
        ("accepted", True, 1),
        ("accepted", True, 1),
        ("proposed", False, 1),
    ]
    assert sum(e["qa_sample"] for e in stored) == 1  # round(0.5 * 2)
    history = client.get(f"/api/sites/{site_id}/elements/{stored[0]['id']}/history", headers=headers["lead"])
    assert [(h["action"], h["after"]["state"]) for h in history.json()] == [("create", "accepted")]
