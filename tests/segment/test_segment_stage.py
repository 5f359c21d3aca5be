"""The segment stage on the tiny site with a segmenter trained for a few steps: masks of the right size and type
for every key-frame image and every keyframe image, in the data set's layout under masks/predicted/; a rerun
does nothing; an interrupted run goes on where it stopped."""

import os
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.console import EXIT_OK
from cama_pipeline.data import DatasetError, load_dataset, mask_roots
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.keyframes.io import FrameRecord, KeyframesFile, write_keyframes
from cama_pipeline.segment import stage
from cama_pipeline.segment.checkpoint import CheckpointError
from cama_pipeline.segment.config import SegmentConfig
from cama_pipeline.segment.ego_clip import EgoClipConfig
from cama_pipeline.segment.io import progress_path, read_mask_manifest
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from tests.conftest import GeneratedSite
from tests.segment.segmenter_fixture import relabelled_copy, train_small


@pytest.fixture(scope="module")
def checkpoint(tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory) -> Path:
    copy = relabelled_copy(tiny_site.result.out_dir, tmp_path_factory.mktemp("train") / "site")
    return train_small(copy, tmp_path_factory.mktemp("ckpt") / "segmenter")


def config(checkpoint: Path) -> SegmentConfig:
    return SegmentConfig(checkpoint=checkpoint, batch_size=16, device="cpu")


def a_sweep_as_keyframe(root: Path, workspace: Workspace) -> str:
    """Write a keyframes file for the first scene whose one keyframe is a sweep image; its filename."""
    dataset = load_dataset(root, mask_roots=())
    scene = dataset.scenes[0]
    sweep = next(im for ims in scene.images.values() for im in ims if not im.is_key_frame)
    frame = FrameRecord(0, sweep.timestamp_us, {sweep.channel: sweep.token}, 0, True, "first")
    write_keyframes(
        workspace.keyframes(scene.name), KeyframesFile(scene.name, "x", {}, False, 0.0, 0, 0, (frame,))
    )
    return sweep.path.relative_to(dataset.root).as_posix()


