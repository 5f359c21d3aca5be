"""The shipped VMA model is found from any working directory, says which checkpoint it is, and is never
written to: retraining servers get their own seeded registry. Every version records the sites it saw and is
refused on them."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from annotations import AnnotationSet
from app.backend.config import Settings
from app.backend.jobs.vma import unavailable_kinds
from app.backend.vma_loop import with_shipped_registry
from cama_pipeline.site_identity import SeenSiteError
from cama_studio.config import PipelineConfig
from models.vma.bev_sites import write_bev_site
from models.vma.checkpoint import (
    CURRENT,
    CheckpointError,
    checkpoint_kind,
    current_version,
    ensure_unseen,
    load_checkpoint,
    refuse_seen,
)
from models.vma.config import ModelConfig, TrainConfig
from models.vma.shipped import SHIPPED_MASK_REGISTRY, resolve_checkpoint, seed_registry, shipped_registry
from models.vma.train import train

REPO = Path(__file__).resolve().parents[2]
TINY_MODEL = ModelConfig(
    resolution_m=0.2, patch_px=64, num_queries=4, num_points=4, dim=16, decoder_layers=1, heads=2
)


def _promoted_version() -> str:
    return str(json.loads((REPO / "models" / "vma" / "checkpoints" / CURRENT).read_text())["version"])


def test_the_shipped_model_is_found_from_any_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert PipelineConfig().checkpoint is None  # `cama run` asks for the shipped model, not a relative path
    version = resolve_checkpoint(None)
    assert version.is_absolute() and version.name == _promoted_version()
    assert version == (REPO / "models" / "vma" / "checkpoints" / _promoted_version()).resolve()


def test_resolve_checkpoint_names_a_bad_folder(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match=str(tmp_path)):
        resolve_checkpoint(tmp_path)


def test_cama_propose_from_a_temporary_directory_uses_and_names_the_shipped_model(
    drawn_site: Path, tmp_path: Path
) -> None:
    """The real command line, started outside the checkout: it finds the default model (the element-mask
    network) and prints which one."""
    workdir = tmp_path / "elsewhere"
    workdir.mkdir()
    env = {**os.environ, "COLUMNS": "60"}
    done = subprocess.run(
        [sys.executable, "-m", "cama_studio.cli", "propose", str(drawn_site), "--out", "p.json"],
        cwd=workdir,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    shipped = current_version(shipped_registry(*SHIPPED_MASK_REGISTRY)).resolve()
    assert f"VMA checkpoint {shipped.name} (shipped with the package: {shipped})" in done.stdout
    proposals = AnnotationSet.read_json(workdir / "p.json")
    assert proposals.elements and {e.author for e in proposals.elements} == {f"vma-masks-{shipped.name}"}


def test_seed_registry_copies_the_shipped_model_once_and_leaves_it_untouched(tmp_path: Path) -> None:
    shipped = shipped_registry()
    before = sorted(p.name for p in shipped.iterdir())
    registry = seed_registry(tmp_path / "server" / "vma-registry")
    assert (registry / CURRENT).read_text() == (shipped / CURRENT).read_text()
    assert (registry / _promoted_version() / "model.pt").read_bytes() == (
        shipped / _promoted_version() / "model.pt"
    ).read_bytes()
    (registry / CURRENT).write_text(json.dumps({"version": "v0001"}))  # a later promotion is kept
    assert seed_registry(registry) == registry and "v0001" in (registry / CURRENT).read_text()
    assert sorted(p.name for p in shipped.iterdir()) == before
    assert not list(tmp_path.glob("server/.*partial"))
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(CheckpointError, match="foreign: not empty and not a VMA registry"):
        seed_registry(foreign)
    assert (foreign / "notes.txt").read_text() == "mine"


def test_servers_get_a_seeded_registry_so_the_learned_model_and_retrain_are_available(tmp_path: Path) -> None:
    bare = Settings(data_dir=tmp_path / "data")
    assert "no VMA checkpoint registry" in unavailable_kinds(bare)["retrain"]
    settings = with_shipped_registry(bare)
    assert (
        settings.vma_registry == tmp_path / "data" / "vma-mask-registry"
    )  # the element-mask network by default
    assert checkpoint_kind(settings.vma_registry) == "element_masks"
    assert (tmp_path / "data" / "vma-mask-registry" / CURRENT).is_file()
    # the registry is there; what retrain still needs is a held-out site for its promotion gate
    assert "validation sites" in unavailable_kinds(settings)["retrain"]
    gated = with_shipped_registry(Settings(data_dir=tmp_path / "data", vma_validation_sites=(tmp_path,)))
    assert "retrain" not in unavailable_kinds(gated)
    chosen = Settings(data_dir=tmp_path / "data", vma_registry=tmp_path / "mine")
    assert with_shipped_registry(chosen) == chosen  # a configured registry is used as it is


def test_a_server_can_start_from_the_shipped_maptr_model_and_an_older_server_keeps_its_registry(
    tmp_path: Path,
) -> None:
    settings = with_shipped_registry(Settings(data_dir=tmp_path / "data", vma_model="maptr"))
    assert settings.vma_registry == tmp_path / "data" / "vma-registry"
    assert checkpoint_kind(settings.vma_registry) == "maptr"
    # a server whose data folder holds only a MapTR-style registry (started before the default changed) keeps it
    assert with_shipped_registry(Settings(data_dir=tmp_path / "data")).vma_registry == settings.vma_registry
    masks = with_shipped_registry(Settings(data_dir=tmp_path / "data", vma_model="masks"))
    assert checkpoint_kind(masks.vma_registry) == "element_masks"
    # once both are there, auto takes the element-mask network's
    assert with_shipped_registry(Settings(data_dir=tmp_path / "data")).vma_registry == masks.vma_registry
    with pytest.raises(ValueError, match="CAMA_VMA_MODEL: must be one of auto, maptr, masks"):
        Settings.from_env({"CAMA_VMA_MODEL": "hdmapnet"}, data_dir=tmp_path)


def test_a_checkpoint_refuses_to_be_scored_on_the_sites_it_trained_on(
    bev_sites: dict[str, Path], tmp_path: Path
) -> None:
    registry = tmp_path / "registry"
    config = TrainConfig(steps=2, batch_size=2, threads=1)
    elsewhere = write_bev_site(
        3001, tmp_path / "same-place", resolution_m=0.2
    )  # the same place, another folder
    with pytest.raises(SeenSiteError, match="trained on this folder"):  # validating on a training site
        train(TINY_MODEL, config, [bev_sites["train"]], registry, validation_sites=[bev_sites["train"]])
    with pytest.raises(SeenSiteError, match="same seed 3001"):
        train(TINY_MODEL, config, [bev_sites["train"]], registry, validation_sites=[elsewhere])
    folder = train(TINY_MODEL, config, [bev_sites["train"]], registry, show_progress=False)
    checkpoint = load_checkpoint(folder)
    seen = checkpoint.meta["data"]["seen_sites"]
    assert [(s["preset"], s["seed"], s["location"]) for s in seen] == [("vma", 3001, "synth-vma-3001")]
    with pytest.raises(SeenSiteError, match="trained on this folder"):
        ensure_unseen(checkpoint, bev_sites["train"])
    elsewhere = write_bev_site(
        3001, tmp_path / "same-place", resolution_m=0.2
    )  # the same place, another folder
    with pytest.raises(SeenSiteError, match="same seed 3001"):
        ensure_unseen(checkpoint, elsewhere)
    assert ensure_unseen(checkpoint, bev_sites["val"]).seed == 3002  # type: ignore[union-attr]
    # a version trained from it inherits what its parent saw
    child = load_checkpoint(
        train(TINY_MODEL, config, [bev_sites["val"]], registry, init=folder, show_progress=False)
    )
    assert {s["seed"] for s in child.meta["data"]["seen_sites"]} == {3001, 3002}
    with pytest.raises(SeenSiteError):
        ensure_unseen(child, elsewhere)


def test_the_shipped_model_never_saw_the_benchmark_validation_or_demo_sites() -> None:
    shipped = load_checkpoint(shipped_registry())
    locations = {s["location"] for s in shipped.meta["data"]["seen_sites"]}
    assert "synthetic-default" not in locations and "synthetic-tiny" not in locations
    assert not any(f"synth-vma-{seed}" in locations for seed in range(2000, 2005))
    assert not any(f"synth-vma-{seed}" in locations for seed in range(3000, 3003))


def test_a_site_folder_and_its_raster_folder_are_one_site(tmp_path: Path) -> None:
    site, rasters = tmp_path / "site", tmp_path / "site" / "ground_truth" / "bev"
    for trained, measured in ((rasters, site), (site, rasters), (site, site)):
        with pytest.raises(SeenSiteError, match="trained on this folder"):
            refuse_seen(measured, [], [str(trained)], "the model")
    assert refuse_seen(tmp_path / "other", [], [str(rasters)], "the model") is None
