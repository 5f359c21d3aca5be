"""Validation sites scored on a reconstruction: the surface stage's rasters, the truth cut to what was observed,
the product's inference settings, the seen-site refusal through them, and missing reconstructions named."""

import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from shapely.geometry import LineString, Point
from typer.testing import CliRunner

from app.review_effort.review_time import review_time
from cama_pipeline.evaluate.frame import ReconstructionFrame, reconstruction_frame
from cama_pipeline.evaluate.observed import ObservedMask
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.site_identity import SeenSiteError
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from cama_studio.pipeline import PipelineResult
from models.vma.checkpoint import ensure_unseen, refuse_seen_validation, seen_records
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.config import MaskModelConfig, MaskTrainConfig
from models.vma.element_masks.propose import MaskInferenceConfig, predict_site_masks
from models.vma.element_masks.replay import reconstruction_candidates, rehearsed_reconstructions
from models.vma.element_masks.retrain import evaluate_mask_model
from models.vma.element_masks.targets import element_masks
from models.vma.element_masks.train import load_mask_training_site, train_masks
from models.vma.evaluate import evaluate_proposer
from models.vma.patches import site_grid
from models.vma.rasters import SiteInputError, SiteRasters, load_site_rasters, vector_map_of
from models.vma.shipped import SHIPPED_MASK_REGISTRY, shipped_registry
from models.vma.validation import (
    ValidationSite,
    as_validation_site,
    reconstruction_of,
    true_vectors,
)
from models.vma.vectors import Vector, read_vectors
from tests.conftest import GeneratedSite
from tests.vma.vma_test_sites import hand_drawn_site


@pytest.fixture(scope="module")
def reconstructed(tiny_site: GeneratedSite, whole_path: PipelineResult) -> ValidationSite:
    return reconstruction_of(tiny_site.result.out_dir, whole_path.workspace)


def test_a_reconstruction_is_the_surface_stage_rasters_against_the_observed_truth(
    tiny_site: GeneratedSite, whole_path: PipelineResult, reconstructed: ValidationSite
) -> None:
    workspace = Workspace(whole_path.workspace)
    (site_id,) = read_site_ids(workspace.sites_index())
    assert reconstructed.rasters == workspace.surface_bev(site_id) and reconstructed.reconstructed
    assert reconstructed.site == tiny_site.result.out_dir
    rasters = load_site_rasters(reconstructed.rasters)
    assert rasters.reconstructed and not load_site_rasters(tiny_site.result.out_dir).reconstructed

    truth = read_vectors(tiny_site.result.out_dir / "ground_truth" / "vector_map.json")
    observed = true_vectors(reconstructed, rasters)
    mask = ObservedMask.from_semantic(rasters.semantic, rasters.origin_xy, rasters.resolution_m)
    lines = [
        v for v in observed if v.cls != "ped_crossing"
    ]  # a crossing's ring is kept whole when mostly seen
    assert lines and all(mask.contains(v.points).all() for v in lines)
    assert sum(_length(v) for v in observed) < sum(_length(v) for v in truth)
    own = as_validation_site(tiny_site.result.out_dir)
    whole = true_vectors(own, load_site_rasters(own.rasters))  # a site's own rasters: the whole truth
    assert [v.cls for v in whole] == [v.cls for v in truth]
    assert all(np.array_equal(a.points, b.points) for a, b in zip(whole, truth, strict=True))

    # proposing exactly the observed truth is perfect on the reconstruction, for the mAP and the annotator
    def observed_truth(_: SiteRasters) -> list[Vector]:
        return [Vector(v.cls, v.points, 1.0) for v in observed]

    assert evaluate_proposer(observed_truth, [reconstructed])["mean_ap"] == pytest.approx(1.0)
    perfect, nothing = (
        review_time(observed_truth, [reconstructed]),
        review_time(lambda _: [], [reconstructed]),
    )
    assert perfect["speed_up"] > 2.0 and perfect["correction_s"] < nothing["correction_s"]


