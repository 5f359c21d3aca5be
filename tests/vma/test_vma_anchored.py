"""The anchored (hybrid) model: rule-based candidates as instance queries, in patches, training and inference."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from annotations import Georeference
from models.vma.anchors import ANCHOR_FEATURES, patch_anchors, stack_anchors
from models.vma.checkpoint import promote, save_version
from models.vma.config import ModelConfig, TrainConfig, config_fingerprint
from models.vma.infer import InferenceConfig, predict_site
from models.vma.loop import THRESHOLD_KEY
from models.vma.model import VmaNet
from models.vma.patches import procedural_sample, site_grid, site_sample
from models.vma.rasters import load_site_rasters, vector_map_of
from models.vma.retrain import Corrections, RetrainConfig, retrain_from_corrections
from models.vma.rule_based import propose_rule_based
from models.vma.train import fit, load_training_sites, mixed_sampler
from models.vma.vectors import CLASSES, Vector, proposals_as_annotations, read_vectors
from tests.vma.vma_test_sites import hand_drawn_site

ANCHORED = ModelConfig(
    resolution_m=0.4,
    patch_px=48,
    num_queries=6,
    num_points=5,
    dim=32,
    decoder_layers=2,
    heads=2,
    anchored=True,
)


def test_free_configs_keep_the_fingerprint_of_shipped_checkpoints() -> None:
    assert config_fingerprint(ModelConfig()) == "f7080c8e31a56166"  # v0001, made before `anchored` existed
    assert config_fingerprint(ANCHORED) != config_fingerprint(
        ModelConfig(**{**ANCHORED.__dict__, "anchored": False})
    )


def test_patch_anchors_clip_rank_and_describe_candidates() -> None:
    candidates = [
        Vector("divider", np.array([[-10.0, 10.0], [30.0, 10.0]]), 0.5),  # clipped to x 0..48 -> 30 px inside
        Vector("boundary", np.array([[0.0, 40.0], [48.0, 40.0]]), 0.9),
        Vector("divider", np.array([[60.0, 0.0], [70.0, 0.0]]), 1.0),  # outside
    ]
    anchors = patch_anchors(candidates, ANCHORED, min_length_px=2.0)
    assert anchors.points.shape == (6, 5, 2) and anchors.features.shape == (6, ANCHOR_FEATURES)
    assert anchors.features[:, -1].tolist() == [1, 1, 0, 0, 0, 0]
    assert anchors.features[0, CLASSES.index("boundary")] == 1 and anchors.features[0, -2] == pytest.approx(
        0.9
    )
    assert anchors.points[1, :, 0].min() == pytest.approx(0.0) and anchors.points[
        1, :, 0
    ].max() == pytest.approx(30 / 48)
    assert stack_anchors([anchors, None], torch.device("cpu")) is None


def test_untrained_anchored_model_returns_its_anchors_and_refuses_missing_ones() -> None:
    model = VmaNet(ANCHORED).eval()
    anchors = patch_anchors([Vector("divider", np.array([[5.0, 5.0], [40.0, 30.0]]), 0.7)], ANCHORED, 2.0)
    batch = stack_anchors([anchors], torch.device("cpu"))
    images = torch.zeros(1, ANCHORED.in_channels, 48, 48)
    with torch.no_grad():
        logits, points = model(images, batch)
    assert logits.shape == (1, 6, len(CLASSES))
    assert torch.allclose(points[-1][0, 0], torch.as_tensor(anchors.points[0]), atol=1e-3)
    with pytest.raises(ValueError, match="anchored"):
        model(images)
    with pytest.raises(ValueError, match="anchored"):
        VmaNet(ModelConfig(patch_px=48, num_queries=6, num_points=5, dim=32, heads=2))(images, batch)


def test_site_patches_carry_anchors_next_to_their_targets(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    grid = site_grid(rasters, ANCHORED)
    centre = grid.pixel_from_global(np.array([[520.0, 780.0]]))[0]
    sample = site_sample(
        grid, read_vectors(vector_map_of(drawn_site)), ANCHORED, centre, 0.7, propose_rule_based(rasters)
    )
    assert sample.anchors is not None
    filled = sample.anchors.features[:, -1] > 0
    assert filled.sum() >= 2
    # every anchor lies near a same-class target (clean raster: the candidates are right)
    for points, features in zip(sample.anchors.points[filled], sample.anchors.features[filled], strict=True):
        cls = int(np.argmax(features[: len(CLASSES)]))
        same = sample.points[sample.labels == cls]
        nearest = np.linalg.norm(same[:, :, None] - points[None, None], axis=3).min(axis=(1)).mean(axis=1)
        assert nearest.min() * ANCHORED.patch_m < 1.0


def test_anchored_training_lowers_the_loss_and_infers_a_site(drawn_site: Path) -> None:
    sites = load_training_sites(drawn_site, ANCHORED, damaged_copies=1)
    assert len(sites) == 2 and all(s.candidates is not None for s in sites)
    sampler = mixed_sampler(sites, ANCHORED, procedural_share=0.0)
    rng = np.random.default_rng(0)
    fixed = [sampler(rng) for _ in range(3)]
    model = VmaNet(ANCHORED)
    losses = fit(
        model,
        lambda r: fixed[int(r.integers(3))],
        TrainConfig(steps=20, batch_size=3, threads=1),
        show_progress=False,
    )
    assert np.mean(losses[-5:]) < np.mean(losses[:5])
    rasters = load_site_rasters(drawn_site)
    rescored = predict_site(model, rasters, InferenceConfig(min_score=0.0), show_progress=False)
    rule = propose_rule_based(rasters)
    assert len(rescored) == len(rule)  # the candidates' own geometry, with the model's scores
    assert all(
        np.array_equal(a.points, b.points) and 0.0 <= a.score <= 1.0
        for a, b in zip(rescored, rule, strict=True)
    )
    refined = InferenceConfig(min_score=0.0, anchored_output="refined")
    assert predict_site(model, rasters, refined, show_progress=False)
    with pytest.raises(ValueError, match="anchored_output"):
        InferenceConfig(anchored_output="both")


def test_procedural_patches_get_rule_based_anchors() -> None:
    sample = procedural_sample(ANCHORED, np.random.default_rng(4))
    assert sample.anchors is not None and sample.anchors.points.shape == (6, 5, 2)


def test_anchored_retrain_records_the_calibrated_threshold(drawn_site: Path, tmp_path: Path) -> None:
    registry = tmp_path / "registry"
    unseen = {"seen_sites": [], "seen_folders": []}
    promote(registry, save_version(registry, VmaNet(ANCHORED), {"metrics": {}, "data": unseen}).name)
    rasters = load_site_rasters(drawn_site)
    georeference = Georeference(
        site_origin_xy=rasters.origin_xy, origin_xy=rasters.origin_xy, resolution=0.1, width=600, height=400
    )
    truth = proposals_as_annotations(read_vectors(vector_map_of(drawn_site)), georeference, "drawn", "lead")
    accepted = truth.model_copy(
        update={"elements": [e.with_changes(review_state="accepted") for e in truth.elements]}
    )
    config = RetrainConfig(train=TrainConfig(steps=3, batch_size=2, threads=1), replay_share=0.0)
    validation = hand_drawn_site(tmp_path / "validation")
    result = retrain_from_corrections(registry, [Corrections(drawn_site, accepted)], [validation], config)
    meta = json.loads((result.candidate / "checkpoint.json").read_text(encoding="utf-8"))
    assert THRESHOLD_KEY in meta and meta[THRESHOLD_KEY] == result.candidate_metrics[THRESHOLD_KEY]
