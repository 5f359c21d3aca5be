"""`masks=False, gnss=False` (`cama synth --no-masks`): a data set as real nuScenes is, with no mask folders and
no GNSS file; the masks of a normal run, byte for byte, under ground_truth/; recorded in the manifest and the
fingerprint; and the loader reads it."""

import json
from dataclasses import asdict, replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.console import EXIT_BAD_INPUT
from cama_pipeline.data.loader import load_dataset
from cama_pipeline.data.schema import CAN_DIR, GNSS_MESSAGE, INSTANCE_DIR, SEMANTIC_DIR
from cama_pipeline.synthetic.config import MaskNoiseConfig
from cama_pipeline.synthetic.generate import GROUND_TRUTH_DIR, MANIFEST, SynthResult, fingerprint, run
from cama_pipeline.synthetic.render_jobs import render_shot
from cama_pipeline.synthetic.site_model import build_synthetic_site
from cama_studio.cli import app
from tests.synthetic.synth_helpers import file_digests, micro_config

MASK_DIRS = (SEMANTIC_DIR, INSTANCE_DIR)


@pytest.fixture(scope="module")
def sites(tmp_path_factory: pytest.TempPathFactory) -> tuple[SynthResult, SynthResult]:
    """The micro config generated without images (the reference for tables, CAN and ground truth) and, with
    images, as masks=False, gnss=False."""
    root = tmp_path_factory.mktemp("no-masks")
    tables_only = run(micro_config(), root / "tables", images=False, workers=1, show_progress=False)
    bare = run(micro_config(), root / "bare", masks=False, gnss=False, workers=2, show_progress=False)
    return tables_only, bare


def _is_gnss(relpath: str) -> bool:
    return relpath.startswith(f"nuscenes/{CAN_DIR}/") and relpath.endswith(f"_{GNSS_MESSAGE}.json")


def _is_pixels(relpath: str) -> bool:
    parts = Path(relpath).parts
    return parts[1] in ("samples", "sweeps", *MASK_DIRS)


def test_masks_move_to_ground_truth_and_gnss_files_are_left_out(sites):
    tables_only, bare = sites
    reference, bare_files = file_digests(tables_only.out_dir), file_digests(bare.out_dir)
    assert {p: d for p, d in bare_files.items() if not _is_pixels(p)} == {
        p: d for p, d in reference.items() if not _is_gnss(p)
    }
    assert sum(_is_gnss(path) for path in reference) == len(bare.scenes)
    assert not any((bare.dataset_root / folder).exists() for folder in MASK_DIRS)
    assert not list((bare.dataset_root / CAN_DIR).glob(f"*_{GNSS_MESSAGE}.json"))
    for folder in MASK_DIRS:
        assert sum(path.startswith(f"ground_truth/{folder}/") for path in bare_files) == bare.images


@pytest.mark.parametrize("clip_shot", [(0, 0), (0, 7), (2, 3)])
def test_images_and_masks_are_those_of_a_site_with_masks(sites, tmp_path, clip_shot):
    _, bare = sites
    site = build_synthetic_site(micro_config())
    render_shot(site, *clip_shot, tmp_path)  # masks beside the image, as a normal run writes them
    rendered = file_digests(tmp_path)
    assert len(rendered) == 3
    for relpath, digest in rendered.items():
        moved = relpath if relpath.endswith(".jpg") else str(Path("..", GROUND_TRUTH_DIR, relpath))
        assert file_digests(bare.dataset_root / Path(moved).parent)[Path(moved).name] == digest


def test_manifest_fingerprint_and_result_record_it(sites):
    tables_only, bare = sites
    manifest = json.loads((bare.out_dir / MANIFEST).read_text())
    assert manifest["masks_in_dataset"] is False and manifest["gnss"] is False
    assert json.loads((tables_only.out_dir / MANIFEST).read_text())["masks_in_dataset"] is True
    assert fingerprint(micro_config(), masks=False, gnss=False) != fingerprint(micro_config())
    assert bare.mask_root == bare.ground_truth_dir and tables_only.mask_root == tables_only.dataset_root
    again = run(micro_config(), bare.out_dir, masks=False, gnss=False, workers=1, show_progress=False)
    assert again.skipped and not again.masks_in_dataset and not again.gnss


def test_the_loader_reads_a_data_set_without_masks_or_gnss(sites):
    _, bare = sites
    dataset = load_dataset(bare.dataset_root)
    images = list(dataset.camera_images())
    assert len(images) == bare.images
    assert all(image.semantic_mask_path is None and image.instance_mask_path is None for image in images)
    assert all(scene.can.gnss is None and scene.can.imu is not None for scene in dataset.scenes)
    with_truth = load_dataset(bare.dataset_root, mask_roots=[bare.ground_truth_dir])
    assert all(image.semantic_mask_path is not None for image in with_truth.camera_images())


@pytest.mark.slow
def test_cli_no_masks_says_where_the_masks_are(tmp_path):
    out = tmp_path / "bare"
    result = CliRunner().invoke(
        app, ["synth", "--preset", "tiny", "--no-masks", "--no-images", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "no GNSS CAN files" in result.output
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["masks_in_dataset"] is False and manifest["gnss"] is False
    assert not list((out / "nuscenes" / CAN_DIR).glob(f"*_{GNSS_MESSAGE}.json"))


def test_the_ground_truth_masks_are_exact_whatever_the_mask_noise(sites, tmp_path):
    """The config's mask noise imitates a network's masks shipped with a data set; a mask-free site's masks are
    the truth its segmentation and SRE are scored against, so they are written as rendered."""
    _, exact = sites
    noisy = replace(micro_config(), masks=MaskNoiseConfig(boundary_jitter_px=2, miss_rate=0.5))
    bare = run(noisy, tmp_path / "noisy", masks=False, gnss=False, workers=2, show_progress=False)
    manifest = json.loads((bare.out_dir / MANIFEST).read_text())
    assert manifest["config"]["masks"] == asdict(MaskNoiseConfig())
    assert file_digests(bare.out_dir) == file_digests(exact.out_dir)
    render_shot(build_synthetic_site(noisy), 0, 7, tmp_path / "with-masks")  # as a site with masks gets them
    noisy_files, truth_files = file_digests(tmp_path / "with-masks"), file_digests(bare.ground_truth_dir)
    masks = [path for path in noisy_files if not path.endswith(".jpg")]
    assert len(masks) == 2 and any(noisy_files[path] != truth_files[path] for path in masks)


def test_cli_refuses_degraded_masks_on_a_mask_free_site(tmp_path):
    out = tmp_path / "bare"
    args = ["synth", "--preset", "tiny", "--no-masks", "--degrade-masks", "--no-images", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "--degrade-masks and --no-masks" in result.output and not out.exists()
