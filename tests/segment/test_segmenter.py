"""The segmentation network, its checkpoints and training: shapes, a round trip, refusals to train on a
measurement site and to be scored on a site it saw."""

import dataclasses
import hashlib
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from cama_pipeline.console import EXIT_BAD_INPUT
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR
from cama_pipeline.segment.checkpoint import (
    META,
    WEIGHTS,
    CheckpointError,
    ensure_unseen,
    load_checkpoint,
    shipped_checkpoint,
)
from cama_pipeline.segment.config import NetworkConfig, SegmentConfig, TrainConfig
from cama_pipeline.segment.network import NUM_CLASSES, SegmentationNet, parameter_count
from cama_pipeline.segment.predict import score_site, site_images
from cama_pipeline.segment.train import (
    PROBE_STEPS,
    augment,
    check_training_sites,
    initial_network,
    load_training_set,
    resize_labels,
    train,
)
from cama_pipeline.site_identity import SeenSiteError, site_identity
from cama_studio.cli import app
from tests.conftest import GeneratedSite
from tests.segment.segmenter_fixture import FEW_STEPS, SMALL_NETWORK, relabelled_copy, train_small


@pytest.fixture(scope="module")
def training_site(tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return relabelled_copy(tiny_site.result.out_dir, tmp_path_factory.mktemp("train") / "site")


@pytest.fixture(scope="module")
def checkpoint(training_site: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train_small(training_site, tmp_path_factory.mktemp("ckpt") / "segmenter")


def test_network_gives_logits_at_the_input_size_and_masks_at_the_image_size() -> None:
    net = SegmentationNet(NetworkConfig()).eval()
    assert parameter_count(net) < 1_000_000  # under 2 MB in float16
    with torch.no_grad():
        assert net(torch.rand(2, 3, 64, 96)).shape == (2, NUM_CLASSES, 64, 96)
    images = [
        np.zeros((144, 256, 3), np.uint8),
        np.zeros((90, 160, 3), np.uint8),
        np.zeros((144, 256, 3), np.uint8),
    ]
    masks = net.predict(images)
    assert [m.shape for m in masks] == [(144, 256), (90, 160), (144, 256)]
    assert all(m.dtype == np.uint8 and m.max() < NUM_CLASSES for m in masks)
    with pytest.raises(ValueError, match="uint8 RGB"):
        net.predict([np.zeros((10, 10), np.uint8)])


def test_mirror_averaged_masks_mirror_with_the_image(tiny_site: GeneratedSite) -> None:
    """With `flip_average` the masks of a mirrored image are the mirrored masks, to the pixel (the two views'
    probabilities are summed either way); the shipped network's plain masks are not, and differ from them."""
    net = load_checkpoint(shipped_checkpoint()).net.eval()
    image = site_images(tiny_site.result.out_dir)[0].load_rgb()
    mirrored = np.ascontiguousarray(image[:, ::-1])
    averaged, of_mirror = net.predict([image, mirrored], flip_average=True)
    assert np.array_equal(of_mirror, averaged[:, ::-1])
    plain, plain_of_mirror = net.predict([image, mirrored])
    assert not np.array_equal(plain_of_mirror, plain[:, ::-1])
    assert not np.array_equal(plain, averaged)


def test_the_inference_copy_labels_as_the_trained_network_and_leaves_it_trainable(
    tiny_site: GeneratedSite,
) -> None:
    """The stage's copy has no batch norm left and gives the trained network's logits up to float rounding and
    its labels on a site's images; the network it was copied from keeps its norms and still trains."""
    net = load_checkpoint(shipped_checkpoint()).net.eval()
    runner = net.for_inference()
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in runner.modules())
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules()) > 10
    rgb = torch.rand(1, 3, 64, 96)
    with torch.inference_mode():
        assert torch.allclose(runner(rgb), net(rgb), atol=1e-3)
    images = [im.load_rgb() for im in site_images(tiny_site.result.out_dir)[:6]]
    for ours, theirs in zip(runner.predict(images), net.predict(images), strict=True):
        assert np.mean(ours == theirs) > 0.9999
    net.train()
    loss = net(torch.rand(2, 3, 64, 96)).logsumexp(dim=1).mean()
    loss.backward()
    assert all(p.grad is not None for p in net.parameters())


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: NetworkConfig(widths=(8, 8)), "widths"),
        (lambda: NetworkConfig(input_width_px=500), "input_width_px"),
        (lambda: NetworkConfig(full_resolution_width=-1), "full_resolution_width"),
        (lambda: TrainConfig(epochs=0), "epochs"),
        (lambda: TrainConfig(crop_width_px=100), "crop_height_px and crop_width_px"),
        (lambda: TrainConfig(loader_workers=-1), "loader_workers"),
        (lambda: TrainConfig(time_budget_s=0.0), "time_budget_s"),
        (lambda: SegmentConfig(device="tpu"), "device"),  # type: ignore[arg-type]
        (lambda: SegmentConfig(batch_size=0), "batch_size"),
        (lambda: SegmentConfig(flip_average="yes"), "flip_average"),  # type: ignore[arg-type]
    ],
)
def test_configs_name_the_bad_field(make: object, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        make()  # type: ignore[operator]


def test_checkpoint_round_trip_records_what_it_saw(checkpoint: Path, training_site: Path) -> None:
    loaded = load_checkpoint(checkpoint)
    meta = json.loads((checkpoint / META).read_text(encoding="utf-8"))
    assert meta["weights_sha256"] == hashlib.sha256((checkpoint / WEIGHTS).read_bytes()).hexdigest()
    assert loaded.digest == meta["weights_sha256"][:16]
    assert meta["network"] == SMALL_NETWORK.to_json() and meta["train"] == FEW_STEPS.to_json()
    assert [s["seed"] for s in meta["training_sites"]] == [4242]
    assert meta["training_sites"][0]["location"] == "test-copy-4242"
    assert meta["metrics"]["cpu_seconds_per_512x288"] > 0 and len(meta["metrics"]["loss"]) == 1
    image = np.random.default_rng(1).integers(0, 256, (144, 256, 3), dtype=np.uint8)
    again = load_checkpoint(checkpoint)
    assert np.array_equal(loaded.net.predict([image])[0], again.net.predict([image])[0])
    state = torch.load(checkpoint / WEIGHTS, weights_only=True)
    assert all(v.dtype == torch.float16 for v in state.values() if v.is_floating_point())


def test_a_checkpoint_refuses_to_be_scored_on_a_site_it_saw(
    checkpoint: Path, training_site: Path, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    loaded = load_checkpoint(checkpoint)
    with pytest.raises(SeenSiteError, match=str(training_site)):
        ensure_unseen(loaded, training_site)
    with pytest.raises(SeenSiteError, match="seed 4242"):
        score_site(loaded, training_site, "cpu")
    same_place = relabelled_copy(tiny_site.result.out_dir, tmp_path / "other-seed", seed=77)
    manifest = json.loads((same_place / "manifest.json").read_text(encoding="utf-8"))
    manifest["config"]["location"] = "test-copy-4242"  # another seed and layout, but the same location
    manifest["config"]["layout"]["lane_width_m"] += 0.5
    (same_place / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    with pytest.raises(SeenSiteError, match="location"):
        ensure_unseen(loaded, same_place)
    assert ensure_unseen(loaded, tiny_site.result.out_dir).seed == tiny_site.config.seed


def test_training_refuses_measurement_sites_and_held_out_places(
    tiny_site: GeneratedSite, training_site: Path, tmp_path: Path
) -> None:
    with pytest.raises(SeenSiteError, match="measurement site"):
        check_training_sites([tiny_site.result.out_dir], [])  # the tiny preset at its default seed
    with pytest.raises(SeenSiteError, match="measurement site"):
        check_training_sites([relabelled_copy(tiny_site.result.out_dir, tmp_path / "m", seed=9000)], [])
    with pytest.raises(SeenSiteError, match="held-out"):
        check_training_sites([training_site], [training_site])
    assert [i.seed for i in check_training_sites([training_site], [tiny_site.result.out_dir])] == [4242]
    with pytest.raises(SeenSiteError):
        train(FEW_STEPS, [tiny_site.result.out_dir], tmp_path / "never", network=SMALL_NETWORK)
    assert not (tmp_path / "never").exists()


def test_train_segmenter_command_names_the_measurement_site(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    site = tiny_site.result.out_dir
    result = CliRunner().invoke(app, ["train-segmenter", "--sites", str(site), "--out", str(tmp_path / "c")])
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "measurement site" in result.output and str(site) in result.output


def test_bad_checkpoints_name_their_file(checkpoint: Path, tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match=str(tmp_path / "none" / META)):
        load_checkpoint(tmp_path / "none")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / META).write_text("{ not json", encoding="utf-8")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        load_checkpoint(broken)
    (broken / META).write_text((checkpoint / META).read_text(encoding="utf-8"), encoding="utf-8")
    (broken / WEIGHTS).write_bytes(b"not weights")
    with pytest.raises(CheckpointError, match=str(broken / WEIGHTS)):
        load_checkpoint(broken)
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        site_identity(tmp_path)
    (tmp_path / "manifest.json").write_text('{"preset": "tiny"}', encoding="utf-8")
    with pytest.raises(ValueError, match="not a generator manifest"):
        site_identity(tmp_path)


def test_going_on_from_a_checkpoint_keeps_what_it_saw(
    checkpoint: Path, training_site: Path, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    second_site = relabelled_copy(
        tiny_site.result.out_dir, tmp_path / "second", seed=5151, lane_width_shift_m=0.75
    )
    folder = train(FEW_STEPS, [second_site], tmp_path / "next", init=checkpoint, show_progress=False)
    meta = json.loads((folder / META).read_text(encoding="utf-8"))
    assert [s["seed"] for s in meta["training_sites"]] == [4242, 5151]
    parent = load_checkpoint(checkpoint)
    assert meta["epochs_total"] == 2 and meta["parent"]["weights_sha256"] == parent.meta["weights_sha256"]
    with pytest.raises(SeenSiteError, match="seed 4242"):  # the parent's site stays seen
        ensure_unseen(load_checkpoint(folder), training_site)
    moved = shutil.copytree(training_site, tmp_path / "regenerated-elsewhere")
    again = train(FEW_STEPS, [moved], tmp_path / "again", init=folder, show_progress=False)
    sites = json.loads((again / META).read_text(encoding="utf-8"))["training_sites"]
    assert [(s["seed"], s["path"]) for s in sites] == [(5151, str(second_site)), (4242, str(moved))]


def _fit_stripes(net: SegmentationNet, steps: int = 120) -> float:
    """Pixel accuracy of `net` after fitting one image of alternating one-pixel rows (road, lane marking)."""
    torch.manual_seed(0)
    image = torch.zeros(1, 3, 32, 64)
    image[..., 1::2, :] = 1.0
    target = torch.ones(1, 32, 64, dtype=torch.long)
    target[:, 1::2, :] = 3
    optimiser = torch.optim.Adam(net.parameters(), lr=1e-2)
    net.train()
    for _ in range(steps):
        loss = torch.nn.functional.cross_entropy(net(image), target)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        return float((net.eval()(image).argmax(dim=1) == target).float().mean())


def test_the_full_resolution_refinement_draws_what_stride_2_logits_cannot() -> None:
    """Rows alternating between two classes: upsampled stride-2 logits cannot alternate in sign from one pixel to
    the next over a whole image, the refinement's per-pixel correction can."""
    config = NetworkConfig(widths=(8, 8, 16, 16, 16), input_width_px=64, full_resolution_width=4)
    torch.manual_seed(0)
    plain = SegmentationNet(dataclasses.replace(config, full_resolution_width=0))
    refined = SegmentationNet(config)
    assert plain.refine is None and refined.refine is not None
    assert _fit_stripes(plain) < 0.8
    assert _fit_stripes(refined) > 0.99


def test_a_checkpoint_goes_on_with_a_refinement_from_the_same_output(
    training_site: Path, tmp_path: Path
) -> None:
    plain = dataclasses.replace(SMALL_NETWORK, full_resolution_width=0)
    folder = train(FEW_STEPS, [training_site], tmp_path / "plain", network=plain, show_progress=False)
    meta = json.loads((folder / META).read_text(encoding="utf-8"))
    del meta["network"]["full_resolution_width"]  # as written before the refinement existed
    (folder / META).write_text(json.dumps(meta), encoding="utf-8")
    parent = load_checkpoint(folder)
    assert parent.net.config == plain and parent.net.refine is None
    refined = dataclasses.replace(SMALL_NETWORK, full_resolution_width=6)
    net, loaded = initial_network(refined, folder)
    image = torch.rand(2, 3, 64, 96)
    with torch.no_grad():
        assert torch.equal(net.eval()(image), parent.net.eval()(image))
    assert loaded is not None and loaded.digest == parent.digest and net.config == refined
    with pytest.raises(CheckpointError, match="not the one asked for"):
        initial_network(dataclasses.replace(refined, input_width_px=128), folder)
    result = CliRunner().invoke(
        app,
        [
            "train-segmenter",
            "--sites",
            str(training_site),
            "--out",
            str(tmp_path / "next"),
            "--init",
            str(folder),
            "--full-resolution-width",
            "6",
            "--epochs",
            "1",
            "--batch-size",
            "2",
            "--max-class-weight",
            "0",
        ],
    )
    assert result.exit_code == EXIT_BAD_INPUT and "max_class_weight" in result.output, result.output


def test_a_mask_free_site_is_scored_on_its_ground_truth(training_site: Path, tmp_path: Path) -> None:
    """`cama synth --no-masks` keeps the masks in ground_truth/: held-out scores and training read them there;
    a site with masks in neither place is named."""
    with_masks = site_images(training_site)
    bare = shutil.copytree(training_site, tmp_path / "bare")
    for folder in (SEMANTIC_DIR, INSTANCE_DIR):
        shutil.move(bare / "nuscenes" / folder, bare / "ground_truth" / folder)
    moved = site_images(bare)
    assert [im.token for im in moved] == [im.token for im in with_masks]
    assert all(str(bare / "ground_truth") in str(im.semantic_mask_path) for im in moved)
    shutil.rmtree(bare / "ground_truth" / SEMANTIC_DIR)
    with pytest.raises(ValueError, match=f"{bare}: no camera image with a semantic mask"):
        site_images(bare)


def test_unit_scale_crops_masks_without_resampling_them() -> None:
    """`--scale-range 1 1`: each training mask is an exact crop (maybe mirrored) of the site's own, so a thin
    class's edge is not moved by the nearest-neighbour resampling of a rescale."""
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (64, 96, 3), dtype=np.uint8)
    mask = rng.integers(0, NUM_CLASSES, (64, 96), dtype=np.uint8)
    config = TrainConfig(crop_height_px=32, crop_width_px=64, scale_range=(1.0, 1.0))
    for _ in range(6):
        _, crop = augment(image, mask, config, rng)
        windows = np.lib.stride_tricks.sliding_window_view(mask, crop.shape)
        assert (windows == crop).all(axis=(2, 3)).any() or (windows == crop[:, ::-1]).all(axis=(2, 3)).any()
    _, rescaled = augment(image, mask, dataclasses.replace(config, scale_range=(1.3, 1.3)), rng)
    windows = np.lib.stride_tricks.sliding_window_view(mask, rescaled.shape)
    assert not (windows == rescaled).all(axis=(2, 3)).any()


def test_resized_labels_follow_the_interpolated_image() -> None:
    """A rescaled mask's edge lies where the interpolated image crosses half way between the two sides, for any
    step position, where nearest neighbour moves it by up to half a pixel."""
    nearest_misses = 0
    for step in range(13, 22):
        image = np.zeros((20, 40, 3), np.uint8)
        mask = np.zeros((20, 40), np.uint8)
        image[:, step:], mask[:, step:] = 200, 3
        for size in ((52, 26), (29, 14)):
            interpolation = cv2.INTER_LINEAR if size[0] > 40 else cv2.INTER_AREA
            bright = cv2.resize(image, size, interpolation=interpolation)[..., 0] > 100
            assert ((resize_labels(mask, size, interpolation) == 3) == bright).all(), (step, size)
            nearest = cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST) == 3
            nearest_misses += int((nearest != bright).any())
    assert nearest_misses > 0


def test_resized_labels_take_the_majority_class() -> None:
    """Halving a mask whose 2x2 blocks hold three pixels of one class and one of another keeps the three, where
    nearest neighbour would keep the top-left one; a one-class mask stays that class."""
    mask = np.full((8, 12), int(NUM_CLASSES - 1), np.uint8)
    mask[::2, ::2] = 2
    halved = resize_labels(mask, (6, 4), cv2.INTER_AREA)
    assert (halved == NUM_CLASSES - 1).all()
    assert (cv2.resize(mask, (6, 4), interpolation=cv2.INTER_NEAREST) == 2).all()
    assert (resize_labels(np.full((8, 12), 4, np.uint8), (5, 3), cv2.INTER_AREA) == 4).all()


def test_training_images_narrower_than_the_site_keep_each_class_area(training_site: Path) -> None:
    """A site wider than the network's input is loaded with its masks resized like its images: every class keeps
    its share of the pixels."""
    full = load_training_set([training_site], 256)
    half = load_training_set([training_site], 128)
    assert half.masks[0].shape == (72, 128) and half.images[0].shape == (72, 128, 3)
    for cls in range(NUM_CLASSES):
        before = np.mean([(m == cls).mean() for m in full.masks])
        after = np.mean([(m == cls).mean() for m in half.masks])
        assert abs(after - before) <= 0.2 * before + 1e-3, cls


def test_train_segmenter_names_a_bad_scale_range(training_site: Path, tmp_path: Path) -> None:
    args = ["train-segmenter", "--sites", str(training_site), "--out", str(tmp_path / "c"), "--scale-range"]
    result = CliRunner().invoke(app, [*args, "1.3", "0.7"])
    assert result.exit_code == EXIT_BAD_INPUT and "scale_range" in result.output, result.output
    assert not (tmp_path / "c").exists()


def test_loader_workers_repeat_a_run_and_differ_from_the_loops_own_crops(
    training_site: Path, tmp_path: Path
) -> None:
    """Crops made by loader processes (what keeps a GPU fed) train the same weights twice for a seed and worker
    count; they are drawn per worker, so they are not the crops the training loop makes itself."""
    in_workers = dataclasses.replace(FEW_STEPS, loader_workers=2)
    digests = [
        json.loads(
            (
                train(c, [training_site], tmp_path / name, network=SMALL_NETWORK, show_progress=False) / META
            ).read_text(encoding="utf-8")
        )["weights_sha256"]
        for c, name in ((in_workers, "a"), (in_workers, "b"), (FEW_STEPS, "loop"))
    ]
    assert digests[0] == digests[1] != digests[2]


def test_a_time_budget_fills_its_seconds_and_records_the_passes(training_site: Path, tmp_path: Path) -> None:
    """With `time_budget_s` the run measures its speed and trains for about the budget, not for `epochs`
    passes; the checkpoint records the steps and the (fractional) passes it made."""
    config = dataclasses.replace(FEW_STEPS, epochs=1, time_budget_s=4.0)
    folder = train(config, [training_site], tmp_path / "budget", network=SMALL_NETWORK, show_progress=False)
    meta = json.loads((folder / META).read_text(encoding="utf-8"))
    steps_per_pass = FEW_STEPS.images_per_epoch // FEW_STEPS.batch_size  # type: ignore[operator]
    assert meta["metrics"]["steps"] > PROBE_STEPS > steps_per_pass
    assert meta["epochs"] == round(meta["metrics"]["steps"] / steps_per_pass, 2)
    assert len(meta["metrics"]["loss"]) == -(-meta["metrics"]["steps"] // steps_per_pass)
    assert meta["device"] == "cpu" and meta["metrics"]["crops_per_second"] > 0
    # about the budget, not the one pass `epochs` asks for (the steps above say so exactly); the run plans its
    # steps at the probe's speed, so with the machine's load changing after the probe it ends early or late
    assert 2.0 < meta["seconds"] < 120.0


@pytest.mark.parametrize(
    ("option", "field"),
    [
        (["--time-budget", "0"], "time_budget_s"),
        (["--crop", "100", "64"], "crop_height_px and crop_width_px"),
        (["--loader-workers", "-1"], "loader-workers"),
    ],
)
def test_train_segmenter_names_a_bad_gpu_option(
    training_site: Path, tmp_path: Path, option: list[str], field: str
) -> None:
    args = ["train-segmenter", "--sites", str(training_site), "--out", str(tmp_path / "c"), *option]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == EXIT_BAD_INPUT and field in result.output, result.output
    assert not (tmp_path / "c").exists()
