"""`bench/surface_photometric.py` splits the BEV colour's error against the truth by class and by scale: a colour
offset is coarse error, a pixel-scale pattern fine error, and darkened paint shows in its class's mean."""

import numpy as np
import pytest

from bench.surface_photometric import photometric_figures, scale_split
from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.evaluate.photometric import affine_fit, psnr
from cama_pipeline.semantics import Semantic

SHAPE = (60, 60)


def truth_colour() -> np.ndarray:
    """A smooth albedo (a gradient) with some texture, 0-255."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    base = 80 + rows + 0.5 * cols
    return np.clip(np.stack([base, base + 5, base - 5], axis=-1) + rng.normal(0, 3, (*SHAPE, 3)), 0, 255)


def test_a_colour_offset_is_coarse_error_and_a_checkerboard_fine() -> None:
    truth, observed = truth_colour(), np.ones(SHAPE, bool)
    offset = scale_split(truth + 6.0, truth, observed)
    assert offset["sigma_2"]["coarse_share"] == pytest.approx(1.0, abs=1e-6)
    assert offset["sigma_2"]["fine_share"] == pytest.approx(0.0, abs=1e-6)
    assert offset["psnr_db"] == pytest.approx(psnr(truth + 6.0, truth))
    checker = np.where(
        (np.add.outer(np.arange(SHAPE[0]), np.arange(SHAPE[1])) % 2 == 0)[..., None], 6.0, -6.0
    )
    fine = scale_split(truth + checker, truth, observed)
    assert fine["sigma_1"]["fine_share"] > 0.95 and fine["sigma_1"]["coarse_share"] < 0.05
    # the truth's own texture is fine: blurred, it scores far below a perfect copy but far above the noise
    assert 20 < fine["sigma_2"]["truth_blurred_psnr_db"] < 60


def test_unobserved_cells_neither_count_nor_leak_into_the_blur() -> None:
    truth = truth_colour()
    observed = np.zeros(SHAPE, bool)
    observed[:, :40] = True
    ours = truth.copy()
    ours[:, 40:] = 0  # garbage where nothing was observed
    split = scale_split(ours, truth, observed)
    assert split["psnr_db"] > 100 and split["cells"] == (60 - 16) * (40 - 16)


def test_darkened_paint_shows_in_its_class() -> None:
    truth = truth_colour()
    semantic = np.full(SHAPE, int(Semantic.ROAD), np.uint8)
    semantic[:, 28:31] = int(Semantic.LANE_MARKING)
    truth[:, 28:31] = 220.0
    ours = truth.copy()
    ours[:, 28:31] = 165.0  # the paint smeared into the asphalt around it
    semantic_ours = semantic.copy()
    semantic_ours[0, :] = int(Semantic.UNOBSERVED)
    georeference = RasterGeoreference(origin_xy=(0.0, 0.0), resolution=0.1, width=SHAPE[1], height=SHAPE[0])

    def rasters(colour: np.ndarray, labels: np.ndarray) -> BevRasters:
        elevation = np.zeros(SHAPE, np.float32)
        return BevRasters(
            georeference, semantic=labels, photometric_rgb=colour.astype(np.uint8), elevation=elevation
        )

    figures = photometric_figures(rasters(ours, semantic_ours), rasters(truth, semantic))
    assert figures["cells"] == SHAPE[0] * SHAPE[1] - SHAPE[1]
    # after the global affine fit, which the darker paint pulls a little, the paint still reads darker than it is
    assert figures["by_class"]["lane_marking"]["mean_over_truth"] < 0.85
    assert figures["by_class"]["road"]["mean_over_truth"] == pytest.approx(1.0, abs=0.03)
    assert figures["by_class"]["lane_marking"]["psnr_db"] < figures["by_class"]["road"]["psnr_db"]
    assert "crosswalk" not in figures["by_class"]


def test_the_affine_fit_takes_out_a_gain_and_an_offset() -> None:
    truth = truth_colour().reshape(-1, 3)
    shaded = 0.8 * truth + 10
    assert psnr(affine_fit(shaded, truth), truth) > 60 > psnr(shaded, truth)
