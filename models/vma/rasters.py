"""Reading a site's BEV rasters (semantic, photometric, georeference) and checking them before any model sees them.

A site folder is either a raster folder (`cama_pipeline.bev`; the model reads its semantic and photometric
layers) or a generated site whose rasters are in `ground_truth/bev/`; its vectors (for training and
evaluation) are `ground_truth/vector_map.json` or `vector_map.json` beside.
"""

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.bev import RasterGeoreference, is_raster_folder, layer_path, read_bev
from cama_pipeline.semantics import BEV_CLASSES, Semantic
from cama_pipeline.surface.outputs import is_surface_bev

logger = logging.getLogger(__name__)

KNOWN_IDS: frozenset[int] = frozenset(int(c) for c in BEV_CLASSES) | {int(Semantic.UNOBSERVED)}
"""Semantic ids a BEV raster may hold."""
NUM_SEMANTIC = len(BEV_CLASSES)
"""One-hot channels of the model input (unobserved cells are all-zero)."""


class SiteInputError(ValueError):
    """A site raster or vector file that cannot be used; the message names the file and field."""


@dataclass(frozen=True, eq=False)
class SiteRasters:
    """The BEV rasters of one site with their georeference (global metres)."""

    semantic: np.ndarray
    """(H, W) uint8 semantic ids."""
    photometric: np.ndarray
    """(H, W, 3) uint8 RGB."""
    georeference: RasterGeoreference
    name: str = "site"
    reconstructed: bool = False
    """Whether these are a surface stage's rasters (`is_surface_bev`), not a generator's clean ones: proposers
    read boundaries differently there (smeared curbs)."""

    def __post_init__(self) -> None:
        if (
            self.semantic.shape[:2] != self.georeference.shape
            or self.photometric.shape[:2] != self.georeference.shape
        ):
            raise ValueError(
                f"{self.name}: semantic {self.semantic.shape} / photometric {self.photometric.shape} rasters do "
                f"not match the georeference (height, width) {self.georeference.shape}"
            )

    @property
    def origin_xy(self) -> tuple[float, float]:
        """Global metres of pixel (0, 0)'s centre."""
        return self.georeference.origin_xy

    @property
    def resolution_m(self) -> float:
        """Metres per pixel."""
        return self.georeference.resolution

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in pixels."""
        return (int(self.semantic.shape[0]), int(self.semantic.shape[1]))

    def global_from_pixel(self, colrow: np.ndarray) -> np.ndarray:
        """Pixel (col, row), fractional, to global x, y."""
        return self.georeference.global_from_pixel(colrow)

    def pixel_from_global(self, xy: np.ndarray) -> np.ndarray:
        """Global x, y to pixel (col, row), fractional."""
        return self.georeference.pixel_from_global(xy)

    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the raster's pixel centres, global metres."""
        return self.georeference.extent()

    def area_km2(self) -> float:
        """Raster area in square kilometres."""
        h, w = self.shape
        return h * w * self.resolution_m**2 / 1e6


def raster_dir_of(site: Path) -> Path:
    """The folder with a site's rasters: `site` itself or its `ground_truth/bev/`."""
    site = Path(site)
    for candidate in (site, site / "ground_truth" / "bev"):
        if is_raster_folder(candidate):
            return candidate
    raise FileNotFoundError(f"{site}: no BEV rasters here or in ground_truth/bev/ (not a site folder)")


def vector_map_of(site: Path) -> Path:
    """A site's vector map file: `ground_truth/vector_map.json`, or `vector_map.json` beside the rasters."""
    site = Path(site)
    for candidate in (site / "ground_truth" / "vector_map.json", site / "vector_map.json"):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"{site}: no vector_map.json in ground_truth/ or beside the rasters")


def load_site_rasters(site: Path) -> SiteRasters:
    """Read and check a site's semantic and photometric rasters and georeference; SiteInputError naming the file."""
    folder = raster_dir_of(site)
    try:
        bev = read_bev(folder, ("semantic", "photometric"))
    except ValueError as err:
        raise SiteInputError(str(err)) from None
    semantic, where = bev.require("semantic"), layer_path(folder, "semantic")
    unknown = sorted(set(np.unique(semantic).tolist()) - KNOWN_IDS)
    if unknown:
        raise SiteInputError(f"{where}: unknown semantic ids {unknown[:10]}, expected {sorted(KNOWN_IDS)}")
    observed = semantic != int(Semantic.UNOBSERVED)
    if not np.any(observed & (semantic != int(Semantic.BACKGROUND))):
        raise SiteInputError(f"{where}: empty site, no road or marking cell observed")
    name = Path(site).name or "site"
    rasters = SiteRasters(
        semantic, bev.require("photometric"), bev.georeference, name, reconstructed=is_surface_bev(folder)
    )
    geo = bev.georeference
    logger.info("read %s rasters %dx%d at %.2f m/px", name, geo.width, geo.height, geo.resolution)
    return rasters


def model_input(rasters: SiteRasters, resolution_m: float) -> np.ndarray:
    """(C, H', W') float32 model input at `resolution_m`: area-averaged one-hot semantics, then RGB in [0, 1]."""
    scale = rasters.resolution_m / resolution_m
    h, w = rasters.shape
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    channels = []
    for cls in range(NUM_SEMANTIC):
        one_hot = (rasters.semantic == cls).astype(np.float32)
        channels.append(cv2.resize(one_hot, size, interpolation=cv2.INTER_AREA) if scale != 1 else one_hot)
    rgb = np.asarray(rasters.photometric, dtype=np.float32) / 255.0
    if scale != 1:
        rgb = np.asarray(cv2.resize(rgb, size, interpolation=cv2.INTER_AREA), dtype=np.float32)
    return np.concatenate([np.stack(channels), rgb.transpose(2, 0, 1)], axis=0)