def read_png(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return image


def key_frame_images(root: Path) -> list[str]:
    dataset = load_dataset(root, mask_roots=())
    return [im.path.relative_to(dataset.root).as_posix() for im in dataset.camera_images() if im.is_key_frame]


def test_masks_for_every_image_the_pipeline_uses(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path
) -> None:
    root = tiny_site.result.dataset_root
    ws = Workspace(tmp_path / "ws")
    sweep = a_sweep_as_keyframe(root, ws)
    result = stage.run(config(checkpoint), root, ws, workers=1, show_progress=False)
    (item,) = result.items
    assert not item.skipped and item.path == ws.masks_dir("predicted")
    expected = sorted([*key_frame_images(root), sweep])
    manifest = read_mask_manifest(ws.masks_manifest("predicted"))
    assert list(manifest.images) == expected and manifest.source == "predicted"
    assert manifest.made_by["checkpoint"] == "segmenter" and manifest.extra["segmented"] == len(expected)
    assert not progress_path(ws.masks_dir("predicted")).exists()
    height, width = tiny_site.config.camera.height_px, tiny_site.config.camera.width_px
    for name in expected[:: max(1, len(expected) // 10)] + [sweep]:
        semantic = read_png(ws.masks_dir("predicted") / mask_relpath(SEMANTIC_DIR, name))
        instance = read_png(ws.masks_dir("predicted") / mask_relpath(INSTANCE_DIR, name))
        assert semantic.shape == instance.shape == (height, width)
        assert (
            semantic.dtype == np.uint8 and instance.dtype == np.uint16 and semantic.max() <= int(Semantic.EGO)
        )
        classes = set(np.unique(instance // INSTANCE_ID_BASE)) - {0}
        assert classes <= {int(Semantic.CURB), int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK)}
    # the loader finds them as the workspace's predicted masks
    dataset = load_dataset(root, mask_roots=mask_roots("predicted", root, ws))
    image = next(im for im in dataset.camera_images() if im.is_key_frame)
    assert image.load_semantic().shape == (height, width) and image.load_instance().dtype == np.uint16


def test_a_rerun_skips_and_an_interrupted_run_resumes(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = tiny_site.result.dataset_root
    ws = Workspace(tmp_path / "ws")
    calls: list[int] = []
    real = stage.segment_chunk

    def interrupted(chunk: stage.Chunk) -> tuple[str, ...]:
        if len(calls) == 2:
            raise KeyboardInterrupt  # the user pressed Ctrl-C during the third batch
        calls.append(len(chunk.filenames))
        return real(chunk)

    monkeypatch.setattr(stage, "segment_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        stage.run(config(checkpoint), root, ws, workers=1, show_progress=False)
    assert not ws.masks_manifest("predicted").exists()  # incomplete: no other stage takes these masks
    assert progress_path(ws.masks_dir("predicted")).is_file()
    monkeypatch.setattr(stage, "segment_chunk", real)
    resumed = stage.run(config(checkpoint), root, ws, workers=1, show_progress=False).items[0]
    total = len(key_frame_images(root))
    assert resumed.report["segmented"] == total - 32 and resumed.report["reused"] == 32
    manifest = ws.masks_manifest("predicted")
    stamp = os.stat(manifest).st_mtime_ns
    again = stage.run(config(checkpoint), root, ws, workers=1, show_progress=False).items[0]
    assert again.skipped and os.stat(manifest).st_mtime_ns == stamp
    redone = stage.run(config(checkpoint), root, ws, workers=1, overwrite=True, show_progress=False).items[0]
    assert redone.report["segmented"] == total


def test_segment_command_and_its_bad_input(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path
) -> None:
    root = str(tiny_site.result.dataset_root)
    ws = str(tmp_path / "ws")
    args = ["segment", root, "--workspace", ws, "--checkpoint", str(checkpoint), "--device", "cpu"]
    result = CliRunner().invoke(app, [*args, "--workers", "2", "--batch-size", "32"])
    assert result.exit_code == EXIT_OK, result.output
    assert "predicted masks" in result.output
    rerun = CliRunner().invoke(app, args)
    assert rerun.exit_code == EXIT_OK and "up to date" in rerun.output, rerun.output
    bad = CliRunner().invoke(app, ["segment", root, "--workspace", ws, "--checkpoint", str(tmp_path)])
    assert bad.exit_code == 2 and str(tmp_path / "checkpoint.json") in bad.output, bad.output
    with pytest.raises(CheckpointError):
        stage.run(SegmentConfig(checkpoint=tmp_path), Path(root), Path(ws), show_progress=False)


def test_every_mask_of_a_camera_gets_its_one_ego_body(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path
) -> None:
    root = tiny_site.result.dataset_root
    ws = Workspace(tmp_path / "ws")
    item = stage.run(config(checkpoint), root, ws, workers=1, show_progress=False).items[0]
    dataset = load_dataset(root)  # the generator's own masks, for the truth
    bodies: dict[str, np.ndarray] = {}
    true_ego = predicted_ego = both = 0
    for image in dataset.camera_images():
        if not image.is_key_frame:
            continue
        name = image.path.relative_to(dataset.root).as_posix()
        ego = read_png(ws.masks_dir("predicted") / mask_relpath(SEMANTIC_DIR, name)) == int(Semantic.EGO)
        body = bodies.setdefault(image.calibration.token, ego)
        assert (ego == body).all(), f"{name}: its ego pixels differ from its camera's other masks"
        if image.channel == "CAM_BACK":
            truth = image.load_semantic() == int(Semantic.EGO)
            true_ego, predicted_ego, both = (
                true_ego + truth.sum(),
                predicted_ego + ego.sum(),
                both + (ego & truth).sum(),
            )
    assert true_ego > 0 and both / (true_ego + predicted_ego - both) > 0.9  # the trunk, from the clips
    assert item.report["ego_body_pixels"]["CAM_BACK"] > 0
    off = replace(config(checkpoint), ego_clip=EgoClipConfig(enabled=False))
    plain = stage.run(off, root, ws, workers=1, show_progress=False).items[0]
    assert not plain.skipped and plain.report["ego_body_pixels"] is None  # another ego setting: made again


def test_a_mask_of_another_size_in_a_camera_is_named(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = tiny_site.result.dataset_root
    ws = Workspace(tmp_path / "ws")
    real = stage.segment_chunk

    def one_shrunk(chunk: stage.Chunk) -> tuple[str, ...]:
        written = real(chunk)
        if chunk.filenames[0] == first:  # the first mask comes out at half size
            path = ws.masks_dir("predicted") / mask_relpath(SEMANTIC_DIR, first)
            cv2.imwrite(str(path), read_png(path)[::2, ::2])
        return written

    first = key_frame_images(root)[0]
    monkeypatch.setattr(stage, "segment_chunk", one_shrunk)
    with pytest.raises(DatasetError, match=r"shape \(72, 128\) for a 256x144 CAM_\w+ image") as error:
        stage.run(config(checkpoint), root, ws, workers=1, show_progress=False)
    assert Path(first).stem in str(error.value)
    assert not ws.masks_manifest("predicted").exists()


def test_mirror_averaging_is_a_setting_of_the_masks(
    tiny_site: GeneratedSite, checkpoint: Path, tmp_path: Path
) -> None:
    """Masks made with and without mirror averaging are not each other's: switching the setting makes them again,
    and the masks' manifest says which made them."""
    root = tiny_site.result.dataset_root
    ws = Workspace(tmp_path / "ws")
    made_with = set()
    for flip in (False, True, False):
        item = stage.run(
            replace(config(checkpoint), flip_average=flip), root, ws, workers=1, show_progress=False
        )
        assert not item.items[0].skipped, flip
        made_by = read_mask_manifest(ws.masks_manifest("predicted")).made_by
        assert made_by["flip_average"] is flip
        made_with.add(made_by["made_with"])
    assert len(made_with) == 2
