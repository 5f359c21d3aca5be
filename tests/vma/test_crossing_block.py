"""A crossing's block read from its stripes (`models.vma.crossing_block`): smeared stray cells and a slanted cut of
what was seen neither widen nor tilt it, where they do the smallest rectangle round the stripes."""

from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.semantics import Semantic
from models.vma.crossing_block import plateau_span, stripe_block
from models.vma.element_masks.propose import MaskInferenceConfig, read_crossing, ring_cells, ring_width
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.rule_based import RuleConfig, crosswalk_vectors
from tests.vma.vma_test_sites import drawn_semantic, global_xy, pixel, write_raster_site


def _extent_along_road(ring: np.ndarray) -> tuple[float, float]:
    return float(ring[:, 0].min()), float(ring[:, 0].max())


def test_stray_smeared_cells_widen_the_rectangle_but_not_the_block_read_from_the_stripes(
    tmp_path: Path,
) -> None:
    # the drawn crossing's stripes span x 30-34 m along the road, y 12.5-27.5 m across it
    semantic, vectors = drawn_semantic()
    crosswalk = int(Semantic.CROSSWALK)
    # a surface stage smears a few crosswalk cells past the block along the kerbs, 1.2 m each way
    semantic[pixel(0, 12.6)[1] : pixel(0, 12.8)[1], pixel(34, 0)[0] : pixel(35.2, 0)[0]] = crosswalk
    semantic[pixel(0, 27.2)[1] : pixel(0, 27.4)[1], pixel(28.8, 0)[0] : pixel(30, 0)[0]] = crosswalk
    rasters = load_site_rasters(write_raster_site(tmp_path / "smeared", semantic, vectors))
    stripes = rasters.semantic == crosswalk
    (rectangle,) = crosswalk_vectors(rasters, stripes, RuleConfig())
    low, high = _extent_along_road(rectangle.points)
    assert high - low > 5.0, "the rectangle takes in the smear"

    ring = stripe_block(
        rasters,
        stripes,
        rasters.semantic != int(Semantic.UNOBSERVED),
        RuleConfig(),
        rectangle=rectangle.points,
    )
    assert ring is not None and len(ring) == 5
    np.testing.assert_allclose(ring[0], ring[-1])
    low, high = _extent_along_road(ring)
    # the drawn cells are columns 300-339: their outer edges lie at 29.95 and 33.95 m
    assert low == pytest.approx(529.95, abs=0.1) and high == pytest.approx(533.95, abs=0.1), (low, high)
    ys = ring[:, 1]
    assert ys.max() == pytest.approx(global_xy(0, 12)[1], abs=0.2), "carried to the kerb as before"
    assert ys.min() == pytest.approx(global_xy(0, 28)[1], abs=0.2)


def test_the_width_holds_where_a_slanted_edge_of_what_was_seen_cuts_the_block() -> None:
    rng = np.random.default_rng(0)
    # a block 40 cells wide along the road (-0.5 .. 39.5) and 100 across, of which the cameras saw the cells
    # left of a slanting line: the block's far corner is unobserved, its stripes there missing
    across, along = np.meshgrid(np.arange(100.0), np.arange(-10.0, 50.0), indexing="ij")
    seen = along < 60 - 0.5 * across
    stripe = (across // 5) % 2 == 0
    in_block = (along >= 0) & (along < 40)
    positions = along[seen & stripe & in_block]
    observed = along[seen]
    stray = rng.uniform(40, 48, 6)  # a few smeared cells past the block's end
    cells, seen_cells = np.concatenate([positions, stray]), np.concatenate([observed, stray])
    low, high = plateau_span(cells, seen_cells, 0.5)
    assert low == pytest.approx(-0.5, abs=0.1) and high == pytest.approx(39.5, abs=0.1), (low, high)
    # a lower level reads a sharp edge that much of a cell farther out
    low, high = plateau_span(cells, seen_cells, 0.25)
    assert low == pytest.approx(-0.75, abs=0.1) and high == pytest.approx(39.75, abs=0.1), (low, high)


def test_a_blob_without_stripes_gives_no_block_and_the_setting_is_checked(tmp_path: Path) -> None:
    rasters = load_site_rasters(write_raster_site(tmp_path / "site", *drawn_semantic()))
    square = np.zeros(rasters.shape, bool)
    square[100:140, 100:140] = True  # a worn crossing read as one blob: no direction at all
    observed = rasters.semantic != int(Semantic.UNOBSERVED)
    assert stripe_block(rasters, square, observed, RuleConfig()) is None
    assert stripe_block(rasters, np.zeros(rasters.shape, bool), observed, RuleConfig()) is None
    with pytest.raises(ValueError, match="crossing_fit"):
        MaskInferenceConfig(crossing_fit="hull")  # type: ignore[arg-type]


def _network_ring(rasters: SiteRasters, x0: float, x1: float) -> tuple[np.ndarray, np.ndarray]:
    """A soft ring round the drawn crossing as the network traces it, and the cells inside it."""
    corners = np.array([global_xy(x0, 12.5), global_xy(x1, 12.5), global_xy(x1, 27.5), global_xy(x0, 27.5)])
    ring = np.vstack([corners, corners[:1]])
    return ring, ring_cells(rasters, ring) > 0


def test_the_narrower_fit_takes_the_stripes_block_only_where_stray_cells_widened_the_rectangle(
    tmp_path: Path,
) -> None:
    narrower = MaskInferenceConfig(crossing_fit="narrower")
    semantic, vectors = drawn_semantic()
    clean = load_site_rasters(write_raster_site(tmp_path / "clean", semantic.copy(), vectors))
    ring, inside = _network_ring(clean, 29.6, 34.4)
    rectangle = read_crossing(clean, ring, inside, MaskInferenceConfig(crossing_fit="rectangle"))
    # nothing smeared: the block read from the stripes is no narrower, and the rectangle stays
    np.testing.assert_array_equal(read_crossing(clean, ring, inside, narrower), rectangle)

    crosswalk = int(Semantic.CROSSWALK)
    semantic[pixel(0, 12.6)[1] : pixel(0, 12.8)[1], pixel(34, 0)[0] : pixel(35.2, 0)[0]] = crosswalk
    semantic[pixel(0, 27.2)[1] : pixel(0, 27.4)[1], pixel(28.8, 0)[0] : pixel(30, 0)[0]] = crosswalk
    smeared = load_site_rasters(write_raster_site(tmp_path / "smeared", semantic, vectors))
    ring, inside = _network_ring(smeared, 28.6, 35.4)
    wide = read_crossing(smeared, ring, inside, MaskInferenceConfig(crossing_fit="rectangle"))
    assert ring_width(wide) > 5.0  # the rectangle takes in the smear
    read = read_crossing(smeared, ring, inside, narrower)
    assert ring_width(read) == pytest.approx(4.0, abs=0.15)
    low, high = _extent_along_road(read)
    assert low == pytest.approx(529.95, abs=0.1) and high == pytest.approx(533.95, abs=0.1), (low, high)
    with pytest.raises(ValueError, match="crossing_margin_m"):
        MaskInferenceConfig(crossing_fit="narrower", crossing_margin_m=-0.1)
