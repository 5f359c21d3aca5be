"""`cama_pipeline.synthetic.truth_grid`: a site's truth rendered on another grid is the stored truth where the
grids coincide, the ground at each cell's own centre where they do not, unobserved where the stored truth is, and
refused when the rebuilt world does not give the stored truth."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.bev import RasterGeoreference, write_bev
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from cama_pipeline.synthetic import ground_truth
from cama_pipeline.synthetic.config import preset, with_ramp
from cama_pipeline.synthetic.generate import run
from cama_pipeline.synthetic.truth_grid import (
    TrueGround,
    TruthMismatch,
    cell_centres,
    centre_labels,
    nearest_stored,
    rebuilt_world,
    site_config,
    stored_truth,
    truth_on_grid,
)
from tests.conftest import GeneratedSite

Window = tuple[slice, slice]


@pytest.fixture(scope="module")
def window(tiny_site: GeneratedSite) -> Window:
    """Rows and columns of the tiny site's stored grid that the tests render again: 13 x 22 m around the middle
    one of its lane-marking cells (road, paint and kerbs)."""
    marking = np.argwhere(
        stored_truth(tiny_site.result.out_dir).require("semantic") == int(Semantic.LANE_MARKING)
    )
    row, col = marking[len(marking) // 2]
    return slice(max(row - 65, 0), max(row - 65, 0) + 130), slice(max(col - 110, 0), max(col - 110, 0) + 220)


def _window(
    geo: RasterGeoreference, window: Window, shift_cells: tuple[float, float] = (0.0, 0.0)
) -> RasterGeoreference:
    """`window` of `geo` as a georeference of its own, moved by (columns, rows) of a cell."""
    rows, cols = window
    x, y = geo.global_from_pixel([[cols.start + shift_cells[0], rows.start + shift_cells[1]]])[0]
    return RasterGeoreference(
        origin_xy=(float(x), float(y)),
        resolution=geo.resolution,
        width=cols.stop - cols.start,
        height=rows.stop - rows.start,
    )


def test_where_the_grids_coincide_the_truth_is_the_stored_truth(
    tiny_site: GeneratedSite, window: Window
) -> None:
    site = tiny_site.result.out_dir
    stored = stored_truth(site)
    again = truth_on_grid(site, _window(stored.georeference, window))
    assert (stored.require("semantic")[window] == int(Semantic.LANE_MARKING)).sum() > 50
    for layer in ("semantic", "photometric", "elevation", "observation_count"):
        assert np.array_equal(again.require(layer), stored.require(layer)[window]), layer


def test_half_a_cell_off_each_cell_takes_the_ground_at_its_own_centre(
    tiny_site: GeneratedSite, window: Window
) -> None:
    site = tiny_site.result.out_dir
    stored = stored_truth(site)
    geo = _window(stored.georeference, window, (0.45, 0.4))
    moved = truth_on_grid(site, geo).require("semantic")
    cfg, world = rebuilt_world(site)
    layout_origin = (geo.origin_xy[0] - cfg.site_origin_xy[0], geo.origin_xy[1] - cfg.site_origin_xy[1])
    grid = ground_truth.BevGrid(layout_origin, geo.resolution, geo.height, geo.width)
    observed = moved != int(Semantic.UNOBSERVED)
    assert observed.mean() > 0.9
    assert np.array_equal(moved[observed], centre_labels(world, grid)[observed])
    # the stored truth read at the nearest cell, as the benches read it before, is not the truth there: its
    # lane-marking cells disagree at the paint's edges
    nearest = stored.require("semantic")[window]
    marking = int(Semantic.LANE_MARKING)
    disagree = ((moved == marking) != (nearest == marking)) & observed
    assert 0 < disagree.sum() < (nearest == marking).sum()


def test_cells_the_stored_truth_did_not_observe_or_hold_are_unobserved(tiny_site: GeneratedSite) -> None:
    site = tiny_site.result.out_dir
    stored = stored_truth(site)
    geo = stored.georeference
    beyond = RasterGeoreference(
        origin_xy=(geo.origin_xy[0] - 20 * geo.resolution, geo.origin_xy[1]),
        resolution=geo.resolution,
        width=60,
        height=geo.height,
    )
    truth = truth_on_grid(site, beyond)
    semantic, count = truth.require("semantic"), truth.require("observation_count")
    assert (semantic[:, :20] == int(Semantic.UNOBSERVED)).all() and (count[:, :20] == 0).all()
    held = stored.require("semantic")[:, :40]
    assert np.array_equal(semantic[:, 20:] == int(Semantic.UNOBSERVED), held == int(Semantic.UNOBSERVED))
    assert np.array_equal(count.ravel(), nearest_stored(stored, cell_centres(beyond)))


def test_a_site_whose_rebuilt_world_does_not_give_its_truth_is_refused(
    tiny_site: GeneratedSite, window: Window, tmp_path: Path
) -> None:
    site = tmp_path / "site"
    site.mkdir()
    shutil.copy(tiny_site.result.out_dir / "manifest.json", site / "manifest.json")
    shutil.copytree(tiny_site.result.out_dir / "ground_truth" / "bev", site / "ground_truth" / "bev")
    rasters = stored_truth(site)
    semantic = rasters.require("semantic").copy()
    observed = tuple(np.argwhere(semantic != int(Semantic.UNOBSERVED))[0])
    semantic[observed] = (semantic[observed] + 1) % 5
    write_bev(site / "ground_truth" / "bev", replace(rasters, semantic=semantic))
    with pytest.raises(TruthMismatch, match=f"{site}: the world rebuilt from its manifest does not give"):
        truth_on_grid(site, _window(rasters.georeference, window))


def test_a_site_with_its_own_terrain_is_rebuilt_with_it(tmp_path: Path) -> None:
    """A site made with `cama synth --terrain-rise/--ramp-width` (a config no preset gives): its truth on its own
    grid is the stored truth, heights included (rebuilt from the preset, the heights were the preset's terrain's:
    1.8 m off at the hilly default site's western end)."""
    site = tmp_path / "hilly"
    cfg = preset("tiny")
    run(replace(cfg, terrain=with_ramp(cfg.terrain, 6.0, 20.0)), site, images=False)
    stored = stored_truth(site)
    again = truth_on_grid(site, stored.georeference)
    for layer in ("semantic", "elevation"):
        assert np.array_equal(again.require(layer), stored.require(layer), equal_nan=True), layer
    assert site_config(site).terrain.rise_m == 6.0


def test_a_manifest_config_that_cannot_be_rebuilt_is_refused(
    tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    for field, value, why in (
        ("rise_m", 100.0, "exceeds max_grade"),
        ("hill_m", 3.0, "no attribute 'hill_m'"),
    ):
        site = tmp_path / field
        site.mkdir()
        manifest = json.loads((tiny_site.result.out_dir / "manifest.json").read_text())
        manifest["config"]["terrain"][field] = value
        (site / "manifest.json").write_text(json.dumps(manifest))
        with pytest.raises(TruthMismatch, match=f"{site}: its manifest's config cannot be rebuilt: .*{why}"):
            site_config(site)


def test_a_reconstruction_frame_moves_where_each_cell_is_read(
    tiny_site: GeneratedSite, window: Window
) -> None:
    """A frame that puts the reconstruction one cell east of the world reads every cell's truth one cell east."""
    site = tiny_site.result.out_dir
    stored = stored_truth(site)
    geo = stored.georeference
    rows, cols = window
    framed = truth_on_grid(site, _window(geo, window), lambda xy: xy + np.array([geo.resolution, 0.0]))
    east = (rows, slice(cols.start + 1, cols.stop + 1))
    assert np.array_equal(framed.require("semantic"), stored.require("semantic")[east])
    assert np.abs(framed.require("elevation") - stored.require("elevation")[east]).max() < 1e-4


def test_the_true_ground_anywhere_has_the_stored_height_and_class(
    tiny_site: GeneratedSite, window: Window
) -> None:
    """At the stored cell centres: the stored elevation for the classes asked for (NaN for others), the stored
    class, and unobserved where the stored truth has no cell."""
    site = tiny_site.result.out_dir
    stored = stored_truth(site)
    centres = cell_centres(_window(stored.georeference, window))
    semantic = stored.require("semantic")[window].ravel()
    elevation = stored.require("elevation")[window].ravel()
    road = np.isin(semantic, ROAD_SURFACE_IDS)
    ground = TrueGround.of(site)
    heights = ground.height_of()(centres)
    assert road.sum() > 1000
    assert np.abs(heights[road] - elevation[road]).max() < 1e-4
    assert np.isnan(heights[~road & (semantic != int(Semantic.UNOBSERVED))]).all()
    curb = semantic == int(Semantic.CURB)
    with_curb = ground.height_of((*ROAD_SURFACE_IDS, int(Semantic.CURB)))(centres)
    assert curb.sum() > 20
    assert np.abs(with_curb[curb] - elevation[curb]).max() < 1e-4
    assert np.array_equal(ground.label(centres), semantic)
    assert ground.label(centres.min(axis=0, keepdims=True) - 50.0) == int(Semantic.UNOBSERVED)
