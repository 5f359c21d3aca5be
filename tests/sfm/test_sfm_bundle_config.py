"""SfM config: validated fields naming the bad one, and the benchmark's presets."""

import pytest

from cama_pipeline.sfm.config import SfmConfig


def test_presets_are_the_benchmark_variants() -> None:
    plain, rigid, iterative = (SfmConfig.preset(n) for n in ("plain", "rigid", "iterative"))
    assert (plain.rigid, plain.iterative) == (False, False)
    assert (rigid.rigid, rigid.iterative) == (True, False)
    assert (iterative.rigid, iterative.iterative) == (True, True)
    assert plain.odometry_priors and not SfmConfig.preset("rigid", odometry_priors=False).odometry_priors
    with pytest.raises(ValueError, match="unknown SfM preset 'fast'"):
        SfmConfig.preset("fast")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_reprojection_error_px", 0.0),
        ("max_iterations", 0),
        ("min_track_length", 1),
        ("max_refinement_change", 1.0),
        ("loss", "l1"),
        ("position_sigma_m", -1.0),
        ("first_ba_max_iterations", 0),
    ],
)
def test_bad_fields_are_named(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"SfmConfig.{field}"):
        SfmConfig(**{field: value})  # type: ignore[arg-type]


def test_refining_extrinsics_needs_a_rig() -> None:
    with pytest.raises(ValueError, match="refine_extrinsics needs rigid"):
        SfmConfig(rigid=False, refine_extrinsics=True)
