"""A BEV raster folder: its files, their formats and the raster georeference. This module is the only one that
names these files or parses `georeference.json`; every writer and reader of raster folders goes through it.

A raster folder (the surface stage's `surface/<site_id>/bev/`, a generated site's `ground_truth/bev/`) holds:
    semantic.png           uint8 class ids 0-4 (`cama_pipeline.semantics.BEV_CLASSES`), 255 where unobserved
    photometric.png        8-bit colour, black where unobserved (stored BGR as OpenCV writes it; RGB in memory)
    elevation.npy          float32 global z in metres, NaN where unobserved
    observation_count.png  uint16 camera rays that hit each cell (the surface stage and the generator write it)
    georeference.json      RasterGeoreference, pretty-printed (indent 2) and written last: a folder with it is
                           complete. {"origin_xy": [x, y] (pixel (0, 0) centre, global m), "resolution": m/px,
                           "width", "height", "frame": "global", "row_axis": "-y", "col_axis": "+x"}
A folder may hold only some layers (a training site has no elevation); readers ask for the layers they need.
Pixels (col, row) have their centres at integers; columns grow with +x and rows with -y (DESIGN.md).
"""

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Self

import cv2
import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from cama_pipeline.io import atomic_write_image, atomic_write_json, atomic_write_npy

LayerName = Literal["semantic", "photometric", "elevation", "observation_count"]
LAYER_NAMES: tuple[LayerName, ...] = ("semantic", "photometric", "elevation", "observation_count")
LAYER_FILES: dict[LayerName, str] = {
    "semantic": "semantic.png",
    "photometric": "photometric.png",
    "elevation": "elevation.npy",
    "observation_count": "observation_count.png",
}
GEOREFERENCE_FILE = "georeference.json"


class RasterGeoreference(BaseModel):
    """Where a BEV raster's pixels lie in the global frame (DESIGN.md raster convention)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    origin_xy: tuple[float, float] = Field(description="Global metres of raster pixel (0, 0)'s centre.")
    resolution: float = Field(gt=0.0, description="Metres per pixel.")
    width: int = Field(ge=1, description="Raster columns.")
    height: int = Field(ge=1, description="Raster rows.")
    frame: Literal["global"] = "global"
    row_axis: Literal["-y"] = "-y"
    col_axis: Literal["+x"] = "+x"

    @property
    def shape(self) -> tuple[int, int]:
        """Raster shape as numpy orders it: (height, width)."""
        return (self.height, self.width)

    def pixel_from_global(self, xy: ArrayLike) -> np.ndarray:
        """Global x, y (N, 2+; further columns ignored) to pixel (col, row), fractional."""
        xy = _columns(xy)
        col = (xy[:, 0] - self.origin_xy[0]) / self.resolution
        row = (self.origin_xy[1] - xy[:, 1]) / self.resolution
        return np.column_stack([col, row])

    def global_from_pixel(self, colrow: ArrayLike) -> np.ndarray:
        """Pixel (col, row), fractional (N, 2), to global x, y."""
        colrow = _columns(colrow)
        x = self.origin_xy[0] + colrow[:, 0] * self.resolution
        y = self.origin_xy[1] - colrow[:, 1] * self.resolution
        return np.column_stack([x, y])

    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the pixel centres, global metres."""
        x0, y0 = self.origin_xy
        return (x0, x0 + (self.width - 1) * self.resolution, y0 - (self.height - 1) * self.resolution, y0)

    def as_raster(self) -> "RasterGeoreference":
        """The plain raster georeference (a subclass, such as annotations' Georeference, adds fields)."""
        return self if type(self) is RasterGeoreference else RasterGeoreference.model_validate(self.to_json())

    def to_json(self) -> dict[str, Any]:
        """The `georeference.json` object (the raster fields only), keys in file order."""
        return self.model_dump(mode="json", include=set(RasterGeoreference.model_fields))

    @classmethod
    def from_json(cls, data: Any, *, source: str = GEOREFERENCE_FILE) -> Self:
        """Validate a parsed georeference object; ValueError naming `source` and each bad field."""
        try:
            return cls.model_validate(data)
        except ValidationError as error:
            raise ValueError(f"{source}: invalid raster georeference: {_problems(error)}") from None

    @classmethod
    def read(cls, path: Path) -> Self:
        """Read a `georeference.json`; FileNotFoundError, or ValueError naming the file and field."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: file not found")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise ValueError(f"{path}: not valid JSON: {error}") from None
        return cls.from_json(data, source=str(path))

    def write(self, path: Path) -> None:
        """Write as `georeference.json` (indent 2), atomically."""
        atomic_write_json(path, self.to_json(), indent=2)


def _columns(points: ArrayLike) -> np.ndarray:
    """`points` as a float64 (N, k >= 2) array; one point may be given flat."""
    array = np.asarray(points, dtype=np.float64)
    array = array.reshape(1, -1) if array.ndim == 1 else array
    if array.ndim != 2 or array.shape[1] < 2:
        raise ValueError(f"points: expected an (N, 2) array, got shape {np.shape(points)}")
    return array


def _problems(error: ValidationError) -> str:
    """`origin_xy: ...; resolution: ...`: each failed field with pydantic's reason."""
    parts = []
    for item in error.errors():
        loc = ".".join(str(part) for part in item["loc"]) or "(root)"
        parts.append(f"{loc}: {item['msg']}")
    return "; ".join(parts)


