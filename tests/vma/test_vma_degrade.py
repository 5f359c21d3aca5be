"""Reconstruction-like damage for benchmarks: markings thinned, noise added, unobserved cells kept."""

from dataclasses import replace
from pathlib import Path

import numpy as np

from cama_pipeline.semantics import Semantic
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.rasters import load_site_rasters


def test_damage_is_seeded_and_keeps_unobserved_cells(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    semantic = rasters.semantic.copy()
    semantic[:20] = int(Semantic.UNOBSERVED)
    clean = replace(rasters, semantic=semantic)
    damaged = degrade_rasters(
        clean, DegradeConfig(marking_dropout=0.5, speckle=0.0, edge_jitter_px=0, seed=1)
    )
    assert (damaged.semantic[:20] == int(Semantic.UNOBSERVED)).all()
    marking = int(Semantic.LANE_MARKING)
    assert (damaged.semantic == marking).sum() < 0.8 * (clean.semantic == marking).sum()
    assert not np.array_equal(damaged.photometric, clean.photometric)
    again = degrade_rasters(clean, DegradeConfig(marking_dropout=0.5, speckle=0.0, edge_jitter_px=0, seed=1))
    assert np.array_equal(again.semantic, damaged.semantic)
    untouched = degrade_rasters(clean, DegradeConfig(0.0, 3.0, 0.0, 0, 0.0))
    assert np.array_equal(untouched.semantic, clean.semantic)


def test_speckle_relabels_cells(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    damaged = degrade_rasters(
        rasters, DegradeConfig(marking_dropout=0.0, speckle=0.05, edge_jitter_px=0, seed=2)
    )
    changed = (damaged.semantic != rasters.semantic).mean()
    assert 0.01 < changed < 0.05
