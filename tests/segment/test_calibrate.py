"""Calibrating a segmenter: offsets that undo a biased class, folded into the classifier, and the sites it may
(and may not) be calibrated on."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from cama_pipeline.segment.calibrate import (
    CalibrationConfig,
    PixelLogits,
    calibrate,
    calibrated_network,
    confusion_of,
    fit_logit_offsets,
    mean_iou,
)
from cama_pipeline.segment.checkpoint import META, ensure_unseen, load_checkpoint
from cama_pipeline.segment.network import NUM_CLASSES
from cama_pipeline.site_identity import SeenSiteError
from cama_studio.cli import app
from tests.conftest import GeneratedSite
from tests.segment.segmenter_fixture import relabelled_copy, train_small

LANE = 3


def biased_pixels(bias: float, rng: np.random.Generator) -> PixelLogits:
    """Pixels of two classes (road 0.8, lane marking 0.2) whose logits score the true class 2 higher, with
    noise, and the lane-marking logit pushed up by `bias` everywhere (as a class-weighted loss does)."""
    truth = np.where(rng.random(20000) < 0.2, LANE, 1)
    logits = rng.normal(0.0, 1.0, (truth.size, NUM_CLASSES)) - 4.0
    logits[:, 1] += 4.0 + 2.0 * (truth == 1)
    logits[:, LANE] += 4.0 + 2.0 * (truth == LANE) + bias
    return PixelLogits(torch.as_tensor(logits, dtype=torch.float32), torch.as_tensor(truth))


def test_offsets_undo_a_class_pushed_up_and_never_make_iou_worse() -> None:
    rng = np.random.default_rng(0)
    pixels = biased_pixels(1.5, rng)
    before = mean_iou(confusion_of(pixels, np.zeros(NUM_CLASSES)))
    offsets = fit_logit_offsets(pixels, CalibrationConfig(), show_progress=False)
    after = mean_iou(confusion_of(pixels, offsets))
    sweep = []  # the best a single lane-marking offset can do, found by brute force
    for value in np.arange(-3.0, 3.01, 0.05):
        trial = np.zeros(NUM_CLASSES)
        trial[LANE] = value
        sweep.append(mean_iou(confusion_of(pixels, trial)))
    assert after > before + 0.05 and after >= max(sweep) - 0.005
    assert -2.5 < offsets[LANE] - offsets[1] < -1.0  # pulled back by about the push
    unbiased = biased_pixels(0.0, rng)
    kept = fit_logit_offsets(unbiased, CalibrationConfig(), show_progress=False)
    assert mean_iou(confusion_of(unbiased, kept)) >= mean_iou(confusion_of(unbiased, np.zeros(NUM_CLASSES)))
    assert abs(kept[LANE] - kept[1]) < 0.8


@pytest.fixture(scope="module")
def trained_on(tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return relabelled_copy(tiny_site.result.out_dir, tmp_path_factory.mktemp("calibrate") / "trained")


@pytest.fixture(scope="module")
def parent(trained_on: Path) -> Path:
    return train_small(trained_on, trained_on.parent / "ckpt")


def test_the_classifier_bias_carries_the_offsets(parent: Path) -> None:
    net = load_checkpoint(parent).net
    offsets = np.linspace(-1.0, 1.0, NUM_CLASSES)
    x = torch.rand(1, 3, 64, 96)
    shifted = calibrated_network(net, offsets)(x) - net(x)
    assert torch.allclose(shifted, torch.as_tensor(offsets, dtype=torch.float32).view(1, -1, 1, 1), atol=1e-4)


def test_calibration_records_its_sites_as_seen_and_refuses_seen_and_measurement_sites(
    tiny_site: GeneratedSite, trained_on: Path, parent: Path, tmp_path: Path
) -> None:
    fresh = relabelled_copy(tiny_site.result.out_dir, tmp_path / "fresh", seed=6161, lane_width_shift_m=0.75)
    config = CalibrationConfig(step=0.5, span=1.0, passes=1, pixel_stride=4)
    folder = calibrate(
        [fresh], tmp_path / "calibrated", checkpoint=parent, config=config, show_progress=False
    )
    meta = json.loads((folder / META).read_text(encoding="utf-8"))
    record = meta["calibration"]
    assert [s["seed"] for s in meta["training_sites"]] == [4242, 6161]
    assert set(record["offsets"]) == {
        "background",
        "road",
        "curb",
        "lane_marking",
        "crosswalk",
        "vehicle",
        "static_object",
        "sky",
        "ego",
    }
    assert record["after"]["mean_iou"] >= record["before"]["mean_iou"]
    assert record["parent"]["weights_sha256"] != meta["weights_sha256"]
    calibrated = load_checkpoint(folder)
    for seen in (trained_on, fresh):
        with pytest.raises(SeenSiteError):
            ensure_unseen(calibrated, seen)
    with pytest.raises(SeenSiteError, match="seed 4242"):  # its logits on a site it trained on flatter it
        calibrate([trained_on], tmp_path / "again", checkpoint=parent, config=config, show_progress=False)
    with pytest.raises(SeenSiteError, match="measurement site"):
        calibrate(
            [tiny_site.result.out_dir],
            tmp_path / "again",
            checkpoint=parent,
            config=config,
            show_progress=False,
        )
    assert not (tmp_path / "again").exists()


def test_calibrate_segmenter_command_names_a_missing_site(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app, ["calibrate-segmenter", "--sites", str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")]
    )
    assert result.exit_code == 2 and "nowhere" in result.output
    assert not (tmp_path / "out").exists()


def test_only_the_chosen_classes_are_fitted() -> None:
    rng = np.random.default_rng(1)
    pixels = biased_pixels(1.5, rng)
    only_lane = CalibrationConfig(classes=("lane_marking",))
    offsets = fit_logit_offsets(pixels, only_lane, show_progress=False)
    others = np.delete(offsets, LANE)
    assert (others == 0).all() and -2.5 < offsets[LANE] < -1.0
    only_road = fit_logit_offsets(pixels, CalibrationConfig(classes=("road",)), show_progress=False)
    assert only_road[LANE] == 0 and only_road[1] > 0.5  # road pushed up instead, as far as helps


def test_calibrate_segmenter_command_names_an_unknown_class(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app,
        [
            "calibrate-segmenter",
            "--sites",
            str(tmp_path),
            "--out",
            str(tmp_path / "out"),
            "--classes",
            "curb,kerb",
        ],
    )
    assert result.exit_code == 2 and "unknown class 'kerb'" in result.output, result.output
    assert not (tmp_path / "out").exists()
