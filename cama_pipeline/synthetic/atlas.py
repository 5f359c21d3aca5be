"""The ground texture atlas: the road layout rasterised finely (labels, paint, instances, raised sidewalks).

The renderer and the ground-truth BEV rasters both sample it, so image labels, BEV labels and vector
elements agree by construction. Pixel (0, 0)'s centre is at `origin_xy` (layout-local metres); rows grow
with -y and columns with +x, as the DESIGN.md raster convention.
"""

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic
from cama_pipeline.synthetic.layout import RoadLayout

PAINT_NONE, PAINT_WHITE, PAINT_YELLOW = 0, 1, 2
_SUBPIXEL_BITS = 3


@dataclass(frozen=True)
class GroundAtlas:
    """Fine rasters of the ground: uint8 label / paint colour / paint alpha / raised, int32 instance."""

    origin_xy: tuple[float, float]
    texel_m: float
    label: torch.Tensor
    paint_color: torch.Tensor
    paint_alpha: torch.Tensor
    raised: torch.Tensor
    instance: torch.Tensor

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return int(self.label.shape[0]), int(self.label.shape[1])

    def to_pixel(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Continuous (col, row) of layout-local points (pixel centres at integers)."""
        return (x - self.origin_xy[0]) / self.texel_m, (self.origin_xy[1] - y) / self.texel_m

    def nearest(self, layer: torch.Tensor, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Nearest-texel lookup of an integer layer; points outside the atlas read 0."""
        col, row = self.to_pixel(x, y)
        rows, cols = self.shape
        ci = torch.round(col).long()
        ri = torch.round(row).long()
        inside = (ci >= 0) & (ci < cols) & (ri >= 0) & (ri < rows)
        flat = (ri.clamp(0, rows - 1) * cols + ci.clamp(0, cols - 1)).reshape(-1)
        values = layer.reshape(-1)[flat].reshape(x.shape)
        return torch.where(inside, values, torch.zeros_like(values))

    def bilinear(
        self, layer: torch.Tensor, x: torch.Tensor, y: torch.Tensor, scale: float = 1.0 / 255
    ) -> torch.Tensor:
        """Bilinear lookup of a uint8 layer as float in [0, 1] (edges clamp)."""
        col, row = self.to_pixel(x, y)
        rows, cols = self.shape
        c0 = torch.floor(col)
        r0 = torch.floor(row)
        fc = (col - c0).float()
        fr = (row - r0).float()
        c0 = c0.long().clamp(0, cols - 2)
        r0 = r0.long().clamp(0, rows - 2)
        flat = layer.reshape(-1)
        base = r0 * cols + c0
        v00, v01 = flat[base].float(), flat[base + 1].float()
        v10, v11 = flat[base + cols].float(), flat[base + cols + 1].float()
        top = v00 + (v01 - v00) * fc
        bottom = v10 + (v11 - v10) * fc
        return (top + (bottom - top) * fr) * scale


def build_atlas(layout: RoadLayout, texel_m: float, margin_m: float = 30.0) -> GroundAtlas:
    """Rasterise the layout into a ground atlas covering it plus `margin_m` on every side."""
    minx, miny, maxx, maxy = layout.bounds
    origin = (minx - margin_m, maxy + margin_m)
    cols = int(np.ceil((maxx - minx + 2 * margin_m) / texel_m)) + 1
    rows = int(np.ceil((maxy - miny + 2 * margin_m) / texel_m)) + 1
    raster = _Rasteriser(origin, texel_m, rows, cols)

    label = np.zeros((rows, cols), np.uint8)
    raised = np.zeros((rows, cols), np.uint8)
    paint_color = np.zeros((rows, cols), np.uint8)
    paint_alpha = np.zeros((rows, cols), np.uint8)
    instance = np.zeros((rows, cols), np.int32)

    raster.fill(raised, layout.sidewalk, 255)
    raster.fill(label, layout.road, int(Semantic.ROAD))
    raster.fill(label, layout.curb_strip, int(Semantic.CURB))
    for element in layout.elements:
        if element.cls == "boundary":
            strip = element.geometry.buffer(layout.config.curb_width_m).intersection(layout.curb_strip)
            raster.fill(instance, strip, int(Semantic.CURB) * INSTANCE_ID_BASE + element.index)
    for patch in layout.paint:
        cls = (
            Semantic.CROSSWALK
            if layout.elements[patch.element_index].cls == "ped_crossing"
            else Semantic.LANE_MARKING
        )
        raster.fill(label, patch.polygon, int(cls))
        raster.fill(paint_alpha, patch.polygon, 255)
        raster.fill(paint_color, patch.polygon, PAINT_YELLOW if patch.color == "yellow" else PAINT_WHITE)
        raster.fill(instance, patch.polygon, int(cls) * INSTANCE_ID_BASE + patch.element_index)
    return GroundAtlas(
        origin_xy=origin,
        texel_m=texel_m,
        label=torch.from_numpy(label),
        paint_color=torch.from_numpy(paint_color),
        paint_alpha=torch.from_numpy(paint_alpha),
        raised=torch.from_numpy(raised),
        instance=torch.from_numpy(instance),
    )


class _Rasteriser:
    """Fills shapely polygons into numpy rasters in the atlas's pixel frame (sub-pixel precise)."""

    def __init__(self, origin: tuple[float, float], texel_m: float, rows: int, cols: int) -> None:
        self.origin = origin
        self.texel_m = texel_m
        self.shape = (rows, cols)

    def _ring(self, coords: object) -> np.ndarray:
        xy = np.asarray(coords, dtype=np.float64)[:, :2]
        col = (xy[:, 0] - self.origin[0]) / self.texel_m
        row = (self.origin[1] - xy[:, 1]) / self.texel_m
        return np.round(np.stack([col, row], axis=1) * (1 << _SUBPIXEL_BITS)).astype(np.int32)

    def fill(self, image: np.ndarray, geom: BaseGeometry, value: int) -> None:
        """Set the pixels whose centres lie inside `geom` (holes respected) to `value`."""
        polygons = list(geom.geoms) if hasattr(geom, "geoms") else [geom]
        for polygon in polygons:
            if not isinstance(polygon, Polygon) or polygon.is_empty:
                continue
            rings = [self._ring(polygon.exterior.coords)] + [self._ring(r.coords) for r in polygon.interiors]
            cv2.fillPoly(image, rings, color=int(value), lineType=cv2.LINE_8, shift=_SUBPIXEL_BITS)
