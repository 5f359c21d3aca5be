"""bench/surface_grid.py: the world rebuilt from a site's manifest gives its stored truth, the area rule is scored
against it, and a site whose truth the rebuilt world does not give is refused."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bench.surface_grid import ceiling
from cama_pipeline.bev import read_bev, write_bev
from tests.conftest import GeneratedSite


def _truth_only(site: Path, to: Path) -> Path:
    """The manifest and the true rasters of `site` in `to`: all the bench reads."""
    to.mkdir()
    shutil.copy(site / "manifest.json", to / "manifest.json")
    shutil.copytree(site / "ground_truth" / "bev", to / "ground_truth" / "bev")
    return to


def test_the_area_rule_is_scored_against_the_stored_truth(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    site = _truth_only(tiny_site.result.out_dir, tmp_path / "site")
    row = ceiling(site, 2)
    assert set(row["classes"]) == {"curb", "lane_marking", "crosswalk"}
    marking = row["classes"]["lane_marking"]
    assert marking["true_cells"] > 0 and 0.5 < marking["area_rule_iou"] <= 1.0
    assert json.loads(json.dumps(row)) == row  # written as JSON as it is


def test_a_site_the_rebuilt_world_does_not_give_is_refused(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    site = _truth_only(tiny_site.result.out_dir, tmp_path / "site")
    rasters = read_bev(site / "ground_truth" / "bev")
    semantic = rasters.require("semantic").copy()
    observed = np.argwhere(semantic != 255)[0]
    semantic[tuple(observed)] = (semantic[tuple(observed)] + 1) % 5
    write_bev(site / "ground_truth" / "bev", replace(rasters, semantic=semantic))
    with pytest.raises(ValueError, match="does not give its stored truth raster"):
        ceiling(site, 2)
