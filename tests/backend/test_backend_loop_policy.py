"""The loop's policy adapter (pre-accept threshold, retrain trigger, QA sample) and its settings."""

import json
from pathlib import Path

import pytest

from app.backend.config import Settings
from app.backend.vma_loop import preaccept_threshold, qa_sample, should_retrain
from models.vma.loop import THRESHOLD_KEY
from tests.backend.vma_loop_site import write_registry


def test_qa_sample_is_reproducible_and_sized_by_share() -> None:
    ids = list(range(100, 140))
    sample = qa_sample(ids, 0.25, seed=3)
    assert len(sample) == 10 and sample <= set(ids) and sample == qa_sample(reversed(ids), 0.25, seed=3)
    assert qa_sample(ids, 0.25, seed=4) != sample
    assert qa_sample(ids, 0.0, seed=3) == set() and qa_sample([], 0.5, seed=3) == set()
    assert len(qa_sample([7], 0.01, seed=0)) == 1  # a positive share never samples nothing
    assert qa_sample(ids, 1.0, seed=0) == set(ids)


def test_should_retrain() -> None:
    assert should_retrain(5, 5) and should_retrain(6, 5)
    assert not should_retrain(4, 5) and not should_retrain(100, 0)


def test_preaccept_threshold_comes_from_the_promoted_checkpoint(tmp_path: Path) -> None:
    registry = write_registry(tmp_path / "registry")
    assert preaccept_threshold(registry) is None  # not calibrated: nothing is pre-accepted
    meta_path = registry / "v0001" / "checkpoint.json"
    meta = json.loads(meta_path.read_text())
    meta_path.write_text(json.dumps({**meta, THRESHOLD_KEY: 0.83}))
    assert preaccept_threshold(registry) == pytest.approx(0.83)
    assert preaccept_threshold(tmp_path / "missing") is None


def test_loop_settings_from_the_environment(tmp_path: Path) -> None:
    env = {
        "CAMA_VMA_REGISTRY": str(tmp_path / "reg"),
        "CAMA_VMA_VALIDATION_SITES": f"{tmp_path / 'a'}:{tmp_path / 'b'}",
        "CAMA_RETRAIN_AFTER": "25",
        "CAMA_QA_SHARE": "0.2",
        "CAMA_PREACCEPT_THRESHOLD": "0.9",
        "CAMA_RETRAIN_STALL_S": "120",
    }
    settings = Settings.from_env(env)
    assert settings.vma_registry == tmp_path / "reg" and settings.retrain_after == 25
    assert settings.vma_validation_sites == (tmp_path / "a", tmp_path / "b")
    assert settings.qa_share == 0.2 and settings.preaccept_threshold == 0.9
    assert settings.retrain_stall_s == 120.0 and Settings().retrain_stall_s == 900.0
    for key, value, message in (
        ("CAMA_QA_SHARE", "1.5", "CAMA_QA_SHARE: must be in [0, 1]"),
        ("CAMA_RETRAIN_AFTER", "-1", "CAMA_RETRAIN_AFTER: must be >= 0"),
        ("CAMA_PREACCEPT_THRESHOLD", "2", "CAMA_PREACCEPT_THRESHOLD: must be in [0, 1]"),
        ("CAMA_RETRAIN_AFTER", "many", "CAMA_RETRAIN_AFTER: invalid value"),
        ("CAMA_RETRAIN_STALL_S", "-5", "CAMA_RETRAIN_STALL_S: must be >= 0 seconds"),
    ):
        with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
            Settings.from_env({key: value})