@dataclass(frozen=True, eq=False)
class BevRasters:
    """The layers of one raster folder (None: not present or not read) and their georeference."""

    georeference: RasterGeoreference
    semantic: np.ndarray | None = None
    """(H, W) uint8 class ids, 255 unobserved."""
    photometric_rgb: np.ndarray | None = None
    """(H, W, 3) uint8 RGB, black unobserved."""
    elevation: np.ndarray | None = None
    """(H, W) float32 global z (m), NaN unobserved."""
    observation_count: np.ndarray | None = None
    """(H, W) uint16 camera rays per cell."""

    def __post_init__(self) -> None:
        for name in self.layers():
            _check_layer(name, self.require(name), self.georeference, f"layer {name}", "georeference")

    def layer(self, name: LayerName) -> np.ndarray | None:
        """One layer by name (photometric in RGB), None when absent."""
        layers = {
            "semantic": self.semantic,
            "photometric": self.photometric_rgb,
            "elevation": self.elevation,
            "observation_count": self.observation_count,
        }
        return layers[name]

    def require(self, name: LayerName) -> np.ndarray:
        """One layer that must be present; ValueError naming it otherwise."""
        layer = self.layer(name)
        if layer is None:
            raise ValueError(f"layer {name}: not in these rasters ({', '.join(self.layers())})")
        return layer

    def layers(self) -> tuple[LayerName, ...]:
        """The names of the layers present."""
        return tuple(name for name in LAYER_NAMES if self.layer(name) is not None)


def _check_layer(
    name: LayerName, layer: np.ndarray, geo: RasterGeoreference, where: str, geo_where: str
) -> None:
    """ValueError naming `where` (the layer) or `geo_where` (its georeference) when a layer's dtype or shape
    breaks the format or does not fit the georeference."""
    if name == "semantic" and (layer.ndim != 2 or layer.dtype != np.uint8):
        raise ValueError(f"{where}: must be a single-channel 8-bit image, got {layer.dtype} {layer.shape}")
    if name == "photometric" and (layer.ndim != 3 or layer.shape[2] != 3 or layer.dtype != np.uint8):
        raise ValueError(f"{where}: must be an 8-bit 3-channel image, got {layer.dtype} {layer.shape}")
    if name in ("elevation", "observation_count") and layer.ndim != 2:
        raise ValueError(f"{where}: must be a 2D raster, got shape {layer.shape}")
    if layer.shape[:2] != geo.shape:
        raise ValueError(
            f"{geo_where}: width x height {geo.width} x {geo.height} does not match {where} "
            f"({layer.shape[1]} x {layer.shape[0]}); wrong georeference for these rasters"
        )


def layer_path(folder: Path, name: LayerName) -> Path:
    """Where layer `name` is stored in a raster folder."""
    return Path(folder) / LAYER_FILES[name]


def georeference_path(folder: Path) -> Path:
    """Where a raster folder's georeference is stored."""
    return Path(folder) / GEOREFERENCE_FILE


def is_raster_folder(folder: Path) -> bool:
    """Whether `folder` holds a (complete) raster folder: its georeference is written last."""
    return georeference_path(folder).is_file()


def present_layers(folder: Path) -> tuple[LayerName, ...]:
    """The layers whose files exist in `folder`, in LAYER_NAMES order."""
    return tuple(name for name in LAYER_NAMES if layer_path(folder, name).is_file())


def read_georeference(folder: Path) -> RasterGeoreference:
    """A raster folder's georeference; FileNotFoundError, or ValueError naming the file and field."""
    return RasterGeoreference.read(georeference_path(folder))


def read_layer(folder: Path, name: LayerName, *, mmap: bool = False) -> np.ndarray:
    """One layer file as stored (photometric converted to RGB), unchecked against the georeference;
    `mmap` memory-maps the elevation. FileNotFoundError, or ValueError naming the file."""
    path = layer_path(folder, name)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    if name == "elevation":
        try:
            return np.load(path, mmap_mode="r" if mmap else None, allow_pickle=False)
        except (ValueError, EOFError, OSError) as error:
            raise ValueError(f"{path}: not a readable .npy raster: {error}") from None
    image = cv2.imread(str(path), cv2.IMREAD_COLOR if name == "photometric" else cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError(f"{path}: not a readable image")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if name == "photometric" else image


def read_bev(folder: Path, layers: Iterable[LayerName] = LAYER_NAMES, *, mmap: bool = False) -> BevRasters:
    """Read the georeference and `layers` of a raster folder, each checked against the format and the
    georeference; FileNotFoundError for a missing file, ValueError naming the file and field otherwise."""
    folder = Path(folder)
    geo = read_georeference(folder)
    read: dict[str, np.ndarray] = {}
    for name in layers:
        layer = read_layer(folder, name, mmap=mmap)
        _check_layer(name, layer, geo, str(layer_path(folder, name)), str(georeference_path(folder)))
        read["photometric_rgb" if name == "photometric" else name] = layer
    return BevRasters(geo, **read)


def write_bev(folder: Path, rasters: BevRasters) -> None:
    """Write the layers present, then the georeference (each file atomically). The old georeference is removed
    first, so a folder is never complete (`is_raster_folder`) with layers of two different writes."""
    folder = Path(folder)
    georeference_path(folder).unlink(missing_ok=True)
    for name in rasters.layers():
        layer = rasters.require(name)
        path = layer_path(folder, name)
        if name == "elevation":
            atomic_write_npy(path, layer)
        elif name == "photometric":
            atomic_write_image(path, cv2.cvtColor(layer, cv2.COLOR_RGB2BGR))
        else:
            atomic_write_image(path, layer)
    rasters.georeference.write(georeference_path(folder))
