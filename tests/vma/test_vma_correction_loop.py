"""The human-in-the-loop: corrections of proposals retrain the model, and the evaluation gate guards promotion."""

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from annotations import Georeference
from annotations.geometry import resample_fixed
from cama_pipeline.evaluate.chamfer_ap import chamfer_distance
from models.vma.checkpoint import current_version, load_checkpoint, promote, save_version
from models.vma.config import ModelConfig, TrainConfig
from models.vma.gate import gate_passes, passes_gate, saving_confidence
from models.vma.model import VmaNet
from models.vma.rasters import load_site_rasters, vector_map_of
from models.vma.retrain import (
    Corrections,
    RetrainConfig,
    gate_checkpoint,
    retrain_from_corrections,
)
from models.vma.rule_based import propose_rule_based
from models.vma.vectors import Vector, proposals_as_annotations, read_vectors
from tests.vma.vma_test_sites import hand_drawn_site

NOTHING_SEEN = {"sites": [], "seen_sites": [], "seen_folders": []}
"""`data` of a version saved untrained: it saw no site."""
LOOP = ModelConfig(
    resolution_m=0.5, patch_px=64, num_queries=12, num_points=8, dim=64, decoder_layers=2, heads=4
)


def simulated_review(site: Path, proposals: list[Vector], share: float, rng: np.random.Generator):
    """A reviewer works through `share` of the proposals: matched ones are fixed to the truth, others rejected;
    the truth nobody proposed is drawn by hand. Returns the reviewed annotation set."""
    truth = read_vectors(vector_map_of(site))
    reviewed = [p for p in proposals if rng.random() < share]
    fixed, rejected, used = [], [], set()
    for proposal in reviewed:
        same = [(k, t) for k, t in enumerate(truth) if t.cls == proposal.cls and k not in used]
        dist = [
            chamfer_distance(resample_fixed(proposal.points, 50), resample_fixed(t.points, 50))
            for _, t in same
        ]
        if dist and min(dist) < 3.0:
            k, t = same[int(np.argmin(dist))]
            used.add(k)
            fixed.append(Vector(t.cls, t.points, 1.0))
        else:
            rejected.append(proposal)
    drawn = [t for k, t in enumerate(truth) if k not in used]
    rasters = load_site_rasters(site)
    georeference = Georeference(
        site_origin_xy=rasters.origin_xy,
        origin_xy=rasters.origin_xy,
        resolution=rasters.resolution_m,
        width=rasters.shape[1],
        height=rasters.shape[0],
    )
    labelled = proposals_as_annotations(fixed + drawn + rejected, georeference, site.name, "reviewer")
    states = ["fixed"] * (len(fixed) + len(drawn)) + ["rejected"] * len(rejected)
    elements = [e.with_changes(review_state=s) for e, s in zip(labelled.elements, states, strict=True)]
    return labelled.model_copy(update={"elements": elements}), len(fixed), len(rejected)


@pytest.mark.slow
def test_corrections_raise_validation_map(bev_sites: dict[str, Path], tmp_path: Path) -> None:
    registry = tmp_path / "registry"
    promote(registry, save_version(registry, VmaNet(LOOP), {"metrics": {}, "data": NOTHING_SEEN}).name)
    proposals = propose_rule_based(load_site_rasters(bev_sites["train"]))
    annotations, fixed, rejected = simulated_review(
        bev_sites["train"], proposals, 0.7, np.random.default_rng(0)
    )
    assert fixed > 0
    config = RetrainConfig(train=TrainConfig(steps=120, batch_size=4, learning_rate=2e-3), replay_share=0.1)
    result = retrain_from_corrections(
        registry, [Corrections(bev_sites["train"], annotations)], [bev_sites["val"]], config
    )
    assert result.labels == len(annotations.elements) - rejected and result.negatives == rejected
    assert result.candidate_metrics["mean_ap"] > result.current_metrics["mean_ap"]
    assert result.promoted and current_version(registry) == result.candidate


@pytest.mark.slow
def test_gate_refuses_a_deliberately_bad_checkpoint(bev_sites: dict[str, Path], tmp_path: Path) -> None:
    shipped = Path(__file__).parents[2] / "models" / "vma" / "checkpoints"
    registry = tmp_path / "registry"
    good = current_version(shipped)
    (registry / "v0001").mkdir(parents=True)
    for name in ("model.pt", "checkpoint.json"):
        (registry / "v0001" / name).write_bytes((good / name).read_bytes())
    promote(registry, "v0001")
    bad = VmaNet(load_checkpoint(good).config)  # untrained weights: proposes nothing useful
    candidate = save_version(
        registry, bad, {"metrics": {}, "data": {"note": "deliberately bad", **NOTHING_SEEN}}
    )
    promoted, current, challenger = gate_checkpoint(registry, candidate, [bev_sites["val"]])
    assert current["mean_ap"] > 0.0
    assert not promoted and challenger["mean_ap"] < current["mean_ap"]
    assert current_version(registry).name == "v0001"


