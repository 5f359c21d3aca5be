"""A generated site's true BEV rasters on any grid: what a reconstruction's rasters are scored against.

The stored truth (`ground_truth/bev/`) labels each cell by the ground at the cell's centre on the generator's own
grid, whose origin follows the ground atlas's extent. A reconstruction's grid is snapped to whole cells of the
global frame instead, so on a randomised site the two grids' centres lie up to half a cell apart on each axis.
Paired by nearest cell, the stored truth is then read up to 5 cm from where it is scored at 0.1 m cells; on 0.15 m
lane lines that shift alone costs a third of the IoU. So the generator's world is rebuilt from the site's manifest
(and checked against the stored truth: same labels at every observed cell centre, else `TruthMismatch`), and
sampled at the other grid's own cell centres, or where a reconstruction's frame puts them. Where the stored truth is
unobserved (no key-frame camera looked, 255) or has no cell, so is the truth on the other grid.
"""

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cama_pipeline.bev import BevRasters, RasterGeoreference, read_bev
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from cama_pipeline.synthetic import ground_truth
from cama_pipeline.synthetic.config import SynthConfig, preset
from cama_pipeline.synthetic.randomise import randomised_config
from cama_pipeline.synthetic.render import World
from cama_pipeline.synthetic.site_model import build_synthetic_site


class TruthMismatch(ValueError):
    """The world rebuilt from a site's manifest does not give the site's stored truth."""


def site_config(site: Path) -> SynthConfig:
    """The generator config of a site from its manifest: its preset and seed, randomised when it was, with every
    part the manifest's config holds otherwise (`cama synth --terrain-rise`, `--image-size`, ...) taken from
    it. TruthMismatch naming the site and the fields when the config rebuilt is not the one stored."""
    manifest = json.loads((Path(site) / "manifest.json").read_text(encoding="utf-8"))
    stored = manifest["config"]
    base = (
        randomised_config(int(manifest["random_seed"]), base=manifest["preset"])
        if manifest.get("random_seed") is not None
        else preset(manifest["preset"], seed=int(manifest["seed"]))
    )
    try:
        changed: dict[str, Any] = {
            name: _as_stored(getattr(base, name), stored[name])
            for name in (f.name for f in fields(base))
            if name in stored and _json(getattr(base, name)) != stored[name]
        }
        cfg = replace(base, **changed)
    except (AttributeError, TypeError, ValueError) as error:
        raise TruthMismatch(f"{site}: its manifest's config cannot be rebuilt: {error}") from None
    differing = sorted(f.name for f in fields(cfg) if _json(getattr(cfg, f.name)) != stored.get(f.name))
    if differing:
        raise TruthMismatch(f"{site}: its manifest's config cannot be rebuilt (fields {differing})")
    return cfg


def _json(value: object) -> object:
    """A config value as the manifest stores it (dataclasses as dicts, tuples as lists)."""
    return json.loads(json.dumps(asdict(value) if is_dataclass(value) else value))  # type: ignore[arg-type]


def _as_stored(current: object, stored: object) -> object:
    """The stored form of a config field, typed like `current`: a nested config rebuilt field by field, lists as
    the configs' tuples."""
    if is_dataclass(current) and isinstance(stored, dict):
        return replace(current, **{k: _as_stored(getattr(current, k), v) for k, v in stored.items()})  # type: ignore[type-var]
    if isinstance(stored, list):
        return tuple(_as_stored(None, item) for item in stored)
    return stored


def stored_truth(site: Path) -> BevRasters:
    """The site's stored true rasters (`ground_truth/bev/`)."""
    return read_bev(Path(site) / "ground_truth" / "bev")


def rebuilt_world(site: Path, truth: BevRasters | None = None) -> tuple[SynthConfig, World]:
    """The site's config and generator world, rebuilt from its manifest; TruthMismatch naming the site when the
    world's labels at the stored truth's cell centres are not the stored ones wherever that is observed."""
    cfg = site_config(site)
    world = build_synthetic_site(cfg).world
    truth = truth if truth is not None else stored_truth(site)
    semantic = truth.require("semantic")
    grid = ground_truth.bev_grid_for(world, cfg.bev_resolution_m)
    if semantic.shape != (grid.rows, grid.cols):
        raise TruthMismatch(
            f"{site}: the rebuilt grid is {grid.rows}x{grid.cols}, the stored truth {semantic.shape}"
        )
    observed = semantic != int(Semantic.UNOBSERVED)
    if not np.array_equal(centre_labels(world, grid)[observed], semantic[observed]):
        raise TruthMismatch(
            f"{site}: the world rebuilt from its manifest does not give its stored truth raster"
        )
    return cfg, world


