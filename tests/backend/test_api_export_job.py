"""The editor's export job (issue 24.9), on sites without a reconstruction: every format is offered, a bad
request is a 4xx at submission naming the field (a refined-pose export of a site without a reconstruction among
them), an export that needs neither data set nor poses runs, and a failing export leaves nothing behind."""

import io
import re
import shutil
import time
import zipfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS
from cama_pipeline.export import CamaMode, ExportFormat, PoseChoice
from cama_pipeline.export import run as export_run
from cama_pipeline.export.request import FORMATS_NEEDING_DATASET
from cama_pipeline.export.run import ExportInputs
from cama_pipeline.semantics import Semantic
from cama_pipeline.site.io import write_sites_index
from cama_pipeline.workspace import Workspace
from tests.backend.backend_helpers import crosswalk, divider, register_site

Headers = dict[str, dict[str, str]]
POLL_TIMEOUT_S = 60.0
ORIGIN = [1.299, 103.788]


def post_export(client: TestClient, headers: Headers, site_id: int, **params: Any) -> Any:
    """Submit an export as the lead; the response."""
    body = {"kind": "export", "params": params}
    return client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["lead"])


def wait_done(client: TestClient, headers: Headers, job_id: int) -> dict[str, Any]:
    deadline = time.monotonic() + POLL_TIMEOUT_S
    while (job := client.get(f"/api/jobs/{job_id}", headers=headers["lead"]).json())["state"] in (
        "queued",
        "running",
    ):
        assert time.monotonic() < deadline, job
        time.sleep(0.02)
    return dict(job)


def enum_of(schema: dict[str, Any], field: str) -> set[str]:
    """The allowed values of an enum field of a params JSON Schema (inline or through `$defs`)."""
    spec = schema["properties"][field]
    if "$ref" in spec:
        spec = schema["$defs"][spec["$ref"].rsplit("/", 1)[-1]]
    return set(spec["enum"])


def test_every_format_and_option_is_offered(client: TestClient, headers: Headers) -> None:
    kinds = client.get("/api/job-kinds", headers=headers["annotator"])
    assert kinds.status_code == 200, kinds.text
    export = next(kind for kind in kinds.json() if kind["kind"] == "export")
    assert export["available"] is True
    schema = export["params_schema"]
    assert enum_of(schema, "format") == {choice.value for choice in ExportFormat}
    assert enum_of(schema, "poses") == {choice.value for choice in PoseChoice}
    assert enum_of(schema, "mode") == {choice.value for choice in CamaMode}
    assert {"with_clip_data", "origin_lat_lon", "dataset_root", "scenes"} <= set(schema["properties"])
    assert {"origin_location", "projection"} <= set(schema["properties"])
    assert schema["properties"]["poses"]["default"] == "refined"
    assert client.get("/api/job-kinds").status_code == 401


@pytest.mark.parametrize(
    ("params", "field", "words"),
    [
        ({"format": "shapefile"}, "format", "'cama', 'maptr', 'nuscenes-cama' or 'lanelet2'"),
        ({"format": "maptr", "poses": "best"}, "poses", "'refined' or 'coarse'"),
        ({"format": "maptr"}, "dataset_root", "required for format 'maptr'"),
        ({"format": "cama"}, "dataset_root", "required for format 'cama'"),
        ({"format": "nuscenes-cama"}, "dataset_root", "required for format 'nuscenes-cama'"),
        ({"format": "lanelet2"}, "origin_lat_lon", "site 's1' has no reconstruction whose location"),
        ({"format": "lanelet2", "origin_location": "mars"}, "origin_location", "one of ['boston-seaport'"),
        (
            {"format": "lanelet2", "origin_lat_lon": ORIGIN, "origin_location": "boston-seaport"},
            "origin_location",
            "one or",
        ),
        ({"format": "lanelet2", "projection": "mercator"}, "projection", "'local' or 'utm'"),
        (
            {"format": "maptr", "projection": "utm"},
            "projection",
            "only for format 'lanelet2'",
        ),
        ({"format": "lanelet2", "origin_lat_lon": [91.0, 0.0]}, "origin_lat_lon", "lat in [-90, 90]"),
        ({"format": "lanelet2", "origin_lat_lon": [1.0]}, "origin_lat_lon", "at least 2 items"),
        ({"format": "lanelet2", "origin_lat_lon": ["1", "2"]}, "origin_lat_lon.0", "valid number"),
        ({"format": "lanelet2", "origin_lat_lon": ORIGIN, "with_clip_data": True}, "with_clip_data", "only"),
        ({"format": "lanelet2", "origin_lat_lon": ORIGIN, "scenes": []}, "scenes", "at least 1 item"),
        ({"format": "lanelet2", "origin_lat_lon": ORIGIN, "colour": "red"}, "colour", "Extra inputs"),
    ],
)
def test_bad_requests_are_422_naming_the_field(
    client: TestClient, headers: Headers, site_id: int, params: dict[str, Any], field: str, words: str
) -> None:
    response = post_export(client, headers, site_id, **params)
    assert response.status_code == 422, response.text
    assert f"{field}: " in response.text and words in response.text
    assert client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json() == []


