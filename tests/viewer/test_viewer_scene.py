"""The 3D review on the tiny site: every layer present, vectors follow their source, clicks select."""

import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import viser
from typer.testing import CliRunner

from annotations.schema import AnnotationSet, Georeference, MapElement
from app.viewer.review import ViewInputs, follow, open_review
from app.viewer.sources import FileVectorSource, VectorSourceError
from cama_pipeline.bev import read_georeference
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.workspace import Workspace
from tests.pairs.site_workspace import build_site_workspace


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module")
def view_site(tiny_site, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:  # type: ignore[no-untyped-def]
    """The tiny site with a workspace made by wigo -> keyframes -> sites."""
    root = tiny_site.result.out_dir
    return root, build_site_workspace(root / "nuscenes", tmp_path_factory.mktemp("view-ws"))


def _annotations(site_root: Path, elements: list[MapElement]) -> AnnotationSet:
    georef = Georeference.of(read_georeference(site_root / "ground_truth" / "bev"), site_origin_xy=(0.0, 0.0))
    return AnnotationSet(site_id="tiny", georeference=georef, elements=elements)


def _road_points(workspace: Path) -> np.ndarray:
    """Two global points on the tiny site's road, a few metres apart: the ego path from the site manifest."""
    manifest = read_site_manifest(Workspace(workspace).site_manifest("site-001"))
    poses = sorted(manifest["poses"].values(), key=lambda p: p["timestamp_us"])
    xy = np.array([p["translation"][:2] for p in poses])
    far = int(np.argmax(np.linalg.norm(xy - xy[0], axis=1) > 4.0))
    return np.stack([xy[0], xy[far]])


@pytest.fixture()
def server() -> Iterator[viser.ViserServer]:
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def test_review_shows_every_layer_and_follows_the_file(view_site, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    site_root, workspace = view_site
    xy = _road_points(workspace)
    path = tmp_path / "vectors.json"
    first = MapElement(id="e1", cls="divider", source="human", points_2d=xy.tolist())
    _annotations(site_root, [first]).write_json(path)
    scene = open_review(server, ViewInputs(site_root, workspace, "site-001"), FileVectorSource(path))
    assert set(scene._toggles) >= {"Road mesh", "Vectors"}
    assert any(name.startswith("Cameras (") and not name.startswith("Cameras (0") for name in scene._toggles)
    assert scene._vectors["e1"][1].shape[1] == 3
    assert np.all(np.isfinite(scene._vectors["e1"][1]))

    accepted = first.with_changes(review_state="accepted", version=2)
    second = MapElement(id="e2", cls="boundary", source="human", points_2d=(xy + [0.0, 1.0]).tolist())
    _annotations(site_root, [accepted, second]).write_json(path)
    counts = scene.sync_vectors(FileVectorSource(path).load())
    assert (counts.added, counts.updated, counts.removed) == (1, 1, 0)
    assert scene._vectors["e1"][0].state == "accepted"
    assert scene.sync_vectors(FileVectorSource(path).load()).updated == 0  # unchanged: nothing redrawn

    _annotations(site_root, [second]).write_json(path)
    assert scene.sync_vectors(FileVectorSource(path).load()).removed == 1
    assert set(scene._vectors) == {"e2"}


def test_a_click_on_a_vector_selects_it_and_shows_its_state(view_site, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    site_root, workspace = view_site
    xy = _road_points(workspace)
    path = tmp_path / "vectors.json"
    _annotations(
        site_root,
        [MapElement(id="e7", cls="divider", source="human", points_2d=xy.tolist(), review_state="fixed")],
    ).write_json(path)
    scene = open_review(server, ViewInputs(site_root, workspace, "site-001"), FileVectorSource(path))
    middle = scene._vectors["e7"][1].mean(axis=0)
    picked = scene.pick(middle + [0.0, 0.0, 15.0], np.array([0.0, 0.0, -1.0]))
    assert picked == "e7"
    scene.select(picked)
    assert "e7" in scene._panel.content and "fixed" in scene._panel.content
    scene.select(scene.pick(middle + [50.0, 50.0, 15.0], np.array([0.0, 0.0, -1.0])))
    assert scene.selected is None


def test_follow_keeps_the_last_vectors_when_the_source_breaks(view_site, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    site_root, workspace = view_site
    path = tmp_path / "vectors.json"
    _annotations(
        site_root,
        [MapElement(id="e1", cls="divider", source="human", points_2d=_road_points(workspace).tolist())],
    ).write_json(path)
    source = FileVectorSource(path)
    scene = open_review(server, ViewInputs(site_root, workspace, "site-001"), source)
    path.write_text("{ not json")
    with pytest.raises(VectorSourceError, match="vectors.json"):
        source.load()
    stop = threading.Event()
    worker = threading.Thread(target=follow, args=(scene, source, stop), kwargs={"interval_s": 0.05})
    worker.start()
    stop.wait(0.3)
    stop.set()
    worker.join(5)
    assert set(scene._vectors) == {"e1"}


def test_view_command_names_a_missing_workspace(tmp_path: Path) -> None:
    from cama_studio.cli import app

    result = CliRunner().invoke(app, ["view", str(tmp_path / "nowhere"), "--port", str(_free_port())])
    assert result.exit_code == 2
    assert "nowhere" in result.output