def centre_labels(world: World, grid: ground_truth.BevGrid, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """(rows, cols) the ground atlas's label at every cell centre of `grid` (layout metres), moved by (dx, dy)."""
    xs, ys = grid.cell_centres()
    yy, xx = np.meshgrid(ys + dy, xs + dx, indexing="ij")
    x, y = torch.from_numpy(xx.astype(np.float32)), torch.from_numpy(yy.astype(np.float32))
    return world.atlas.nearest(world.atlas.label, x, y).numpy()


def truth_on_grid(
    site: Path,
    georeference: RasterGeoreference,
    world_of: Callable[[np.ndarray], np.ndarray] | None = None,
) -> BevRasters:
    """The site's true semantic, photometric and elevation rasters and observation count on `georeference`
    (global metres), each cell rendered at its own centre; unobserved (255, count 0) where the stored truth's
    nearest cell is, or where the stored truth has none. `world_of` maps (N, 2) global x, y of the grid into the
    world's first (a reconstruction's frame: `cama_pipeline.evaluate.frame.ReconstructionFrame.world_of`), so
    that each cell takes the ground that stands where the reconstruction's frame puts it. TruthMismatch when the
    site cannot be rebuilt."""
    truth = stored_truth(site)
    cfg, world = rebuilt_world(site, truth)
    if world_of is None:
        origin = (
            georeference.origin_xy[0] - cfg.site_origin_xy[0],
            georeference.origin_xy[1] - cfg.site_origin_xy[1],
        )
        grid = ground_truth.BevGrid(origin, georeference.resolution, georeference.height, georeference.width)
        semantic, photometric, elevation = ground_truth.render_bev(world, grid)
        centres = cell_centres(georeference)
    else:
        centres = world_of(cell_centres(georeference))
        local = centres - np.asarray(cfg.site_origin_xy)
        label, albedo, height = ground_truth.render_points(
            world, local[:, 0], local[:, 1], georeference.resolution
        )
        semantic = label.reshape(georeference.shape)
        photometric = albedo.reshape(*georeference.shape, 3)
        elevation = height.reshape(georeference.shape)
    count = nearest_stored(truth, centres).reshape(georeference.shape)
    semantic[count == 0] = int(Semantic.UNOBSERVED)
    return BevRasters(
        georeference.as_raster(),
        semantic=semantic,
        photometric_rgb=photometric,
        elevation=elevation,
        observation_count=count,
    )


@dataclass(frozen=True, eq=False)
class TrueGround:
    """A site's generator world, rebuilt once and checked against its stored truth: the true ground's class and
    height at any global point, not only at cell centres."""

    config: SynthConfig
    world: World
    truth: BevRasters

    @classmethod
    def of(cls, site: Path) -> "TrueGround":
        """The site's true ground; TruthMismatch when the site cannot be rebuilt."""
        truth = stored_truth(site)
        config, world = rebuilt_world(site, truth)
        return cls(config, world, truth)

    def _local(self, xy: np.ndarray) -> np.ndarray:
        return np.asarray(xy, dtype=np.float64)[:, :2] - np.asarray(self.config.site_origin_xy)

    def _classes(self, local: np.ndarray) -> torch.Tensor:
        x, y = torch.from_numpy(local.astype(np.float32)).unbind(dim=1)
        return self.world.atlas.nearest(self.world.atlas.label, x, y)

    def label(self, xy: np.ndarray) -> np.ndarray:
        """(N,) uint8 the true class at (N, 2) global x, y; unobserved (255) where the stored truth's nearest cell
        is (no key-frame camera looked) or where it has none."""
        labels = self._classes(self._local(xy)).numpy().astype(np.uint8)
        observed = nearest_stored(self.truth, np.asarray(xy, dtype=np.float64)[:, :2]) > 0
        return np.where(observed, labels, np.uint8(Semantic.UNOBSERVED))

    def height_of(self, classes: tuple[int, ...] = ROAD_SURFACE_IDS) -> Callable[[np.ndarray], np.ndarray]:
        """A function from (N, 2) global x, y to the true ground height there (N,), raised sidewalks and kerbs
        included, NaN where the ground's class is not one of `classes` (by default the road surface: road, lane
        marking, crosswalk)."""
        wanted = torch.tensor([int(c) for c in classes])

        def height(xy: np.ndarray) -> np.ndarray:
            local = self._local(xy)
            kept = torch.isin(self._classes(local), wanted)
            x, y = torch.from_numpy(local).unbind(dim=1)
            return torch.where(kept, self.world.ground_height(x, y), torch.nan).numpy()

        return height


def cell_centres(georeference: RasterGeoreference) -> np.ndarray:
    """(rows * cols, 2) global x, y of every cell centre, row by row."""
    rows, cols = np.indices(georeference.shape)
    return georeference.global_from_pixel(np.column_stack([cols.ravel(), rows.ravel()]))


def nearest_true_cells(xy: np.ndarray, truth: BevRasters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) whether each global x, y falls on the `truth` raster, and the (row, col) of its nearest cell (0
    outside)."""
    geo = truth.georeference
    colrow = np.round(geo.pixel_from_global(xy)).astype(np.int64)
    col, row = colrow[:, 0], colrow[:, 1]
    inside = (row >= 0) & (row < geo.height) & (col >= 0) & (col < geo.width)
    return inside, np.where(inside, row, 0), np.where(inside, col, 0)


def nearest_stored(truth: BevRasters, xy: np.ndarray) -> np.ndarray:
    """(N,) uint16: the stored truth's observation count at the stored cell nearest each global (x, y), 0 where
    that cell is unobserved or there is none (the count is a coverage map on a 0.5 m grid)."""
    inside, row, col = nearest_true_cells(xy, truth)
    observed = inside & (truth.require("semantic")[row, col] != int(Semantic.UNOBSERVED))
    count = np.maximum(truth.require("observation_count")[row, col], 1).astype(np.uint16)
    return np.where(observed, count, 0).astype(np.uint16)
