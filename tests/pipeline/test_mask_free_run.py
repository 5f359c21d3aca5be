"""`cama run` end to end on a tiny site generated as real nuScenes is (`cama synth --no-masks`: no masks in the data
set, no GNSS file): with masks imported from elsewhere, the run skips the segmenter and every stage reads them.
The site is `mask_free_site` (tests/pipeline/conftest.py)."""

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.data.masks import has_masks
from cama_pipeline.synthetic.generate import SynthResult
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

pytestmark = pytest.mark.slow


def test_a_mask_free_tiny_site_runs_end_to_end_on_imported_masks(
    mask_free_site: SynthResult, tmp_path: Path
) -> None:
    root, workspace = mask_free_site.dataset_root, Workspace(tmp_path / "workspace")
    assert not has_masks(root) and has_masks(mask_free_site.mask_root)
    runner = CliRunner()
    # masks made elsewhere: the generator's own, kept in ground_truth/, imported as another network's would be
    imported = runner.invoke(
        app,
        ["import-masks", str(root), str(mask_free_site.mask_root / "semantic"), "--class-map", "cama"]
        + ["--workspace", str(workspace.root), "--workers", "1"],
    )
    assert imported.exit_code == 0, imported.output
    done = runner.invoke(
        app,
        [
            "run",
            str(root),
            "--workspace",
            str(workspace.root),
            "--proposer",
            "rule",
            "--max-features",
            "1024",
        ],
    )
    assert done.exit_code == 0, done.output
    assert "skipped: imported masks in" in done.output  # auto: no data set masks, imported ones, no predicted
    site_ids = [p.stem for p in workspace.stage_dir("proposals").glob("*.json")]
    assert site_ids
    for site_id in site_ids:
        assert (workspace.surface_bev(site_id) / "semantic.png").is_file()
        assert workspace.sfm_points(site_id).is_file()
