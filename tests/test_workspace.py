"""The workspace layout: every path method, the default beside the data set, and `locate` back from a raster
folder; the up-to-date check every stage uses."""

import inspect
from pathlib import Path

import pytest

from cama_pipeline.fingerprints import fingerprint, is_up_to_date, mark_done, sidecar, stored_fingerprint
from cama_pipeline.io import atomic_write_json
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.workspace import STAGE_FOLDERS, SiteLocation, Workspace

EXPECTED = {
    "wigo": ("scene-1", "wigo/scene-1.json"),
    "keyframes": ("scene-1", "keyframes/scene-1.json"),
    "masks_dir": ("predicted", "masks/predicted"),
    "masks_manifest": ("imported", "masks/imported/manifest.json"),
    "sites_index": (None, "sites/index.json"),
    "site_manifest": ("site-001", "sites/site-001/manifest.json"),
    "pairs_dir": ("site-001", "pairs/site-001"),
    "pairs_txt": ("site-001", "pairs/site-001/pairs.txt"),
    "pairs_json": ("site-001", "pairs/site-001/pairs.json"),
    "features_dir": ("site-001", "features/site-001"),
    "features_db": ("site-001", "features/site-001/database.db"),
    "features_report": ("site-001", "features/site-001/features.json"),
    "features_extraction": ("site-001", "features/site-001/extraction.json"),
    "sfm_dir": ("site-001", "sfm/site-001"),
    "sfm_model": ("site-001", "sfm/site-001/model"),
    "sfm_clips": ("site-001", "sfm/site-001/clips"),
    "sfm_poses": ("site-001", "sfm/site-001/poses.json"),
    "sfm_points": ("site-001", "sfm/site-001/points.npz"),
    "sfm_report": ("site-001", "sfm/site-001/report.json"),
    "surface_dir": ("site-001", "surface/site-001"),
    "surface_bev": ("site-001", "surface/site-001/bev"),
    "surface_mesh": ("site-001", "surface/site-001/mesh.ply"),
    "surface_kerb_step": ("site-001", "surface/site-001/kerb_step.npy"),
    "surface_report": ("site-001", "surface/site-001/report.json"),
    "proposals": ("site-001", "proposals/site-001.json"),
}


def path_methods() -> set[str]:
    """Public methods of Workspace that name one output (not the constructors, listings or `stage_dir`)."""
    skip = {"for_dataset", "resolve", "locate", "stage_dir", "wigo_scenes"}
    return {
        name
        for name, member in inspect.getmembers(Workspace, inspect.isfunction)
        if not name.startswith("_") and name not in skip
    }


def test_every_path_method_gives_its_documented_place(tmp_path: Path) -> None:
    assert path_methods() == set(EXPECTED), "a new Workspace path method needs a row in EXPECTED"
    ws = Workspace(tmp_path)
    for name, (key, relative) in EXPECTED.items():
        method = getattr(ws, name)
        assert (method() if key is None else method(key)) == tmp_path / relative, name
    assert [ws.stage_dir(stage) for stage in STAGE_FOLDERS] == [tmp_path / stage for stage in STAGE_FOLDERS]
    with pytest.raises(ValueError, match="'bev'"):
        ws.stage_dir("bev")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'dataset'"):
        ws.masks_dir("dataset")


def test_default_workspace_sits_beside_the_data_set_and_a_given_one_wins(tmp_path: Path) -> None:
    dataset = tmp_path / "site" / "nuscenes"
    assert Workspace.for_dataset(dataset).root == (tmp_path / "site" / "workspace").absolute()
    assert Workspace.resolve(None, dataset) == Workspace.for_dataset(dataset)
    assert Workspace.resolve(tmp_path / "ws", dataset) == Workspace(tmp_path / "ws")
    given = Workspace(tmp_path / "other")
    assert Workspace.resolve(given, dataset) is given
    assert Workspace(str(tmp_path)).root == tmp_path  # type: ignore[arg-type]


def test_wigo_scenes_lists_what_wigo_wrote(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    assert ws.wigo_scenes() == []
    for scene in ("scene-2", "scene-1"):
        atomic_write_json(ws.wigo(scene), {})
    assert ws.wigo_scenes() == ["scene-1", "scene-2"]


def test_locate_goes_back_from_a_surface_raster_folder(tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "ws")
    assert Workspace.locate(ws.surface_bev("site-007")) == SiteLocation(ws, "site-007")
    relative = Workspace.locate(Path("surface/site-001/bev"))
    assert relative.site_id == "site-001" and relative.workspace.root == Path(".")


@pytest.mark.parametrize(
    "path",
    [
        "data/synthetic/default/ground_truth/bev",  # a generator's rasters: no workspace
        "ws/surface/site-001",  # the site's folder, not its rasters
        "ws/sfm/site-001/bev",
        "bev",
        "surface/../bev",
    ],
)
def test_locate_names_a_path_that_is_no_surface_raster_folder(path: str) -> None:
    with pytest.raises(ValueError, match=f"{path}: not a surface stage's raster folder"):
        Workspace.locate(Path(path))


def test_up_to_date_reads_the_field_of_a_json_output_or_the_sidecar_of_any_other(tmp_path: Path) -> None:
    digest = fingerprint("stage", {"a": 1}, [("x", 1, 2)])
    assert digest == fingerprint("stage", {"a": 1}, [("x", 1, 2)]) and len(digest) == 16
    report = tmp_path / "report.json"
    assert not is_up_to_date(report, digest) and stored_fingerprint(report) is None
    atomic_write_json(report, {"schema": "x", "fingerprint": digest})
    assert is_up_to_date(report, digest) and not is_up_to_date(report, "other")
    proposals = tmp_path / "proposals" / "site-001.json"
    atomic_write_json(proposals, {"elements": []})
    assert not is_up_to_date(proposals, digest)
    mark_done(proposals, digest)
    assert sidecar(proposals).read_text() == digest and is_up_to_date(proposals, digest)
    proposals.unlink()  # a sidecar without its output is not done
    assert not is_up_to_date(proposals, digest)
    report.write_text("{broken")
    assert stored_fingerprint(report) is None


def test_stage_result_lists_items_skipped_and_paths(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    items = (
        ItemResult("site-001", ws.sfm_dir("site-001"), {"points": 3}, skipped=True),
        ItemResult("site-002", ws.sfm_dir("site-002"), {"points": 4}, skipped=False),
    )
    result = StageResult("sfm", ws, items, 1.5)
    assert result.skipped == ("site-001",) and result.report == {}
    assert result.paths == {"site-001": ws.sfm_dir("site-001"), "site-002": ws.sfm_dir("site-002")}
    assert result.item("site-002").report == {"points": 4}
    with pytest.raises(KeyError, match="site-003"):
        result.item("site-003")
