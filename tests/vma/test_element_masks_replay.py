"""Rehearsal while fine-tuning on corrections: the version's own generator sites are made again and drawn from
in the configured share, a site the generator no longer makes as recorded is not replayed, bad settings are
named."""

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cama_pipeline.site_identity import site_identity
from models.vma.bev_sites import write_bev_site
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.config import MaskModelConfig
from models.vma.element_masks.replay import replay_candidates, replay_sites
from models.vma.element_masks.retrain import MaskRetrainConfig
from models.vma.element_masks.train import share_weights, site_drawer
from models.vma.shipped import SHIPPED_MASK_REGISTRY, shipped_registry
from models.vma.validation import ValidationSite


@dataclass
class Version:
    """A version record with the fields the replay reads."""

    meta: dict[str, Any]
    path: Path


def version_that_saw(*sites: Path) -> Version:
    identities = [site_identity(site).to_json() for site in sites]
    return Version({"data": {"seen_sites": identities, "seen_folders": []}}, Path("registry/v0001"))


def test_the_shipped_network_rehearses_the_bev_sites_it_trained_on() -> None:
    shipped = load_mask_checkpoint(shipped_registry(*SHIPPED_MASK_REGISTRY))
    assert [s.seed for s in replay_candidates(shipped)] == list(range(1000, 1012))


def test_replay_makes_the_recorded_sites_again_and_skips_one_the_generator_changed(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    original = write_bev_site(3005, tmp_path / "trained-on" / "seed-3005", resolution_m=0.2)
    version = version_that_saw(original)
    # made at the generator's default resolution, so its config is not the one the version trained on
    with caplog.at_level(logging.WARNING):
        assert replay_sites(version, tmp_path / "cache", 2, MaskModelConfig(), 0, seed=1) == []
    assert "not replayed" in caplog.text
    recorded = version.meta["data"]["seen_sites"][0]
    fresh = write_bev_site(3005, tmp_path / "default-resolution")
    recorded.update({k: v for k, v in site_identity(fresh).to_json().items() if k.endswith("digest")})
    (site,) = replay_sites(version, tmp_path / "cache2", 2, MaskModelConfig(), 0, seed=1)
    assert Path(site.name) == tmp_path / "cache2" / "seed-3005"
    assert site.targets.any() and len(site.images) == 1


def test_replay_of_none_writes_nothing(tmp_path: Path) -> None:
    version = version_that_saw()
    assert replay_sites(version, tmp_path / "cache", 4, MaskModelConfig(), 0, seed=0) == []
    assert not (tmp_path / "cache").exists()


def test_sites_are_drawn_by_their_weights_and_uniformly_as_before_without() -> None:
    draw = site_drawer(3, [0.0, 1.0, 3.0])
    rng = np.random.default_rng(0)
    counts = np.bincount([draw(rng) for _ in range(4000)], minlength=3)
    assert counts[0] == 0 and 0.2 < counts[1] / 4000 < 0.3
    uniform, before = site_drawer(5, None), np.random.default_rng(7)
    after = np.random.default_rng(7)
    assert [uniform(after) for _ in range(50)] == [int(before.integers(5)) for _ in range(50)]


def test_a_reconstruction_share_splits_the_crops_between_the_two_kinds_of_site() -> None:
    bev = [Path(f"data/vma/train/seed-{seed}") for seed in (1000, 1001, 1002)]
    rebuilt = [ValidationSite(Path("data/synthetic/random-9101"), Path("bev"), reconstructed=True)]
    weights = share_weights([*bev, *rebuilt], 0.25)
    assert weights == pytest.approx([0.25, 0.25, 0.25, 0.25])  # three BEV sites share 0.75, one rebuilt 0.25
    assert share_weights([*rebuilt, *bev], 0.5) == pytest.approx([0.5, 0.5 / 3, 0.5 / 3, 0.5 / 3])
    for sites, share in (([*bev, *rebuilt], 1.0), (bev, 0.5), ([*bev, *rebuilt], 0.0)):
        with pytest.raises(ValueError, match="reconstruction_share"):
            share_weights(sites, share)


@pytest.mark.parametrize("weights", [[1.0], [1.0, -1.0], [0.0, 0.0]])
def test_bad_site_weights_are_named(weights: list[float]) -> None:
    with pytest.raises(ValueError, match="site_weights"):
        site_drawer(2, weights)


@pytest.mark.parametrize(
    ("field", "value"), [("replay_share", 1.0), ("replay_share", -0.1), ("replay_sites", -1)]
)
def test_bad_replay_settings_are_named(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        MaskRetrainConfig(**{field: value})
