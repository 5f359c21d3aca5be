"""`images=False` (`cama synth --no-images`): the tables and ground truth of a full run, no image or mask file,
recorded in the manifest so that a later full run renders them and image-reading stages fail clearly."""

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR
from cama_pipeline.synthetic.generate import MANIFEST, fingerprint, run
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from tests.synthetic.synth_helpers import file_digests, micro_config

PIXEL_DIRS = ("samples", "sweeps", SEMANTIC_DIR, INSTANCE_DIR)


def _is_pixels(relpath: str) -> bool:
    """A camera image or mask file (nuscenes/<samples|sweeps|mask dir>/...)."""
    parts = Path(relpath).parts
    return parts[0] == "nuscenes" and parts[1] in PIXEL_DIRS


@pytest.fixture(scope="module")
def bare_site(tiny_site, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny site's config generated again without images, through the command line."""
    out = tmp_path_factory.mktemp("no-images") / "tiny"
    result = CliRunner().invoke(app, ["synth", "--preset", "tiny", "--no-images", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "NOT rendered" in result.output
    return out


def test_no_image_or_mask_file_is_written(bare_site):
    assert not [path for path in file_digests(bare_site) if _is_pixels(path)]
    assert not any((bare_site / "nuscenes" / folder).exists() for folder in PIXEL_DIRS)
    manifest = json.loads((bare_site / MANIFEST).read_text())
    assert manifest["images_rendered"] is False
    assert manifest["images"] > 0


def test_tables_can_and_ground_truth_are_those_of_a_full_run(bare_site, tiny_site):
    full = file_digests(tiny_site.result.out_dir)
    assert file_digests(bare_site) == {path: digest for path, digest in full.items() if not _is_pixels(path)}
    tables = bare_site / "nuscenes" / "v1.0-synth"
    assert json.loads((tables / "sample_data.json").read_text()) == json.loads(
        (tiny_site.result.dataset_root / "v1.0-synth" / "sample_data.json").read_text()
    )
    assert sum(path.endswith(".jpg") for path in full) == tiny_site.result.images


@pytest.mark.slow
def test_a_full_run_after_a_bare_one_renders_the_images(tmp_path):
    cfg = micro_config()
    assert fingerprint(cfg, images=False) != fingerprint(cfg)
    target = tmp_path / "site"
    bare = run(cfg, target, images=False, workers=1, show_progress=False)
    assert not bare.images_rendered
    assert run(cfg, target, images=False, workers=1, show_progress=False).skipped
    bare_files = file_digests(target)
    rendered = run(cfg, target, workers=1, show_progress=False)
    assert not rendered.skipped and rendered.images_rendered
    full_files = file_digests(target)
    assert sum(path.endswith(".jpg") for path in full_files) == bare.images
    assert {path: digest for path, digest in full_files.items() if not _is_pixels(path)} == bare_files
    assert run(cfg, target, workers=1, show_progress=False).skipped


def test_pairs_are_planned_without_images_and_features_fail_naming_the_missing_image(bare_site, tmp_path):
    site = tmp_path / "site"
    shutil.copytree(bare_site, site)
    dataset, workspace = str(site / "nuscenes"), str(tmp_path / "ws")
    runner = CliRunner()
    for upstream in ("wigo", "keyframes", "sites", "pairs"):
        result = runner.invoke(app, [upstream, dataset, "--workspace", workspace])
        assert result.exit_code == 0, f"{upstream}: {result.output}"
    assert Workspace(tmp_path / "ws").pairs_txt("site-001").read_text().strip()
    result = runner.invoke(app, ["features", dataset, "--workspace", workspace])
    assert result.exit_code == 2, result.output
    (error,) = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert "image file not found" in error and ".jpg" in error and str(site) in error