def test_the_mask_gate_proposes_on_a_reconstruction_as_the_product_does(
    reconstructed: ValidationSite,
) -> None:
    model = load_mask_checkpoint(shipped_registry(*SHIPPED_MASK_REGISTRY)).model
    rasters = load_site_rasters(reconstructed.rasters)
    road_edge = predict_site_masks(model, rasters, MaskInferenceConfig(boundary_evidence="road_edge"))
    plain = predict_site_masks(model, rasters)
    assert _boundaries(road_edge) != _boundaries(plain)  # the setting matters on this site

    def product(r: SiteRasters) -> list[Vector]:  # the network's own band, on reconstructions too
        return predict_site_masks(model, r, MaskInferenceConfig(boundary_evidence="none"))

    gate, expected = evaluate_mask_model(model, [reconstructed]), evaluate_proposer(product, [reconstructed])
    for key in ("mean_ap", "class_ap", "confidence_bins", "num_predictions", "num_ground_truth"):
        assert gate[key] == expected[key], key
    assert gate["sites"] == [str(reconstructed)] and "reconstructed" in gate["sites"][0]


def test_a_checkpoint_that_saw_the_site_is_not_gated_on_its_reconstruction(
    tiny_site: GeneratedSite, reconstructed: ValidationSite
) -> None:
    seen = seen_records([tiny_site.result.out_dir], None)
    with pytest.raises(SeenSiteError):
        refuse_seen_validation(seen, [reconstructed], "a model trained on the tiny site")


def test_training_on_a_reconstruction_draws_the_observed_truth_and_records_the_site(
    tiny_site: GeneratedSite, reconstructed: ValidationSite, tmp_path: Path
) -> None:
    config = MaskModelConfig(base_channels=4)
    on_reconstruction = load_mask_training_site(reconstructed, config, damaged_copies=2)
    rasters = load_site_rasters(reconstructed.rasters)
    grid = site_grid(rasters, config)
    observed = element_masks(true_vectors(reconstructed, rasters), grid, config)
    whole = element_masks(read_vectors(vector_map_of(tiny_site.result.out_dir)), grid, config)
    assert np.array_equal(on_reconstruction.targets, observed)
    assert observed.sum() < whole.sum()  # the unseen parts of the truth are not targets
    # the surface stage's rasters are the input, as they are: no simulated damage on top of the real thing
    assert len(on_reconstruction.images) == 1 and np.array_equal(on_reconstruction.images[0], grid.image)

    registry = tmp_path / "registry"
    train = MaskTrainConfig(steps=2, batch_size=2, crop_px=64, damaged_copies=1, threads=1)
    folder = train_masks(config, train, [reconstructed], registry, show_progress=False)
    data = json.loads((folder / "checkpoint.json").read_text())["data"]
    assert data["sites"] == [str(tiny_site.result.out_dir)]
    assert data["reconstructions"] == [str(reconstructed.rasters)]
    checkpoint = load_mask_checkpoint(registry)
    for scored in (tiny_site.result.out_dir, reconstructed.site):
        with pytest.raises(SeenSiteError):
            ensure_unseen(checkpoint, scored)
    with pytest.raises(SeenSiteError):  # nor may it gate on the site it trains on
        train_masks(config, train, [reconstructed], tmp_path / "other", validation_sites=[reconstructed])
    assert not (tmp_path / "other").exists()


@dataclass(frozen=True)
class _Version:
    """A version record (`models.vma.checkpoint.VersionRecord`) with metadata edited by a test."""

    meta: dict[str, Any]
    path: Path


