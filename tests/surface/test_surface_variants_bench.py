"""`bench/surface_variants.py` reads its variants as NAME=JSON over the shipped `SurfaceConfig`, nested parts
included (as a run configuration's `[surface]` table), and refuses a malformed one, an unknown field or a value
the config refuses, naming it."""

from pathlib import Path

import pytest

from bench.surface import mask_choice
from bench.surface_variants import against_baseline, parse_variant
from cama_pipeline.surface import SurfaceConfig


def test_a_variant_sets_fields_and_fields_of_parts() -> None:
    base = SurfaceConfig(torch_threads=2)
    name, config, settings = parse_variant(
        'smooth 100={"refine": {"smoothness_weight": 100, "sweeps": [[0.06, 0.02]]}, "sfm_gate_m": 0.5}', 2
    )
    assert name == "smooth 100" and settings["sfm_gate_m"] == 0.5
    assert config.refine.smoothness_weight == 100 and config.refine.sweeps == ((0.06, 0.02),)
    assert config.sfm_gate_m == 0.5 and config.refine.ridge_weight == base.refine.ridge_weight
    assert parse_variant("shipped={}", 2)[1] == base


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("smooth", "expected NAME=JSON"),
        ("={}", "expected NAME=JSON"),
        ("smooth=[1]", "expected NAME=JSON"),
        ("smooth={nope", "not NAME=JSON"),
        ('smooth={"refine": {"smoothness": 30}}', "unknown key 'refine.smoothness'"),
        ('smooth={"refine": {"smoothness_weight": -1}}', "smoothness_weight must be >= 0"),
        ('smooth={"refine": {"smoothness_weight": "stiff"}}', "refine.smoothness_weight must be a number"),
    ],
)
def test_a_bad_variant_is_refused_naming_what_is_wrong(text: str, named: str) -> None:
    with pytest.raises(SystemExit, match=named):
        parse_variant(text, 1)


def test_each_run_is_compared_with_the_first() -> None:
    def run(rmse: float, curb: float, seconds: float) -> dict:
        return {
            "elevation_rmse_cm": rmse,
            "iou_in_reconstruction_frame": {"curb": curb},
            "psnr_db": 22.0,
            "seconds": seconds,
        }

    compared = against_baseline({"base": run(5.0, 0.6, 40.0), "smooth": run(4.5, 0.65, 44.0)})
    assert compared["base"]["elevation_rmse_cm"] == 0.0
    assert compared["smooth"]["elevation_rmse_cm"] == pytest.approx(-0.5)
    assert compared["smooth"]["iou_in_reconstruction_frame"]["curb"] == pytest.approx(0.05)
    assert compared["smooth"]["seconds_ratio"] == pytest.approx(1.1)


def test_a_variant_may_name_the_masks_it_observes_through() -> None:
    name, config, settings = parse_variant('generator masks={"masks": "generator"}', 2)
    assert name == "generator masks" and settings == {"masks": "generator"}
    assert config == SurfaceConfig(torch_threads=2)  # the masks are not a setting of the stage
    assert parse_variant('smooth={"masks": "predicted", "sfm_gate_m": 0.5}', 2)[1].sfm_gate_m == 0.5
    with pytest.raises(SystemExit, match="masks 'truth' is not one of auto, predicted"):
        parse_variant('bad={"masks": "truth"}', 2)


def test_generator_masks_are_the_mask_free_sites_ground_truth(tmp_path: Path) -> None:
    site = tmp_path / "site"
    assert mask_choice(site, "predicted") == "predicted" and mask_choice(site, "auto") == "auto"
    with pytest.raises(SystemExit, match=f"{site / 'ground_truth'}: no generator masks"):
        mask_choice(site, "generator")
    (site / "ground_truth" / "semantic").mkdir(parents=True)
    assert mask_choice(site, "generator") == str(site / "ground_truth")
