"""The loop policy: pre-accept threshold calibration and storage, when to retrain, the QA sample."""

from pathlib import Path

import pytest

from models.vma.checkpoint import promote, save_version
from models.vma.config import ModelConfig
from models.vma.loop import (
    THRESHOLD_KEY,
    LoopConfig,
    calibrate_preaccept_threshold,
    preaccept_threshold,
    qa_sample,
    should_retrain,
)
from models.vma.model import VmaNet

STRICT = LoopConfig(preaccept_precision=0.9, min_preaccepted=2)


def test_threshold_is_the_lowest_confidence_reaching_the_precision() -> None:
    confidences = [0.95, 0.9, 0.85, 0.8, 0.7, 0.6, 0.5, 0.3]
    correct = [True, True, True, True, True, False, True, False]
    # down to 0.7 all 5 right; at 0.6 5/6 < 0.9; at 0.5 6/7 < 0.9
    assert calibrate_preaccept_threshold(confidences, correct, STRICT) == pytest.approx(0.7)
    assert calibrate_preaccept_threshold(confidences, [True] * 8, STRICT) == pytest.approx(0.3)


def test_threshold_none_when_unreachable_or_too_few() -> None:
    assert calibrate_preaccept_threshold([0.9, 0.8], [False, True], STRICT) is None
    assert calibrate_preaccept_threshold([0.9], [True], STRICT) is None  # one proposal is not evidence
    assert calibrate_preaccept_threshold([], [], STRICT) is None


def test_ties_are_never_split() -> None:
    # the two 0.8 proposals go in together: 2 of 3 right is below the target, so only 0.9 qualifies
    assert calibrate_preaccept_threshold([0.9, 0.9, 0.8, 0.8], [True, True, True, False], STRICT) == 0.9


def test_calibration_rejects_mismatched_inputs() -> None:
    with pytest.raises(ValueError, match="must be equal"):
        calibrate_preaccept_threshold([0.5, 0.6], [True], STRICT)


def test_threshold_is_read_from_the_promoted_checkpoint(tmp_path: Path) -> None:
    model = VmaNet(ModelConfig(patch_px=32, num_queries=2, num_points=3, dim=16, decoder_layers=1, heads=2))
    first = save_version(tmp_path, model, {THRESHOLD_KEY: 0.8})
    second = save_version(tmp_path, model, {THRESHOLD_KEY: None})
    promote(tmp_path, first.name)
    assert preaccept_threshold(tmp_path) == pytest.approx(0.8)
    promote(tmp_path, second.name)
    assert preaccept_threshold(tmp_path) is None
    assert preaccept_threshold(tmp_path / "missing") is None


def test_retrain_after_enough_corrections() -> None:
    config = LoopConfig(retrain_after_corrections=200)
    assert not should_retrain(199, config) and should_retrain(200, config)
    assert not should_retrain(10_000, LoopConfig(retrain_after_corrections=0))


def test_qa_sample_is_a_reproducible_share() -> None:
    ids = set(range(100, 150))
    sample = qa_sample(ids, 0.1, seed=3)
    assert len(sample) == 5 and sample <= ids and sample == qa_sample(ids, 0.1, seed=3)
    assert len(qa_sample({7}, 0.1, seed=0)) == 1
    assert qa_sample(ids, 0.0, seed=0) == set() and qa_sample(set(), 0.5, seed=0) == set()
    with pytest.raises(ValueError, match="share"):
        qa_sample(ids, 1.5, seed=0)


def test_loop_config_is_validated() -> None:
    with pytest.raises(ValueError, match="preaccept_precision"):
        LoopConfig(preaccept_precision=0.0)
    with pytest.raises(ValueError, match="qa_sample_share"):
        LoopConfig(qa_sample_share=2.0)