def test_refined_export_of_a_site_without_reconstruction_is_refused_at_submission(
    client: TestClient, headers: Headers, site_id: int, raster_dir: Path, tmp_path: Path
) -> None:
    """The conftest site's rasters are no surface stage's output; a workspace-shaped copy has no SfM poses."""
    with_poses = sorted(fmt.value for fmt in FORMATS_NEEDING_DATASET if fmt in export_run.WRITERS)
    assert "maptr" in with_poses and "cama" in with_poses
    for fmt in with_poses:
        response = post_export(client, headers, site_id, format=fmt, dataset_root=str(tmp_path))
        assert response.status_code == 422, response.text
        detail = response.json()["detail"][0]
        assert detail["loc"] == ["body", "poses"]
        assert "has no reconstruction" in detail["msg"] and "poses 'coarse'" in detail["msg"]
        assert str(tmp_path) not in response.text
    bev = tmp_path / "ws" / "surface" / "site-001" / "bev"
    shutil.copytree(raster_dir, bev)
    in_workspace = register_site(client, headers["lead"], bev, "in a workspace")
    response = post_export(client, headers, in_workspace, format="maptr", dataset_root=str(tmp_path))
    assert response.status_code == 422, response.text
    assert "no SfM poses for site 'site-001'" in response.text and str(tmp_path) not in response.text
    assert client.get(f"/api/sites/{site_id}/jobs", headers=headers["lead"]).json() == []
    # the check is about poses only: lanelet2 takes none
    lanelet2 = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    assert lanelet2.status_code == 202, lanelet2.text


