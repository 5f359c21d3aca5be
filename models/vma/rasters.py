"""Reading a site's BEV rasters (semantic, photometric, georeference) and checking them before any model sees them.

A raster folder holds `semantic.png` (uint8 ids 0-4, 255 unobserved; DESIGN.md), `photometric.png` (BGR) and
`georeference.json` (pixel (0, 0) centre `origin_xy` in global metres, `resolution` m/px, rows grow with -y).
A site folder is either such a raster folder or a generated site whose rasters are in `ground_truth/bev/`;
its vectors (for training and evaluation) are `ground_truth/vector_map.json` or `vector_map.json` beside.
"""

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.semantics import BEV_CLASSES, Semantic

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
    origin_xy: tuple[float, float]
    """Global metres of pixel (0, 0)'s centre."""
    resolution_m: float
    name: str = "site"

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in pixels."""
        return (int(self.semantic.shape[0]), int(self.semantic.shape[1]))

    def global_from_pixel(self, colrow: np.ndarray) -> np.ndarray:
        """Pixel (col, row), fractional, to global x, y."""
        colrow = np.asarray(colrow, dtype=np.float64).reshape(-1, 2)
        x = self.origin_xy[0] + colrow[:, 0] * self.resolution_m
        y = self.origin_xy[1] - colrow[:, 1] * self.resolution_m
        return np.column_stack([x, y])

    def pixel_from_global(self, xy: np.ndarray) -> np.ndarray:
        """Global x, y to pixel (col, row), fractional."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        col = (xy[:, 0] - self.origin_xy[0]) / self.resolution_m
        row = (self.origin_xy[1] - xy[:, 1]) / self.resolution_m
        return np.column_stack([col, row])

    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the raster's pixel centres, global metres."""
        h, w = self.shape
        x0, y0 = self.origin_xy
        return (x0, x0 + (w - 1) * self.resolution_m, y0 - (h - 1) * self.resolution_m, y0)

    def area_km2(self) -> float:
        """Raster area in square kilometres."""
        h, w = self.shape
        return h * w * self.resolution_m**2 / 1e6


def raster_dir_of(site: Path) -> Path:
    """The folder with a site's rasters: `site` itself or its `ground_truth/bev/`."""
    site = Path(site)
    for candidate in (site, site / "ground_truth" / "bev"):
        if (candidate / "georeference.json").is_file():
            return candidate
    raise FileNotFoundError(f"{site}: no georeference.json here or in ground_truth/bev/ (not a site folder)")


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
    geo_path = folder / "georeference.json"
    origin_xy, resolution, width, height = _read_georeference(geo_path)
    semantic = _read_image(folder / "semantic.png", cv2.IMREAD_UNCHANGED)
    if semantic.ndim != 2 or semantic.dtype != np.uint8:
        raise SiteInputError(f"{folder / 'semantic.png'}: must be a single-channel 8-bit image")
    photometric_bgr = _read_image(folder / "photometric.png", cv2.IMREAD_COLOR)
    for name, image in (("semantic.png", semantic), ("photometric.png", photometric_bgr)):
        if image.shape[:2] != (height, width):
            raise SiteInputError(
                f"{geo_path}: width x height {width} x {height} does not match {name} "
                f"({image.shape[1]} x {image.shape[0]}); wrong georeference for these rasters"
            )
    unknown = sorted(set(np.unique(semantic).tolist()) - KNOWN_IDS)
    if unknown:
        raise SiteInputError(
            f"{folder / 'semantic.png'}: unknown semantic ids {unknown[:10]}, expected {sorted(KNOWN_IDS)}"
        )
    observed = semantic != int(Semantic.UNOBSERVED)
    if not np.any(observed & (semantic != int(Semantic.BACKGROUND))):
        raise SiteInputError(f"{folder / 'semantic.png'}: empty site, no road or marking cell observed")
    name = Path(site).name or "site"
    rasters = SiteRasters(
        semantic, cv2.cvtColor(photometric_bgr, cv2.COLOR_BGR2RGB), origin_xy, resolution, name
    )
    logger.info("read %s rasters %dx%d at %.2f m/px", name, width, height, resolution)
    return rasters


def _read_georeference(path: Path) -> tuple[tuple[float, float], float, int, int]:
    """origin_xy, resolution, width, height of a raster georeference, each checked."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise SiteInputError(f"{path}: not valid JSON: {err}") from None
    try:
        origin = [float(v) for v in data["origin_xy"]]
        resolution = float(data["resolution"])
        width, height = int(data["width"]), int(data["height"])
    except (KeyError, TypeError, ValueError) as err:
        raise SiteInputError(f"{path}: needs origin_xy [x, y], resolution, width, height: {err!r}") from None
    if len(origin) != 2 or not np.isfinite(origin).all():
        raise SiteInputError(f"{path}: origin_xy must be two finite numbers, got {data['origin_xy']}")
    if not (np.isfinite(resolution) and resolution > 0):
        raise SiteInputError(f"{path}: resolution must be > 0 m/px, got {resolution}")
    if data.get("row_axis", "-y") != "-y" or data.get("col_axis", "+x") != "+x":
        raise SiteInputError(f"{path}: row_axis/col_axis must be '-y'/'+x' (DESIGN.md raster convention)")
    return (origin[0], origin[1]), resolution, width, height


def _read_image(path: Path, flags: int) -> np.ndarray:
    """cv2.imread that raises naming the file."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    image = cv2.imread(str(path), flags)
    if image is None:
        raise SiteInputError(f"{path}: not a readable image")
    return image


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
