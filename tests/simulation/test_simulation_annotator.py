"""The scripted annotator against the real backend app: it empties the queue through the HTTP API and books time."""

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from app.backend.main import create_app
from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Polyline, SimulationConfig
from app.review_effort.session import MemoryQueue, work_queue
from app.simulation.annotator import ApiSession, SimulationError, correct_proposals, draw_from_scratch
from tests.backend.backend_helpers import GEOREFERENCE, ORIGIN_XY, PASSWORD

TRUTH = [
    Polyline("boundary", np.array([[1010.0, 2010.0], [1090.0, 2010.0]])),
    Polyline("boundary", np.array([[1010.0, 2030.0], [1090.0, 2030.0]])),
    Polyline("divider", np.array([[1010.0, 2020.0], [1050.0, 2020.0], [1090.0, 2021.0]])),
    Polyline(
        "ped_crossing",
        np.array([[1060.0, 2011.0], [1064.0, 2011.0], [1064.0, 2029.0], [1060.0, 2029.0], [1060.0, 2011.0]]),
    ),
]


@pytest.fixture()
def client(tmp_path: Path) -> Iterator[TestClient]:
    settings = Settings(
        data_dir=tmp_path / "data",
        data_roots=(tmp_path,),
        scrypt_n=2**4,
        admin_username="root",
        admin_password=PASSWORD,
    )
    with TestClient(create_app(settings)) as test_client:
        yield test_client
    test_client.app.state.engine.dispose()  # type: ignore[attr-defined]


def _site(client: TestClient, tmp_path: Path, proposals: list[tuple[str, np.ndarray]]) -> int:
    """A lead registers a site, loads proposals (global points) and makes the annotator account."""
    admin = ApiSession(client, "root", PASSWORD)
    admin.call("POST", "/api/users", json={"username": "ann", "password": PASSWORD, "role": "annotator"})
    rasters = tmp_path / "bev"
    rasters.mkdir(exist_ok=True)
    body = {
        "name": "sim",
        "site_origin_xy": ORIGIN_XY,
        "georeference": GEOREFERENCE,
        "raster_dir": str(rasters),
    }
    site_id = int(admin.call("POST", "/api/sites", json=body)["id"])
    if proposals:
        elements = [
            {"class": cls, "points": (pts - ORIGIN_XY).tolist(), "confidence": 0.5, "source": "proposal"}
            for cls, pts in proposals
        ]
        admin.call("POST", f"/api/sites/{site_id}/elements/bulk", json={"elements": elements})
    return site_id


def test_correcting_proposals_accepts_fixes_rejects_and_draws_what_is_missing(
    client: TestClient, tmp_path: Path
) -> None:
    proposals = [
        ("boundary", TRUTH[0].points + [0.0, 0.05]),  # right: accept
        ("divider", TRUTH[1].points + [[0.0, 0.0], [0.0, 0.7]]),  # wrong class, one end off: fix + relabel
        ("divider", TRUTH[2].points + [[0.0, 0.0], [0.0, 1.2], [0.0, 0.0]]),  # middle off: fix
        ("divider", np.array([[1010.0, 2050.0], [1090.0, 2050.0]])),  # nothing there: reject
    ]  # the crosswalk was not proposed: drawn
    site_id = _site(client, tmp_path, proposals)
    annotator = ApiSession(client, "ann", PASSWORD)
    log = correct_proposals(annotator, site_id, TRUTH)
    assert dict(log.counts) == {
        "accept": 1,
        "fix": 2,
        "reject": 1,
        "drawn": 1,
        "vertices_moved": 2,
        "elements_moved_whole": 0,
        "pieces_merged": 0,
        "gaps_drawn": 0,
        "splits": 0,
    }
    assert annotator.call("POST", f"/api/sites/{site_id}/queue/next") is None
    final = annotator.call("GET", f"/api/sites/{site_id}/elements")
    states = sorted(e["state"] for e in final)
    assert states == ["accepted", "accepted", "fixed", "fixed", "rejected"]
    fixed = [e for e in final if e["state"] == "fixed"]
    assert {e["class"] for e in fixed} == {"boundary", "divider"}
    for element in fixed:
        truth = next(
            t
            for t in TRUTH
            if t.cls == element["class"]
            and abs(t.points[0, 1] - ORIGIN_XY[1] - element["points"][0][1]) < 0.01
        )
        np.testing.assert_allclose(np.asarray(element["points"])[[0, -1]], truth.points[[0, -1]] - ORIGIN_XY)
    assert log.road_km == pytest.approx(0.08)
    assert log.total_s > 0 and log.hours_per_km() > 0


def test_pieces_of_a_long_element_are_merged_into_one_through_the_api(
    client: TestClient, tmp_path: Path
) -> None:
    left = ("boundary", np.array([[1010.0, 2010.1], [1040.0, 2010.1]]))
    right = ("boundary", np.array([[1055.0, 2009.9], [1090.0, 2009.9]]))
    site_id = _site(client, tmp_path, [left, right])
    annotator = ApiSession(client, "ann", PASSWORD)
    log = correct_proposals(annotator, site_id, TRUTH[:1])
    assert (log.counts["fix"], log.counts["pieces_merged"], log.counts["gaps_drawn"]) == (1, 1, 0)
    final = annotator.call("GET", f"/api/sites/{site_id}/elements")
    assert [e["state"] for e in final] == ["fixed"]  # the merged piece is deleted, as the editor's merge does
    np.testing.assert_allclose(final[0]["points"], TRUTH[0].points - ORIGIN_XY)


