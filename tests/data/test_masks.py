"""Mask roots: which folders a `--masks` choice names, in which order the loader tries them, and the errors."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from cama_pipeline.data import DatasetError, load_dataset, mask_roots, masks_fingerprint, parse_mask_choice
from cama_pipeline.data.masks import prediction_needed
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.semantics import Semantic
from cama_pipeline.workspace import Workspace
from tests.data.nuscenes_fixture import NuScenesFixture, sample_data_token, write_nuscenes_fixture


def write_mask_root(root: Path, fixture: NuScenesFixture, value: int, *, manifest: bool = True) -> None:
    """Semantic masks of every camera image of `fixture` filled with `value`, and (if asked) a manifest."""
    for record in fixture.read_table("sample_data"):
        if record["filename"].endswith(".jpg"):
            path = root / mask_relpath(SEMANTIC_DIR, record["filename"])
            path.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(path), np.full((fixture.height, fixture.width), value, np.uint8))
    if manifest:
        (root / "manifest.json").write_text(json.dumps({"made_by": "test", "value": value}))


@pytest.fixture
def bare(tmp_path: Path) -> NuScenesFixture:
    """A data set without masks; its workspace is `<tmp>/workspace`."""
    return write_nuscenes_fixture(tmp_path / "nuscenes", with_masks=False, n_samples=2)


def test_choices_parse() -> None:
    assert parse_mask_choice("auto") == "auto" and parse_mask_choice("imported") == "imported"
    assert parse_mask_choice("masks/mine") == Path("masks/mine")
    with pytest.raises(ValueError, match="--masks"):
        parse_mask_choice(" ")


def test_dataset_masks_win_over_predicted(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2)
    ws = Workspace.for_dataset(fixture.root)
    write_mask_root(ws.masks_dir("predicted"), fixture, int(Semantic.VEHICLE))
    roots = mask_roots("auto", fixture.root, None)
    assert roots == (fixture.root.absolute(), ws.masks_dir("predicted"))
    token = sample_data_token("CAM_BACK", 1)
    image = load_dataset(fixture.root, mask_roots=roots).image(token)
    assert image.semantic_mask_path is not None
    assert image.semantic_mask_path.is_relative_to(fixture.root.absolute())
    assert int(image.load_semantic().max()) != int(Semantic.VEHICLE)  # the data set's mask, not the predicted
    # an image whose data set mask is gone takes the predicted one; its instance mask stays the data set's
    image.semantic_mask_path.unlink()
    fallback = load_dataset(fixture.root, mask_roots=roots).image(token)
    assert fallback.semantic_mask_path is not None
    assert fallback.semantic_mask_path.is_relative_to(ws.masks_dir("predicted"))
    assert np.all(fallback.load_semantic() == Semantic.VEHICLE)
    assert fallback.instance_mask_path == image.instance_mask_path
    # --masks predicted reads only the workspace's, even where the data set has masks
    only = load_dataset(fixture.root, mask_roots=mask_roots("predicted", fixture.root, ws))
    assert np.all(only.image(sample_data_token("CAM_FRONT", 0)).load_semantic() == Semantic.VEHICLE)
    assert only.image(sample_data_token("CAM_FRONT", 0)).instance_mask_path is None


def test_mask_free_dataset_reads_workspace_masks(bare: NuScenesFixture, tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "workspace")
    assert mask_roots("auto", bare.root, ws) == ()
    assert (
        load_dataset(bare.root, mask_roots=()).image(sample_data_token("CAM_FRONT", 0)).semantic_mask_path
        is None
    )
    write_mask_root(ws.masks_dir("imported"), bare, int(Semantic.ROAD))
    assert mask_roots("auto", bare.root, ws) == (ws.masks_dir("imported"),)
    write_mask_root(ws.masks_dir("predicted"), bare, int(Semantic.CURB))
    roots = mask_roots("auto", bare.root, ws)
    assert roots == (ws.masks_dir("predicted"), ws.masks_dir("imported"))
    image = load_dataset(bare.root, mask_roots=roots).image(sample_data_token("CAM_FRONT", 1))
    assert np.all(image.load_semantic() == Semantic.CURB)  # predicted before imported
    imported = load_dataset(bare.root, mask_roots=mask_roots("imported", bare.root, ws))
    assert np.all(imported.image(sample_data_token("CAM_FRONT", 1)).load_semantic() == Semantic.ROAD)


def test_unfinished_workspace_masks_do_not_count(bare: NuScenesFixture, tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "workspace")
    write_mask_root(ws.masks_dir("predicted"), bare, int(Semantic.ROAD), manifest=False)
    assert mask_roots("auto", bare.root, ws) == ()
    with pytest.raises(FileNotFoundError, match="cama segment") as info:
        mask_roots("predicted", bare.root, ws)
    assert str(ws.masks_dir("predicted")) in str(info.value)


def test_named_sources_that_are_missing_say_what_makes_them(bare: NuScenesFixture, tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "workspace")
    with pytest.raises(DatasetError, match="no masks") as info:
        mask_roots("dataset", bare.root, ws)
    assert str(bare.root.absolute()) in str(info.value)
    with pytest.raises(FileNotFoundError, match="cama import-masks") as info2:
        mask_roots("imported", bare.root, ws)
    assert str(ws.masks_dir("imported")) in str(info2.value)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match="no semantic/ or lane_instance/") as info3:
        mask_roots(empty, bare.root, ws)
    assert str(empty) in str(info3.value)


def test_a_folder_of_masks_is_a_root(bare: NuScenesFixture, tmp_path: Path) -> None:
    folder = tmp_path / "elsewhere"
    write_mask_root(folder, bare, int(Semantic.SKY), manifest=False)
    assert mask_roots(str(folder), bare.root, None) == (folder,)
    dataset = load_dataset(bare.root, mask_roots=(folder,))
    assert dataset.mask_roots == (folder,)
    assert np.all(dataset.image(sample_data_token("CAM_BACK", 0)).load_semantic() == Semantic.SKY)


def test_image_without_mask_names_the_image_and_the_way_out(bare: NuScenesFixture) -> None:
    image = load_dataset(bare.root, mask_roots=()).image(sample_data_token("CAM_FRONT", 0))
    with pytest.raises(DatasetError, match="no instance mask") as info:
        image.load_instance()
    message = str(info.value)
    assert str(image.path) in message and "cama segment" in message and "cama import-masks" in message


def test_fingerprint_follows_choice_and_manifest(bare: NuScenesFixture, tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "workspace")
    write_mask_root(ws.masks_dir("predicted"), bare, int(Semantic.ROAD))
    roots = mask_roots("auto", bare.root, ws)
    auto = masks_fingerprint("auto", roots, bare.root)
    assert auto == masks_fingerprint("auto", mask_roots("auto", bare.root, ws), bare.root)
    assert auto != masks_fingerprint("predicted", roots, bare.root)
    write_mask_root(ws.masks_dir("predicted"), bare, int(Semantic.CURB))  # new masks, new manifest
    assert masks_fingerprint("auto", roots, bare.root) != auto
    folder = tmp_path / "elsewhere"
    write_mask_root(folder, bare, int(Semantic.SKY), manifest=False)
    before = masks_fingerprint(folder, (folder,), bare.root)
    first = next((folder / SEMANTIC_DIR).rglob("*.png"))
    cv2.imwrite(str(first), np.zeros((bare.height, bare.width + 1), np.uint8))  # one mask rewritten
    assert masks_fingerprint(folder, (folder,), bare.root) != before
    assert not (folder / INSTANCE_DIR).exists()


def test_when_a_run_must_predict_masks(bare: NuScenesFixture, tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "workspace")
    assert prediction_needed("auto", bare.root, ws) is None  # nothing anywhere: predict
    assert prediction_needed("dataset", bare.root, ws) == "--masks dataset"
    assert prediction_needed(tmp_path / "mine", bare.root, ws) == f"masks from {tmp_path / 'mine'}"
    write_mask_root(ws.masks_dir("imported"), bare, int(Semantic.ROAD))
    assert "imported masks" in (prediction_needed("auto", bare.root, ws) or "")
    assert prediction_needed("predicted", bare.root, ws) is None
    write_mask_root(ws.masks_dir("predicted"), bare, int(Semantic.ROAD))
    assert prediction_needed("auto", bare.root, ws) is None  # predicted masks are kept up to date
    with_masks = write_nuscenes_fixture(tmp_path / "with-masks" / "nuscenes", n_samples=1)
    assert prediction_needed("auto", with_masks.root, None) == "the data set has its own masks"
