"""BEV-only synthetic sites for training and held-out evaluation: rasters and vector map, no camera images.

Rendering camera images is slow and the VMA only reads BEV rasters, so this builds a generator site with a
layout drawn from `seed` (road lengths, lanes, curve, cross roads vary) and writes only what `cama synth`
writes under `ground_truth/` for it (every cell observed). Seeds name sites: disjoint seed ranges give
location-disjoint training and held-out sets.
"""

import dataclasses
import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from cama_pipeline.bev import BevRasters, is_raster_folder, write_bev
from cama_pipeline.io import atomic_write_json
from cama_pipeline.synthetic import ground_truth as gt
from cama_pipeline.synthetic.config import LayoutConfig, SynthConfig
from cama_pipeline.synthetic.site_model import build_synthetic_site

logger = logging.getLogger(__name__)

BEV_PRESET = "vma"
"""The preset name in a BEV-only site's manifest."""
MANIFEST = "manifest.json"


def layout_for_seed(seed: int) -> LayoutConfig:
    """A varied but valid road layout drawn from `seed`."""
    rng = np.random.default_rng([seed, 77])
    cross_x: tuple[float, ...] = (0.0,)
    if rng.random() < 0.4:
        cross_x = (float(-rng.uniform(55.0, 80.0)), 0.0)
    return replace(
        LayoutConfig(),
        main_west_length_m=float(rng.uniform(40.0, 90.0)),
        main_east_length_m=float(rng.uniform(25.0, 60.0)),
        curve_radius_m=float(rng.uniform(30.0, 60.0)),
        curve_angle_deg=float(rng.uniform(30.0, 90.0)),
        curve_exit_length_m=float(rng.uniform(10.0, 35.0)),
        cross_road_x_m=cross_x,
        cross_road_half_length_m=float(rng.uniform(35.0, 60.0)),
        main_lanes_per_direction=int(rng.integers(1, 4)),
        cross_lanes_per_direction=int(rng.integers(1, 3)),
        lane_width_m=float(rng.uniform(3.0, 3.75)),
        bike_lane_width_m=float(rng.uniform(1.5, 2.0)),
        crosswalk_depth_m=float(rng.uniform(3.0, 5.0)),
    )


def bev_site_config(seed: int, resolution_m: float = 0.1) -> SynthConfig:
    """The generator config of the BEV-only site of `seed`: its own layout and its own location."""
    return SynthConfig(
        preset=BEV_PRESET,
        seed=seed,
        layout=layout_for_seed(seed),
        bev_resolution_m=resolution_m,
        location=f"synth-vma-{seed}",
    )


def bev_site_manifest(cfg: SynthConfig) -> dict[str, object]:
    """`manifest.json` of a BEV-only site: what names it as a place (`cama_pipeline.site_identity`)."""
    return {
        "preset": cfg.preset,
        "seed": cfg.seed,
        "location": cfg.log_location,
        "config": dataclasses.asdict(cfg),
    }


def write_bev_site(seed: int, out_dir: Path, *, resolution_m: float = 0.1, overwrite: bool = False) -> Path:
    """Write `<out_dir>/ground_truth/{vector_map.json, bev/...}` and `manifest.json` for the site of `seed`; skip
    what is already there (a site written before manifests named their place gets its manifest)."""
    out_dir = Path(out_dir)
    bev = out_dir / "ground_truth" / "bev"
    cfg = bev_site_config(seed, resolution_m)
    manifest = bev_site_manifest(cfg)
    if is_raster_folder(bev) and not overwrite:
        if read_manifest(out_dir) != json.loads(json.dumps(manifest)):
            atomic_write_json(out_dir / MANIFEST, manifest, indent=2)
        logger.info("%s is up to date; nothing to do", out_dir)
        return out_dir
    site = build_synthetic_site(cfg)
    gt_dir = out_dir / "ground_truth"
    atomic_write_json(
        gt_dir / "vector_map.json", {"elements": gt.vector_map(site.layout, site.world, cfg.site_origin_xy)}
    )
    atomic_write_json(out_dir / MANIFEST, manifest, indent=2)
    grid = gt.bev_grid_for(site.world, resolution_m)
    semantic, photometric, elevation = gt.render_bev(site.world, grid)
    # its georeference, written last, marks the site complete
    write_bev(bev, BevRasters(grid.georeference(cfg.site_origin_xy), semantic, photometric, elevation))
    logger.info("wrote BEV site of seed %d to %s", seed, out_dir)
    return out_dir


def read_manifest(site: Path) -> object:
    """The parsed `manifest.json` of a site folder; None when it is missing or not JSON."""
    try:
        return json.loads((Path(site) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def ensure_bev_sites(seeds: list[int], root: Path) -> list[Path]:
    """`<root>/seed-<seed>` for each seed, generated where missing."""
    return [write_bev_site(seed, Path(root) / f"seed-{seed}") for seed in seeds]
