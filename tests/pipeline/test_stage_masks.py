"""Stages on a data set without masks: they read the workspace's masks (here imported ones), follow a change of
them through their fingerprints, fall back on the ego body estimated from the clips, and name what is missing."""

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.data import DatasetError
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.stage import run as run_features
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.stage import run as run_pairs
from cama_pipeline.surface import SurfaceConfig
from cama_pipeline.surface import run as run_surface
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from tests.conftest import GeneratedSite
from tests.features.test_features_stage import keep_first_keyframes
from tests.pairs.site_workspace import build_site_workspace

pytestmark = pytest.mark.slow
FEATURES = FeaturesConfig(max_num_features=512)


@pytest.fixture(scope="module")
def mask_free(tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny site's data set without semantic/ and lane_instance/ (everything else linked), with a workspace
    through the pairs (two keyframes per scene) and no masks in it."""
    source = tiny_site.result.dataset_root
    root = tmp_path_factory.mktemp("mask-free") / "nuscenes"
    root.mkdir()
    for entry in source.iterdir():
        if entry.name not in (SEMANTIC_DIR, INSTANCE_DIR):
            (root / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    workspace = build_site_workspace(root, Workspace.for_dataset(root).root)
    keep_first_keyframes(Workspace(workspace).site_manifest("site-001"), 2)
    run_pairs(PairsConfig(), root, workspace)
    return root


def import_generator_masks(tiny_site: GeneratedSite, workspace: Workspace, note: str) -> None:
    """The generator's masks as the workspace's imported masks (linked), with a manifest saying `note`."""
    imported = workspace.masks_dir("imported")
    imported.mkdir(parents=True, exist_ok=True)
    for kind in (SEMANTIC_DIR, INSTANCE_DIR):
        if not (imported / kind).exists():
            (imported / kind).symlink_to(tiny_site.result.dataset_root / kind, target_is_directory=True)
    workspace.masks_manifest("imported").write_text(json.dumps({"note": note}))


def test_features_on_a_mask_free_data_set_read_the_workspace_masks(
    mask_free: Path, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    workspace = Workspace(tmp_path / "workspace")
    shutil.copytree(Workspace.for_dataset(mask_free).root, workspace.root, symlinks=True)
    import_generator_masks(tiny_site, workspace, "first")
    (site,) = run_features(FEATURES, mask_free, workspace).items
    assert [part[0] for part in site.report["masks"]] == ["choice", "imported"]
    assert site.report["ego_estimated"] == {}  # the masks label the trunk: no estimate needed
    back = [c["masked"] for name, c in site.report["images"].items() if "CAM_BACK/" in name]
    assert back and min(back) > 0  # the trunk's features removed
    (again,) = run_features(FEATURES, mask_free, workspace).items
    assert again.skipped
    import_generator_masks(tiny_site, workspace, "imported again")  # new masks: features run again
    (rerun,) = run_features(FEATURES, mask_free, workspace).items
    assert not rerun.skipped and rerun.report["fingerprint"] != site.report["fingerprint"]


def test_without_any_masks_features_mask_the_trunk_estimated_from_the_clips(
    mask_free: Path, tmp_path: Path
) -> None:
    workspace = Workspace(tmp_path / "workspace")
    shutil.copytree(Workspace.for_dataset(mask_free).root, workspace.root, symlinks=True)
    (site,) = run_features(FEATURES, mask_free, workspace).items
    assert site.report["masks"] == [["choice", "auto"]]
    estimated = site.report["ego_estimated"]
    backs = [fraction for key, fraction in estimated.items() if key.endswith("/CAM_BACK")]
    assert backs and all(0.08 < f < 0.11 for f in backs)  # the generator's trunk covers 9.4 %
    assert all(f < 0.002 for key, f in estimated.items() if not key.endswith("/CAM_BACK"))
    back = [c["masked"] for name, c in site.report["images"].items() if "CAM_BACK/" in name]
    assert back and min(back) > 0


def test_missing_masks_are_named_before_any_work(mask_free: Path, tmp_path: Path) -> None:
    workspace = Workspace(tmp_path / "workspace")
    shutil.copytree(Workspace.for_dataset(mask_free).root, workspace.root, symlinks=True)
    with pytest.raises(DatasetError, match="have no semantic mask") as info:
        run_surface(SurfaceConfig(), mask_free, workspace, poses="wigo", show_progress=False)
    assert "cama segment" in str(info.value) and "CAM_" in str(info.value)
    runner = CliRunner()
    result = runner.invoke(
        app, ["features", str(mask_free), "--workspace", str(workspace.root), "--masks", "dataset"]
    )
    assert result.exit_code == 2 and "has no masks" in result.output
    result = runner.invoke(
        app, ["surface", str(mask_free), "--workspace", str(workspace.root), "--masks", "predicted"]
    )
    assert result.exit_code == 2 and "cama segment" in result.output


def test_eval_reads_the_lane_instances_of_the_chosen_masks(
    mask_free: Path, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    workspace = Workspace(tmp_path / "workspace")
    vector_map = tiny_site.result.ground_truth_dir / "vector_map.json"
    argv = [
        "eval",
        str(mask_free),
        str(vector_map),
        "--scene",
        "scene-0001",
        "--workspace",
        str(workspace.root),
    ]
    runner = CliRunner()
    missing = runner.invoke(app, [*argv, "--out", str(tmp_path / "none.json")])
    assert missing.exit_code == 2 and "no instance mask" in missing.output
    import_generator_masks(tiny_site, workspace, "for eval")
    done = runner.invoke(app, [*argv, "--masks", "imported", "--out", str(tmp_path / "sre.json")])
    assert done.exit_code == 0, done.output
    report = json.loads((tmp_path / "sre.json").read_text())
    assert report["overall"]["image_instances"] > 0 and report["overall"]["matched"] > 0