def test_gate_rule() -> None:
    assert passes_gate(0.5, 0.5, 0.0) and passes_gate(None, 0.1, 0.0) and passes_gate(0.5, 0.48, 0.05)
    assert not passes_gate(0.5, 0.49, 0.0) and not passes_gate(0.5, None, 0.0)


def test_the_review_gate_refuses_a_model_that_costs_the_annotator_more_time() -> None:
    config = RetrainConfig(tolerance=0.0, time_tolerance=0.1)
    current = {"mean_ap": 0.5, "review": {"correction_s": 100.0}}
    assert gate_passes(current, {"mean_ap": 0.6, "review": {"correction_s": 109.0}}, config)
    assert not gate_passes(current, {"mean_ap": 0.6, "review": {"correction_s": 111.0}}, config)
    assert not gate_passes(current, {"mean_ap": 0.4, "review": {"correction_s": 50.0}}, config)
    assert gate_passes({"mean_ap": 0.5}, {"mean_ap": 0.5}, config)  # no review gate: mAP alone
    with pytest.raises(ValueError, match="time_tolerance"):
        RetrainConfig(time_tolerance=-0.1)


def test_the_review_gate_wants_a_saving_that_holds_across_the_validation_sites() -> None:
    current = [100.0, 60.0, 80.0, 50.0, 70.0, 90.0]
    # 22 s less in all, won on one site and lost a little on four; 18 s less, a little on every site
    lucky = [100.0, 62.0, 82.0, 20.0, 72.0, 92.0]
    steady = [96.0, 57.0, 77.0, 47.0, 67.0, 88.0]
    assert saving_confidence(current, lucky) < 0.9 < saving_confidence(current, steady)
    assert saving_confidence(current, current) == 0.0  # no saving at all
    config = RetrainConfig(tolerance=0.0, time_tolerance=0.0)

    def metrics(per_site: list[float]) -> dict[str, Any]:
        return {"mean_ap": 0.5, "review": {"correction_s": sum(per_site), "per_site_correction_s": per_site}}

    assert not gate_passes(metrics(current), metrics(lucky), config)
    assert gate_passes(metrics(current), metrics(steady), config)
    assert gate_passes(metrics(current), metrics(lucky), replace(config, time_confidence=0.0))  # totals alone
    with pytest.raises(ValueError, match="time_confidence"):
        RetrainConfig(time_confidence=1.0)
    with pytest.raises(ValueError, match="same sites"):
        saving_confidence(current, steady[:3])


@pytest.mark.parametrize(("candidate_s", "promoted"), [(150.0, False), (80.0, True)])
def test_retraining_promotes_only_past_the_review_gate(
    drawn_site: Path, tmp_path: Path, candidate_s: float, promoted: bool
) -> None:
    registry = tmp_path / "registry"
    promote(registry, save_version(registry, VmaNet(LOOP), {"metrics": {}, "data": NOTHING_SEEN}).name)
    truth = read_vectors(vector_map_of(drawn_site))
    annotations, _, _ = simulated_review(drawn_site, truth, 1.0, np.random.default_rng(0))
    seconds = iter([100.0, candidate_s])  # the current model is reviewed first, then the candidate

    def review(propose, sites):  # type: ignore[no-untyped-def]
        propose(load_site_rasters(sites[0]))  # the gate hands over a working proposer
        return {"correction_s": next(seconds)}

    config = RetrainConfig(train=TrainConfig(steps=2, batch_size=2), tolerance=1.0)
    result = retrain_from_corrections(
        registry,
        [Corrections(drawn_site, annotations)],
        [hand_drawn_site(tmp_path / "val")],
        config,
        review=review,
    )
    assert result.current_metrics["review"] == {"correction_s": 100.0}
    assert result.candidate_metrics["review"] == {"correction_s": candidate_s}
    assert result.promoted is promoted and (current_version(registry) == result.candidate) is promoted


def test_retrain_needs_labels(drawn_site: Path, tmp_path: Path) -> None:
    registry = tmp_path / "registry"
    promote(registry, save_version(registry, VmaNet(LOOP), {"metrics": {}, "data": NOTHING_SEEN}).name)
    rasters = load_site_rasters(drawn_site)
    georeference = Georeference(
        site_origin_xy=rasters.origin_xy, origin_xy=rasters.origin_xy, resolution=0.1, width=600, height=400
    )
    empty = proposals_as_annotations([], georeference, "drawn", "nobody")
    with pytest.raises(ValueError, match="accepted/fixed annotations"):
        retrain_from_corrections(
            registry, [Corrections(drawn_site, empty)], [hand_drawn_site(tmp_path / "val")]
        )
