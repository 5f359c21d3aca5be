"""bench/pairs.py on an image-free site: matching is estimated from a measured site, labelled, and the results
file keeps the other sites' entries only when they were made with the same config."""

import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.pairs.pair_views import view


def _load_bench_pairs() -> ModuleType:
    """bench/pairs.py, a script rather than a package module, loaded from its file."""
    path = Path(__file__).parents[2] / "bench" / "pairs.py"
    spec = importlib.util.spec_from_file_location("bench_pairs", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the file runs
    spec.loader.exec_module(module)
    return module


_bench = _load_bench_pairs()
STRATEGIES = _bench.STRATEGIES
estimated_matching = _bench.estimated_matching
has_images = _bench.has_images
measured_reference = _bench.measured_reference
previous_results = _bench.previous_results
ratios = _bench.ratios


def _measured_entry(cpu_blas: float) -> dict:
    timing = {"blas": {"cpu_seconds_per_pair": cpu_blas}, "colmap": {"cpu_seconds_per_pair": 2 * cpu_blas}}
    return {name: {"matching": timing} for name in STRATEGIES}


def test_the_reference_is_the_first_measured_entry_and_an_estimate_says_so():
    estimated = {name: {"matching": {"measured": False}} for name in STRATEGIES}
    sites = {"large": {"site-001": estimated}, "default": {"site-001": _measured_entry(0.01)}}
    reference = measured_reference(sites)
    assert reference is not None and reference["source"] == "default site-001"
    entry = estimated_matching("sequential+hsp", 1000, reference)
    assert entry["measured"] is False and entry["estimate"].startswith("NOT MEASURED")
    assert entry["reference_cpu_seconds_per_pair"] == {"blas": 0.01, "colmap": 0.02}
    assert measured_reference({"large": {"site-001": estimated}}) is None


def test_ratios_of_an_estimated_site_are_cpu_only():
    report = {
        "exhaustive": {"pairs": 100, "estimated_matching_cpu_seconds": {"blas": 10.0}},
        "sequential+hsp": {"pairs": 5, "estimated_matching_cpu_seconds": {"blas": 1.0}},
    }
    assert ratios(report, measured=False) == {
        "pairs_hsp_over_exhaustive": 0.05,
        "matching_cpu_hsp_over_exhaustive": 0.1,
    }


def test_previous_entries_are_kept_only_under_the_same_config(tmp_path):
    path = tmp_path / "pairs.json"
    assert previous_results(path, {"a": 1}) == {"sites": {}, "commands": {}}
    path.write_text(json.dumps({"command": "old", "config": {"a": 1}, "sites": {"default": {}}}))
    assert previous_results(path, {"a": 1}) == {"sites": {"default": {}}, "commands": {"default": "old"}}
    assert previous_results(path, {"a": 2})["sites"] == {}


@pytest.mark.parametrize("present", [True, False])
def test_has_images_checks_every_view_file(tmp_path, present):
    views = [view(0, 0, 0), view(5, 0, 0, frame=1)]
    for v in views[: 2 if present else 1]:
        (tmp_path / v.name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / v.name).write_bytes(b"jpg")
    assert has_images(tmp_path, views) is present
