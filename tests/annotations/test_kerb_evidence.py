"""Kerb evidence: boundaries over a hand-made semantic raster classified as kerb, road border or unobserved."""

import numpy as np
import pytest

from annotations import AnnotationSet, MapElement
from annotations.kerb_evidence import KERB_MIN_FRACTION, kerb_evidence
from cama_pipeline.semantics import Semantic
from tests.annotations.kerb_helpers import (
    BORDER_Y,
    KERB_GEOREF,
    KERB_Y,
    boundary,
    kerb_raster,
    kerb_set,
)


def test_kerb_road_border_unobserved_and_inside_the_road() -> None:
    result = kerb_evidence(kerb_set(), kerb_raster())
    assert result.verdicts == {
        "kerb": "observed",
        "border": "none",
        "hidden": "unobserved",
        "inside": "unobserved",
    }
    assert result.counts == {"observed": 1, "none": 1, "unobserved": 2}
    assert result.evidence["kerb"].curb_fraction == 1.0
    assert result.evidence["border"].curb_fraction == 0.0 and result.evidence["border"].edge_fraction == 1.0
    assert result.evidence["hidden"].observed == 0 and "observed" in result.evidence["hidden"].reason
    inside = result.evidence["inside"]
    assert inside.observed == inside.stations and inside.edge_fraction == 0.0 and "road edge" in inside.reason


def _set(*elements: MapElement) -> AnnotationSet:
    return AnnotationSet(site_id="s", georeference=KERB_GEOREF, elements=list(elements))


@pytest.mark.parametrize(
    ("curb_until_x", "verdict"), [(8.0, "observed"), (6.5, "observed"), (5.0, "none"), (2.5, "none")]
)
def test_a_kerb_seen_over_part_of_its_length(curb_until_x: float, verdict: str) -> None:
    """Curb cells from x 1 to `curb_until_x` of a boundary from x 1 to 18: kerb at >= 30 % of it."""
    result = kerb_evidence(_set(boundary("b", KERB_Y)), kerb_raster(curb_until_x=curb_until_x))
    fraction = result.evidence["b"].curb_fraction
    assert fraction == pytest.approx((curb_until_x - 1.0) / 17.0, abs=0.02)
    assert (fraction >= KERB_MIN_FRACTION) == (verdict == "observed")
    assert result.verdicts == {"b": verdict}


@pytest.mark.parametrize("shift_m", [-0.3, 0.3])
def test_a_boundary_drawn_a_little_off_the_edge_is_still_read(shift_m: float) -> None:
    result = kerb_evidence(
        _set(boundary("kerb", KERB_Y + shift_m), boundary("border", BORDER_Y + shift_m)), kerb_raster()
    )
    assert result.verdicts == {"kerb": "observed", "border": "none"}


def test_too_little_observed_stays_unobserved() -> None:
    raster = kerb_raster()
    raster[:, 25:] = int(Semantic.UNOBSERVED)  # only x < 2.5 m seen: 1.5 m of the boundary from x 1
    result = kerb_evidence(_set(boundary("short", KERB_Y)), raster)
    assert result.verdicts == {"short": "unobserved"}
    assert 0 < result.evidence["short"].observed < result.evidence["short"].stations


def test_a_boundary_leaving_the_raster_counts_outside_as_unobserved() -> None:
    result = kerb_evidence(_set(boundary("out", KERB_Y, x0=-40.0, x1=5.0)), kerb_raster())
    evidence = result.evidence["out"]
    assert evidence.verdict == "unobserved" and evidence.observed < 0.3 * evidence.stations


@pytest.mark.parametrize(
    ("raster", "message"),
    [
        (np.zeros((199, 200), dtype=np.uint8), r"shape \(199, 200\).*\(200, 200\)"),
        (np.zeros((200, 200, 3), dtype=np.uint8), r"shape \(200, 200, 3\)"),
        (np.zeros((200, 200), dtype=np.float32), "integer class ids"),
    ],
)
def test_a_raster_that_does_not_fit_is_refused_naming_it(raster: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=f"semantic: .*{message}"):
        kerb_evidence(kerb_set(), raster)