def test_a_proposal_bridging_two_elements_is_split_into_both_through_the_api(
    client: TestClient, tmp_path: Path
) -> None:
    pieces = [  # one divider, cut where a parked car hid 1035-1045 m: two elements in the truth
        Polyline("divider", np.array([[1010.0, 2020.0], [1035.0, 2020.0]])),
        Polyline("divider", np.array([[1045.0, 2020.0], [1090.0, 2020.0]])),
    ]
    bridged = ("divider", np.array([[1010.0, 2020.05], [1090.0, 2020.05]]))
    site_id = _site(client, tmp_path, [bridged])
    annotator = ApiSession(client, "ann", PASSWORD)
    log = correct_proposals(annotator, site_id, pieces)
    assert (log.counts["splits"], log.counts["fix"], log.counts["drawn"]) == (1, 1, 0)
    final = annotator.call("GET", f"/api/sites/{site_id}/elements")
    assert sorted(e["state"] for e in final) == ["accepted", "fixed"]  # the split-off part is a new element
    ends = sorted(np.asarray(e["points"])[[0, -1], 0].round(6).tolist() for e in final)
    assert ends == [
        [1010.0 - ORIGIN_XY[0], 1035.0 - ORIGIN_XY[0]],
        [1045.0 - ORIGIN_XY[0], 1090.0 - ORIGIN_XY[0]],
    ]
    queue = MemoryQueue([(Polyline(*bridged), 0.5)])
    in_memory = work_queue(queue, pieces, SimulationConfig(), ActionCosts())
    assert in_memory.counts == log.counts and in_memory.seconds == pytest.approx(log.seconds)


def test_good_proposals_cost_less_than_drawing_from_scratch(client: TestClient, tmp_path: Path) -> None:
    near = [(t.cls, t.points + [0.0, 0.05]) for t in TRUTH]
    corrected = correct_proposals(ApiSession(client, "root", PASSWORD), _site(client, tmp_path, near), TRUTH)
    admin = ApiSession(client, "root", PASSWORD)
    body = {
        "name": "empty",
        "site_origin_xy": ORIGIN_XY,
        "georeference": GEOREFERENCE,
        "raster_dir": str(tmp_path / "bev"),
    }
    empty = int(admin.call("POST", "/api/sites", json=body)["id"])
    drawn = draw_from_scratch(admin, empty, TRUTH)
    assert drawn.counts["drawn"] == len(TRUTH) and corrected.counts["accept"] == len(TRUTH)
    assert corrected.total_s < drawn.total_s
    assert len(admin.call("GET", f"/api/sites/{empty}/elements")) == len(TRUTH)


def test_a_refused_request_names_the_request(client: TestClient) -> None:
    with pytest.raises(SimulationError, match="POST /api/auth/login: HTTP 401"):
        ApiSession(client, "nobody", PASSWORD)


def test_the_in_memory_queue_books_what_the_backend_queue_books(client: TestClient, tmp_path: Path) -> None:
    proposals = [
        ("boundary", TRUTH[0].points + [0.0, 0.05]),
        ("divider", TRUTH[1].points + [[0.0, 0.0], [0.0, 0.7]]),
        ("divider", TRUTH[2].points + [[0.0, 0.0], [0.0, 1.2], [0.0, 0.0]]),
        ("divider", np.array([[1010.0, 2050.0], [1090.0, 2050.0]])),
        ("boundary", np.array([[1055.0, 2029.9], [1090.0, 2029.9]])),  # a second piece of TRUTH[1]
    ]
    confidences = [0.9, 0.2, 0.5, 0.3, 0.4]
    admin_site = _site(client, tmp_path, [])
    admin = ApiSession(client, "root", PASSWORD)
    elements = [
        {"class": cls, "points": (pts - ORIGIN_XY).tolist(), "confidence": c, "source": "proposal"}
        for (cls, pts), c in zip(proposals, confidences, strict=True)
    ]
    admin.call("POST", f"/api/sites/{admin_site}/elements/bulk", json={"elements": elements})
    over_http = correct_proposals(ApiSession(client, "ann", PASSWORD), admin_site, TRUTH)
    queue = MemoryQueue(
        [(Polyline(cls, pts), c) for (cls, pts), c in zip(proposals, confidences, strict=True)]
    )
    in_memory = work_queue(queue, TRUTH, SimulationConfig(), ActionCosts())
    assert in_memory.counts == over_http.counts
    assert in_memory.seconds == pytest.approx(over_http.seconds)
    assert in_memory.counts["pieces_merged"] == 1 and len(queue.drawn) == in_memory.counts["drawn"] == 1
    kinds = sorted(decision.kind for decision in queue.verdicts.values())  # the merged piece has no verdict
    assert kinds == ["accept", "fix", "fix", "reject"] and not queue.waiting
