"""`cama run` end to end on a mask-free tiny site (`mask_free_site`, tests/pipeline/conftest.py) with nothing
imported: the run starts the segment stage with the shipped segmenter, and the stages after it read the predicted
masks, up to the proposals."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.segment.checkpoint import shipped_checkpoint
from cama_pipeline.segment.io import read_mask_manifest
from cama_pipeline.synthetic.generate import SynthResult
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

pytestmark = pytest.mark.slow


def test_a_mask_free_tiny_site_runs_cama_run_end_to_end_on_predicted_masks(
    mask_free_site: SynthResult, tmp_path: Path
) -> None:
    root, workspace = mask_free_site.dataset_root, Workspace(tmp_path / "workspace")
    argv = [
        "run",
        str(root),
        "--workspace",
        str(workspace.root),
        "--proposer",
        "rule",
        "--max-features",
        "1024",
    ]
    done = CliRunner().invoke(app, argv)
    assert done.exit_code == 0, done.output
    assert "skipped" not in done.output  # the data set has no masks and none are imported: segment ran
    manifest = read_mask_manifest(workspace.masks_manifest("predicted"))
    assert manifest.made_by["checkpoint_path"] == str(shipped_checkpoint().absolute()) and manifest.images
    site_ids = [p.stem for p in workspace.stage_dir("proposals").glob("*.json")]
    assert site_ids
    for site_id in site_ids:
        masks = json.loads(workspace.features_report(site_id).read_text(encoding="utf-8"))["masks"]
        assert [part[0] for part in masks] == ["choice", "predicted"]
        assert (workspace.surface_bev(site_id) / "semantic.png").is_file()