def test_a_format_without_a_writer_is_refused_at_submission(
    client: TestClient, headers: Headers, site_id: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delitem(export_run.WRITERS, ExportFormat.lanelet2)
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    assert response.status_code == 422, response.text
    assert "format: 'lanelet2' is not available in this build" in response.text


def test_lanelet2_export_zips_one_osm_file(
    client: TestClient, headers: Headers, site_id: int, make_element: Any
) -> None:
    made = [make_element(divider()), make_element(crosswalk())]
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    assert response.status_code == 202, response.text
    done = wait_done(client, headers, response.json()["id"])
    assert done["state"] == "succeeded", done["message"]
    assert (
        "exported 2 elements of s1 (lanelet2, 1 files, 0 of 2 lifted (no elevation raster)" in done["message"]
    )
    assert "tags (" in done["message"]
    archive = client.get(done["download_url"], headers=headers["lead"])
    with zipfile.ZipFile(io.BytesIO(archive.content)) as bundle:
        assert bundle.namelist() == ["map.osm"]
        osm = bundle.read("map.osm").decode()
    assert all(f'k="cama:id" v="{element["id"]}"' in osm for element in made)
    workdir = client.app.state.jobs.workdir(done["id"])  # type: ignore[attr-defined]
    assert sorted(path.name for path in workdir.iterdir()) == ["export.zip"]


def test_lanelet2_without_an_origin_takes_the_reconstructions_nuscenes_location(
    client: TestClient, headers: Headers, raster_dir: Path, tmp_path: Path
) -> None:
    """A site whose reconstruction lies at a nuScenes location exports at that location's origin with the local
    projection; at a location without a known origin it is refused at submission, naming the location."""
    workspace = Workspace(tmp_path / "ws")
    shutil.copytree(raster_dir, workspace.surface_bev("site-001"))
    index = {"sites": [{"site_id": "site-001", "location": "synthetic-default", "scenes": []}], "dropped": []}
    write_sites_index(workspace.sites_index(), index)
    site_id = register_site(client, headers["lead"], workspace.surface_bev("site-001"), "seaport")
    refused = post_export(client, headers, site_id, format="lanelet2")
    assert refused.status_code == 422, refused.text
    assert "site 'seaport' lies at 'synthetic-default', whose map origin is not known" in refused.text
    assert str(tmp_path) not in refused.text
    index["sites"][0]["location"] = "boston-seaport"
    write_sites_index(workspace.sites_index(), index)
    element = client.post(f"/api/sites/{site_id}/elements", json=divider(), headers=headers["annotator"])
    assert element.status_code == 201, element.text
    response = post_export(client, headers, site_id, format="lanelet2")
    assert response.status_code == 202, response.text
    done = wait_done(client, headers, response.json()["id"])
    assert done["state"] == "succeeded", done["message"]
    boston = NUSCENES_MAP_ORIGINS["boston-seaport"]
    assert (
        "origin_lat_lon 2, projection local, origin_source site site-001 at boston-seaport" in done["message"]
    )
    archive = client.get(done["download_url"], headers=headers["lead"])
    with zipfile.ZipFile(io.BytesIO(archive.content)) as bundle:
        osm = bundle.read("map.osm").decode()
    node = re.search(r'lat="([-.0-9]+)" lon="([-.0-9]+)"', osm)
    assert node is not None, osm
    lat, lon = (float(value) for value in node.groups())
    assert abs(lat - boston[0]) < 0.05 and abs(lon - boston[1]) < 0.05  # the test site lies 2 km from (0, 0)


def _exported_osm(client: TestClient, headers: Headers, site_id: int) -> tuple[str, str]:
    """Export the site as Lanelet2; the job's message and the OSM file."""
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    assert response.status_code == 202, response.text
    done = wait_done(client, headers, response.json()["id"])
    assert done["state"] == "succeeded", done["message"]
    archive = client.get(done["download_url"], headers=headers["lead"])
    with zipfile.ZipFile(io.BytesIO(archive.content)) as bundle:
        return done["message"], bundle.read("map.osm").decode()


def test_lanelet2_kerbs_come_from_the_site_semantic_raster(
    client: TestClient, headers: Headers, site_id: int, make_element: Any, raster_dir: Path
) -> None:
    """Boundaries along y 40 (a kerb above the road) and y 20 (the road's grass edge); the site's raster folder
    first has an unreadable semantic.png (the export runs, every boundary an assumed kerb), then a real one."""
    for y in (40.0, 20.0):
        make_element({"class": "boundary", "points": [[10.0, y], [35.0, y], [60.0, y]]})
    message, osm = _exported_osm(client, headers, site_id)
    assert "kerbs (observed 0, none 0, assumed 2)" in message
    assert osm.count('k="cama:kerb" v="assumed"') == 2 and 'v="road_border"' not in osm
    rows = np.arange(200)[:, None].repeat(200, axis=1)
    y_site = 100.0 - 0.5 * rows  # the test georeference: row 0 at site y 100, 0.5 m per row
    semantic = np.where((y_site >= 20.0) & (y_site < 40.0), int(Semantic.ROAD), int(Semantic.BACKGROUND))
    semantic[y_site == 40.0] = int(Semantic.CURB)
    assert cv2.imwrite(str(raster_dir / "semantic.png"), semantic.astype(np.uint8))
    message, osm = _exported_osm(client, headers, site_id)
    assert "kerbs (observed 1, none 1, assumed 0)" in message
    assert 'k="cama:kerb" v="observed"' in osm and osm.count('v="road_border"') == 1


def test_a_failing_export_leaves_no_partial_files_and_no_server_path(
    client: TestClient, headers: Headers, site_id: int, make_element: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    make_element(divider())
    wrote: list[Path] = []

    def half_then_fail(inputs: ExportInputs, staging: Path) -> dict[str, object]:
        staging.write_text("<osm half")
        wrote.append(staging)
        raise OSError(f"{staging}: disk full")

    monkeypatch.setitem(export_run.WRITERS, ExportFormat.lanelet2, half_then_fail)
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    done = wait_done(client, headers, response.json()["id"])
    assert done["state"] == "failed" and "disk full" in done["message"], done["message"]
    workdir = client.app.state.jobs.workdir(done["id"])  # type: ignore[attr-defined]
    assert wrote and wrote[0].is_relative_to(workdir)  # the writer had a file half-written in the job folder
    assert list(workdir.iterdir()) == []
    assert str(workdir) not in done["message"] and "<job>/export/.map.osm.partial-" in done["message"]
    assert done["download_url"] is None


def test_stored_params_name_every_option(client: TestClient, headers: Headers, site_id: int) -> None:
    """What a job row keeps: the validated params with their defaults, as JSON."""
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    params = response.json()["params"]
    assert params["format"] == "lanelet2" and params["poses"] == "refined" and params["mode"] == "clip"
    assert params["origin_lat_lon"] == ORIGIN and params["with_clip_data"] is False
    assert params["dataset_root"] is None and params["scenes"] is None
    assert wait_done(client, headers, response.json()["id"])["state"] == "succeeded"


def test_the_archive_holds_what_the_export_wrote_never_what_its_links_reach(
    client: TestClient,
    headers: Headers,
    site_id: int,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A nuScenes-CAMAv2 root links the data set's folders into the export; the zip leaves links out."""
    secret = tmp_path / "server-only"
    secret.mkdir()
    (secret / "passwords.txt").write_text("not for download")

    def with_links(inputs: ExportInputs, staging: Path) -> dict[str, object]:
        (staging / "v1.0-cama").mkdir(parents=True)
        (staging / "v1.0-cama" / "ego_pose.json").write_text("[]")
        (staging / "samples").symlink_to(secret, target_is_directory=True)
        (staging / "v1.0-cama" / "linked.txt").symlink_to(secret / "passwords.txt")
        return {}

    monkeypatch.setitem(export_run.WRITERS, ExportFormat.lanelet2, with_links)
    response = post_export(client, headers, site_id, format="lanelet2", origin_lat_lon=ORIGIN)
    done = wait_done(client, headers, response.json()["id"])
    assert done["state"] == "succeeded", done["message"]
    archive = client.get(done["download_url"], headers=headers["lead"])
    with zipfile.ZipFile(io.BytesIO(archive.content)) as bundle:
        assert bundle.namelist() == ["map.osm/v1.0-cama/ego_pose.json"]
    assert (
        secret / "passwords.txt"
    ).read_text() == "not for download"  # the cleanup removed links, not targets
