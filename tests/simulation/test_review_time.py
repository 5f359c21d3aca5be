"""The retrain job's second gate: the scripted annotator's time on a proposer's output, on an in-memory queue."""

from pathlib import Path

import pytest

from app.review_effort.review_time import review_time
from cama_pipeline.evaluate.frame import ReconstructionFrame
from models.vma.rasters import vector_map_of
from models.vma.validation import ValidationSite
from models.vma.vectors import Vector, read_vectors
from tests.vma.vma_test_sites import hand_drawn_site


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return hand_drawn_site(tmp_path_factory.mktemp("review") / "drawn")


def test_the_truth_is_reviewed_faster_than_nothing_and_than_shifted_lines(site: Path) -> None:
    truth = read_vectors(vector_map_of(site))
    perfect = review_time(lambda rasters: truth, [site])
    nothing = review_time(lambda rasters: [], [site])
    shifted = review_time(lambda rasters: [Vector(v.cls, v.points + [0.0, 0.8], 0.9) for v in truth], [site])
    assert nothing["correction_s"] == pytest.approx(
        nothing["drawing_s"]
    )  # nothing proposed: everything drawn
    assert perfect["drawing_s"] == nothing["drawing_s"] == shifted["drawing_s"]
    assert perfect["speed_up"] > 1.5
    assert perfect["correction_s"] < shifted["correction_s"] < nothing["correction_s"] * 1.5
    assert perfect["sites"] == [str(site)]


def test_proposals_below_the_confidence_floor_are_not_reviewed(site: Path) -> None:
    truth = read_vectors(vector_map_of(site))
    faint = review_time(lambda rasters: [Vector(v.cls, v.points, 0.05) for v in truth], [site])
    nothing = review_time(lambda rasters: [], [site])
    assert faint["correction_s"] == pytest.approx(nothing["correction_s"])


def test_no_site_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="no validation sites"):
        review_time(lambda rasters: [], [])


def test_a_reconstruction_is_reviewed_towards_the_truth_in_its_frame(site: Path) -> None:
    """The rasters of a reconstruction sit where its poses' gauge put them; an annotator sees the rasters, so a
    proposal on the paint as the rasters show it is accepted, and the world's truth is what costs corrections."""
    truth = read_vectors(vector_map_of(site))
    frame = ReconstructionFrame(
        1.0, 0.0, (0.0, 0.6), "sfm", 10, 0.6, 0.01
    )  # across the lines: all stay on the rasters
    reconstruction = ValidationSite(site, site, reconstructed=True, frame=frame)
    world = ValidationSite(site, site, reconstructed=True)
    as_shown = [Vector(v.cls, frame.apply(v.points), 0.9) for v in truth]
    in_world = [Vector(v.cls, v.points, 0.9) for v in truth]
    on_reconstruction = review_time(lambda rasters: as_shown, [reconstruction])
    perfect = review_time(lambda rasters: in_world, [world])
    assert on_reconstruction["correction_s"] == pytest.approx(perfect["correction_s"], rel=0.02)
    assert (
        review_time(lambda rasters: in_world, [reconstruction])["correction_s"]
        > perfect["correction_s"] * 1.2
    )