def test_retraining_rehearses_the_reconstructions_a_version_trained_on_and_skips_changed_ones(
    reconstructed: ValidationSite, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    config = MaskModelConfig(base_channels=4)
    train = MaskTrainConfig(steps=1, batch_size=2, crop_px=64, damaged_copies=1, threads=1)
    version = load_mask_checkpoint(
        train_masks(config, train, [reconstructed], tmp_path / "r", show_progress=False)
    )
    (identity, rasters), *others = reconstruction_candidates(version)
    assert not others and rasters == reconstructed.rasters and Path(identity.path) == reconstructed.site
    (rehearsed,) = rehearsed_reconstructions(version, 3, config, seed=0)  # as many as it trained on
    expected = load_mask_training_site(reconstructed, config, damaged_copies=0)
    assert rehearsed.name == expected.name and np.array_equal(rehearsed.targets, expected.targets)
    assert len(rehearsed.images) == 1  # the reconstruction as it is, no damaged copies
    assert rehearsed_reconstructions(version, 0, config, seed=0) == []

    data = version.meta["data"]
    changed = {**data, "seen_sites": [{**site, "layout_digest": "0" * 16} for site in data["seen_sites"]]}
    moved = {**data, "reconstructions": [str(tmp_path / "gone" / "surface" / "site-001" / "bev")]}
    moved["seen_sites"] = [{**site, "path": str(tmp_path)} for site in data["seen_sites"]]
    for meta, said in ((changed, "is not the reconstruction"), (moved, "not replayed")):
        caplog.clear()
        record = _Version({**version.meta, "data": meta}, version.path)
        assert rehearsed_reconstructions(record, 3, config, seed=0) == []
        assert said in caplog.text


def test_train_masks_names_a_site_without_a_reconstruction(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    copy = tmp_path / "site"
    (copy / "ground_truth").mkdir(parents=True)
    shutil.copy(tiny_site.result.out_dir / "ground_truth" / "vector_map.json", copy / "ground_truth")
    registry = tmp_path / "registry"
    result = CliRunner().invoke(
        app, ["train-masks", "--registry", str(registry), "--reconstructed-site", str(copy), "--steps", "1"]
    )
    assert result.exit_code == 2 and f"cama run {copy / 'nuscenes'}" in result.output
    assert not registry.exists()


def test_a_missing_reconstruction_is_named(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    with pytest.raises(SiteInputError, match=r"cama run .*nuscenes.* first\), found 0"):
        reconstruction_of(tiny_site.result.out_dir, tmp_path / "empty-workspace")
    with pytest.raises(SiteInputError, match="no ground_truth/vector_map.json"):
        reconstruction_of(tmp_path)


def _boundaries(vectors: list[Vector]) -> list[list[float]]:
    return [np.round(v.points, 3).ravel().tolist() for v in vectors if v.cls == "boundary"]


def _length(vector: Vector) -> float:
    return float(np.linalg.norm(np.diff(vector.points, axis=0), axis=1).sum())


def test_a_reconstruction_is_scored_against_the_truth_in_its_frame(tmp_path: Path) -> None:
    site = hand_drawn_site(tmp_path / "drawn")
    frame = ReconstructionFrame(1.0, 0.0, (0.0, 0.4), "sfm", 10, 0.4, 0.01)  # across the lines
    reconstruction = ValidationSite(site, site, reconstructed=True, frame=frame)
    truth = read_vectors(vector_map_of(site))
    moved = true_vectors(reconstruction, load_site_rasters(site))
    assert [v.cls for v in moved] == [v.cls for v in truth]
    for ours, true in zip(moved, truth, strict=True):  # the cut resamples the lines: compare as lines
        carried, left = LineString(frame.apply(true.points)), LineString(true.points)
        assert max(carried.distance(Point(p)) for p in ours.points) < 1e-6
        if not true.closed:  # a crossing's ring moved along its long side overlaps itself
            assert min(left.distance(Point(p)) for p in ours.points) > 0.3

    def as_shown(_: SiteRasters) -> list[Vector]:
        return [Vector(v.cls, frame.apply(v.points), 1.0) for v in truth]

    assert evaluate_proposer(as_shown, [reconstruction])["mean_ap"] == pytest.approx(1.0)


def test_a_reconstruction_of_records_its_frame(
    reconstructed: ValidationSite, whole_path: PipelineResult
) -> None:
    workspace = Workspace(whole_path.workspace)
    (site_id,) = read_site_ids(workspace.sites_index())
    assert reconstructed.frame is not None
    assert reconstructed.frame == reconstruction_frame(reconstructed.site / "nuscenes", workspace, site_id)
