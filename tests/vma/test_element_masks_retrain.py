"""Corrections change what the element-mask network draws: a retrain on one site's corrected geometry moves its
proposals the same way on another site, and the gate keeps a model that got worse out."""

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from shapely.geometry import LineString, MultiLineString

from annotations import AnnotationSet, Georeference
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from models.vma.checkpoint import CheckpointError, current_version
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.config import MaskTrainConfig
from models.vma.element_masks.propose import predict_site_masks
from models.vma.element_masks.retrain import (
    MaskRetrainConfig,
    evaluate_mask_model,
    retrain_masks_from_corrections,
)
from models.vma.rasters import SiteRasters, load_site_rasters, vector_map_of
from models.vma.retrain import Corrections, RetrainResult
from models.vma.shipped import SHIPPED_MASK_REGISTRY, shipped_registry
from models.vma.vectors import Vector, proposals_as_annotations, read_vectors

GUTTER_M = 0.8
"""The corrections' convention: boundaries drawn this far into the road from the kerb line."""


def towards_road(vector: Vector, rasters: SiteRasters, offset_m: float) -> Vector:
    """A boundary moved `offset_m` sideways onto the road side (the side whose offset points are more on road)."""
    line = LineString(vector.points)
    best, best_share = vector, -1.0
    for side in (offset_m, -offset_m):
        moved = line.offset_curve(side)
        if moved.is_empty or not isinstance(moved, LineString):
            continue
        points = np.asarray(moved.coords)
        colrow = np.rint(rasters.pixel_from_global(points)).astype(int)
        h, w = rasters.shape
        inside = (colrow[:, 0] >= 0) & (colrow[:, 0] < w) & (colrow[:, 1] >= 0) & (colrow[:, 1] < h)
        share = float(
            np.isin(rasters.semantic[colrow[inside, 1], colrow[inside, 0]], ROAD_SURFACE_IDS).mean()
        )
        if share > best_share and len(points) >= 2:
            best, best_share = Vector(vector.cls, points), share
    return best


def gutter_truth(site: Path) -> list[Vector]:
    """The site's true vectors with boundaries at the gutter convention."""
    rasters = load_site_rasters(site)
    return [
        towards_road(v, rasters, GUTTER_M) if v.cls == "boundary" else v
        for v in read_vectors(vector_map_of(site))
    ]


def corrected(site: Path, vectors: list[Vector]) -> AnnotationSet:
    """`vectors` as a reviewed annotation set of `site` (every element fixed)."""
    rasters = load_site_rasters(site)
    georeference = Georeference.of(rasters.georeference, site_origin_xy=rasters.origin_xy)
    labelled = proposals_as_annotations(vectors, georeference, site.name, "reviewer")
    return labelled.model_copy(
        update={"elements": [e.with_changes(review_state="fixed") for e in labelled.elements]}
    )


def mean_distance(vectors: list[Vector], truth: list[Vector]) -> float:
    """Mean distance of the boundaries' points (every 0.5 m) to the nearest true boundary."""
    lines = MultiLineString([t.points for t in truth if t.cls == "boundary"])
    distances = []
    for vector in (v for v in vectors if v.cls == "boundary"):
        line = LineString(vector.points)
        for s in np.arange(0.0, line.length, 0.5):
            distances.append(lines.distance(line.interpolate(s)))
    return float(np.mean(distances))


@pytest.fixture()
def registry(tmp_path: Path) -> Path:
    """A writable copy of the shipped element-mask registry."""
    copy = tmp_path / "registry"
    shutil.copytree(shipped_registry(*SHIPPED_MASK_REGISTRY), copy)
    return copy


@pytest.mark.slow
def test_a_retrain_moves_boundaries_to_the_corrected_convention_on_another_site(
    bev_sites: dict[str, Path], registry: Path
) -> None:
    val = bev_sites["val"]
    before = predict_site_masks(load_mask_checkpoint(registry).model, load_site_rasters(val))
    config = MaskRetrainConfig(
        train=MaskTrainConfig(steps=150, batch_size=4, crop_px=96, learning_rate=1e-3, damaged_copies=1)
    )
    result = retrain_masks_from_corrections(
        registry,
        [Corrections(bev_sites["train"], corrected(bev_sites["train"], gutter_truth(bev_sites["train"])))],
        [val],
        config,
    )
    after = predict_site_masks(load_mask_checkpoint(result.candidate).model, load_site_rasters(val))
    shifted, original = gutter_truth(val), read_vectors(vector_map_of(val))
    # before: on the kerb line, the gutter line 0.8 m away; after: the other way round (the val site never seen)
    assert mean_distance(before, original) < mean_distance(before, shifted)
    assert mean_distance(after, shifted) < mean_distance(before, shifted) - 0.3
    assert mean_distance(after, shifted) < mean_distance(after, original)
    meta_data = load_mask_checkpoint(result.candidate).meta["data"]
    assert (
        meta_data["labels"] == result.labels > 0
        and str(Path(bev_sites["train"]).absolute()) in meta_data["seen_folders"]
    )
    assert load_mask_checkpoint(result.candidate).meta["replay"] == {"sites": [], "share": 0.0}


