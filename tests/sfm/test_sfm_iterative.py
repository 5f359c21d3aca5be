"""Iterative BA (Algorithm 1) stops by its rule: changed-observation ratio at or under the threshold, or
the iteration limit, with every iteration in the report."""

import pytest

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views
from tests.sfm.sfm_fixture import SfmInputs

pytestmark = pytest.mark.slow  # the shared SfM inputs take ~30 s to build (pairs, features)


def run_iterative(inputs: SfmInputs, **overrides: object) -> dict:
    views = inputs.longest_drive()
    config = SfmConfig.preset("iterative", **overrides)
    return reconstruct_views(views, inputs.database, inputs.image_dir, config).report


def test_iterations_stop_when_the_changed_ratio_falls_under_the_threshold(sfm_inputs: SfmInputs) -> None:
    report = run_iterative(sfm_inputs, max_iterations=6, max_refinement_change=0.01)
    ratios = [it["changed_ratio"] for it in report["iterations"]]
    assert [it["iteration"] for it in report["iterations"]] == list(range(1, len(ratios) + 1))
    assert all(r > 0.01 for r in ratios[:-1])
    if report["stop"] == "converged":
        assert ratios[-1] <= 0.01
    else:
        assert report["stop"] == "max_iterations" and len(ratios) == 6 and ratios[-1] > 0.01
    for it in report["iterations"]:
        assert it["observations"] > 0 and {"post_ba_retriangulated", "filtered_observations"} <= set(it)


def test_a_loose_threshold_stops_after_one_iteration_and_a_strict_one_at_the_limit(
    sfm_inputs: SfmInputs,
) -> None:
    loose = run_iterative(sfm_inputs, max_iterations=4, max_refinement_change=0.9)
    assert loose["stop"] == "converged" and len(loose["iterations"]) == 1
    strict = run_iterative(sfm_inputs, max_iterations=2, max_refinement_change=0.0)
    ratios = [it["changed_ratio"] for it in strict["iterations"]]
    assert (strict["stop"], len(ratios)) == ("max_iterations", 2) or (
        strict["stop"] == "converged" and ratios[-1] == 0
    )


def test_the_first_ba_is_capped_and_the_later_ones_are_not(sfm_inputs: SfmInputs) -> None:
    report = run_iterative(sfm_inputs, max_iterations=3, max_refinement_change=0.0, first_ba_max_iterations=2)
    steps = [it["solver_iterations"] for it in report["iterations"]]
    assert steps[0] <= 2 + 1 and max(steps[1:]) > 3  # Ceres counts its starting point as a step
