"""`bench/boundary_evidence.py` scores each proposed boundary against the true boundary it lies along; it,
`bench/boundary_offset.py`, `bench/annotator_split.py` and `bench/annotator_seconds.py` refuse a checkpoint on a site it saw."""

import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from app.review_effort.plan import Polyline, SimulationConfig
from bench import annotator_seconds, annotator_split, boundary_evidence, boundary_offset, vma_measures
from bench.boundary_evidence import boundary_errors
from cama_pipeline.site_identity import SeenSiteError
from models.vma.vectors import Vector


def line(y: float, x0: float = 0.0, x1: float = 30.0) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x1, 31), np.full(31, y)])


def test_each_boundary_is_scored_against_the_truth_it_lies_along() -> None:
    truths = [
        Polyline("boundary", line(0.0)),
        Polyline("boundary", line(20.0)),
        Polyline("divider", line(10.0)),
    ]
    hooked = line(20.3)
    hooked[-1] = [30.0, 19.2]  # 0.3 m on the road side, and its end bent 0.8 m into the road
    proposals = [
        Vector("boundary", line(0.1), 0.9),  # within the acceptance
        Vector("boundary", hooked, 0.9),
        Vector("boundary", line(50.0), 0.9),  # along no true boundary: left out
        Vector("boundary", line(0.0), 0.01),  # under the review's confidence floor
        Vector("divider", line(10.0), 0.9),
    ]
    rows = boundary_errors(proposals, truths, SimulationConfig())
    assert len(rows) == 2
    assert rows[0]["acceptable"] and rows[0]["chamfer_m"] == pytest.approx(0.1)
    assert rows[0]["vertices_off_share"] == 0.0
    assert not rows[1]["acceptable"] and rows[1]["worst_gap_m"] == pytest.approx(0.8)
    assert rows[1]["vertices_off_share"] == 1.0


@pytest.mark.parametrize(
    "bench",
    [boundary_evidence, boundary_offset, annotator_split, annotator_seconds],
    ids=lambda m: m.__name__,
)
def test_the_settings_benches_refuse_a_checkpoint_on_a_site_it_saw(
    bench: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def seen(path: Path, sites: list[Path]) -> None:
        raise SeenSiteError(f"{sites[0]}: VMA checkpoint {path} was trained on this folder")

    monkeypatch.setattr(vma_measures, "unseen_mask_checkpoint", seen)
    script = bench.__name__.rsplit(".", 1)[-1]
    out = tmp_path / f"{script}.json"
    monkeypatch.setattr(sys, "argv", [f"{script}.py", "--site", "data/synthetic/seen", "--out", str(out)])
    with pytest.raises(SystemExit) as exited:
        bench.main()
    assert exited.value.code == 2
    error = capsys.readouterr().err
    assert f"bench/{script}.py: data/synthetic/seen" in error and "trained on" in error
    assert not out.exists()