def retrain_on_truth(registry: Path, bev_sites: dict[str, Path], config: MaskRetrainConfig) -> RetrainResult:
    """Retrain `registry` on the train site's true vectors (every element fixed), gated on the val site."""
    truth = read_vectors(vector_map_of(bev_sites["train"]))
    return retrain_masks_from_corrections(
        registry,
        [Corrections(bev_sites["train"], corrected(bev_sites["train"], truth))],
        [bev_sites["val"]],
        config,
    )


@pytest.mark.slow
def test_the_gate_keeps_a_worse_candidate_out(bev_sites: dict[str, Path], registry: Path) -> None:
    promoted_before = current_version(registry)
    config = MaskRetrainConfig(
        train=MaskTrainConfig(steps=20, batch_size=2, crop_px=64, learning_rate=5.0, damaged_copies=0),
        replay_sites=0,
    )
    result = retrain_on_truth(registry, bev_sites, config)
    assert result.candidate_metrics["mean_ap"] < result.current_metrics["mean_ap"]
    assert not result.promoted and current_version(registry) == promoted_before
    assert (result.candidate / "checkpoint.json").is_file()  # kept, with its figures, but not promoted


def weight_distance(model: torch.nn.Module, other: torch.nn.Module) -> float:
    """The L2 distance between two networks' parameters."""
    pairs = zip(model.parameters(), other.parameters(), strict=True)
    return float(sum(((a.detach() - b.detach()) ** 2).sum() for a, b in pairs) ** 0.5)


@pytest.mark.slow
def test_a_retrain_from_an_earlier_version_starts_there_and_is_gated_against_the_promoted_one(
    bev_sites: dict[str, Path], registry: Path
) -> None:
    promoted = current_version(registry)
    earlier = sorted(p.name for p in registry.glob("v*") if p != promoted)[-1]
    config = MaskRetrainConfig(
        train=MaskTrainConfig(steps=3, batch_size=2, crop_px=64, learning_rate=1e-5, damaged_copies=0),
        replay_sites=0,
        start_version=earlier,
    )
    result = retrain_on_truth(registry, bev_sites, config)
    candidate = load_mask_checkpoint(result.candidate)
    start, current = load_mask_checkpoint(registry / earlier), load_mask_checkpoint(promoted)
    # a few steps at a tiny rate: the candidate lies next to the version it was trained from, far from the promoted
    assert weight_distance(candidate.model, start.model) < 0.1 * weight_distance(
        candidate.model, current.model
    )
    assert candidate.meta["parent"] == earlier and candidate.meta["gated_against"] == promoted.name
    # both are scored as they are stored: the gate's figures are those of the saved candidate and the promoted one
    saved = evaluate_mask_model(candidate.model, [bev_sites["val"]])
    assert (result.candidate_metrics["ap"], result.candidate_metrics["mean_ap"]) == (
        saved["ap"],
        saved["mean_ap"],
    )
    rescored = evaluate_mask_model(current.model, [bev_sites["val"]])
    assert (result.current_metrics["ap"], result.current_metrics["mean_ap"]) == (
        rescored["ap"],
        rescored["mean_ap"],
    )


@pytest.mark.parametrize("version", ["v0099", "../v0003"])
def test_a_retrain_from_a_version_the_registry_lacks_names_it(registry: Path, version: str) -> None:
    promoted_before = current_version(registry)
    versions_before = sorted(p.name for p in registry.iterdir())
    with pytest.raises(CheckpointError, match=f"no version '{re.escape(version)}' to retrain from"):
        retrain_masks_from_corrections(registry, [], [], MaskRetrainConfig(start_version=version))
    assert current_version(registry) == promoted_before
    assert sorted(p.name for p in registry.iterdir()) == versions_before
