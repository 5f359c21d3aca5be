"""Ground truth of a generated site, kept apart from the data set: 3D vector map, BEV rasters, baseline map.

BEV rasters follow DESIGN.md: `origin_xy` is pixel (0, 0)'s centre in global metres, rows grow with -y,
columns with +x; semantic ids 0-4 with 255 where no key-frame camera looked.
"""

from dataclasses import dataclass

import numpy as np
import torch
from shapely import affinity
from shapely.geometry import LineString, Polygon

from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic.geometry2d import resample
from cama_pipeline.synthetic.layout import RoadLayout
from cama_pipeline.synthetic.render import World
from cama_pipeline.synthetic.shading import ground_color

OBSERVATION_RANGE_M = 40.0
OBSERVATION_GRID_M = 0.5
BASELINE_OFFSET_M = (0.45, -0.3)
BASELINE_ROTATION_DEG = 0.12
VERTEX_SPACING_M = 1.0


@dataclass(frozen=True)
class BevGrid:
    """A raster grid in layout coordinates: pixel (0, 0) centre at `origin_xy`, `resolution_m` per pixel."""

    origin_xy: tuple[float, float]
    resolution_m: float
    rows: int
    cols: int

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """x (cols,) and y (rows,) of the cell centres."""
        x = self.origin_xy[0] + self.resolution_m * np.arange(self.cols)
        y = self.origin_xy[1] - self.resolution_m * np.arange(self.rows)
        return x, y

    def georeference(self, site_origin_xy: tuple[float, float]) -> RasterGeoreference:
        """The georeference in global coordinates."""
        return RasterGeoreference(
            origin_xy=(self.origin_xy[0] + site_origin_xy[0], self.origin_xy[1] + site_origin_xy[1]),
            resolution=self.resolution_m,
            width=self.cols,
            height=self.rows,
        )


def bev_grid_for(world: World, resolution_m: float) -> BevGrid:
    """The BEV grid covering the whole ground atlas."""
    rows, cols = world.atlas.shape
    extent_x = (cols - 1) * world.atlas.texel_m
    extent_y = (rows - 1) * world.atlas.texel_m
    return BevGrid(
        world.atlas.origin_xy,
        resolution_m,
        int(extent_y / resolution_m) + 1,
        int(extent_x / resolution_m) + 1,
    )


def render_bev(
    world: World, grid: BevGrid, chunk_rows: int = 256
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True semantic (uint8), photometric (RGB uint8, top-down albedo) and elevation (float32) rasters."""
    xs, ys = grid.cell_centres()
    semantic = np.zeros((grid.rows, grid.cols), np.uint8)
    photometric = np.zeros((grid.rows, grid.cols, 3), np.uint8)
    elevation = np.zeros((grid.rows, grid.cols), np.float32)
    for r0 in range(0, grid.rows, chunk_rows):
        yy, xx = np.meshgrid(ys[r0 : r0 + chunk_rows], xs, indexing="ij")
        label, albedo, height = render_points(world, xx.ravel(), yy.ravel(), grid.resolution_m)
        shape = xx.shape
        semantic[r0 : r0 + shape[0]] = label.reshape(shape)
        photometric[r0 : r0 + shape[0]] = albedo.reshape(*shape, 3)
        elevation[r0 : r0 + shape[0]] = height.reshape(shape)
    return semantic, photometric, elevation


def render_points(
    world: World, x: np.ndarray, y: np.ndarray, footprint_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The true label (N,) uint8, top-down albedo (N, 3) uint8 and ground height (N,) float32 at layout points
    (x, y), each seen over `footprint_m` (a cell's size)."""
    xt = torch.from_numpy(np.asarray(x, np.float32))
    yt = torch.from_numpy(np.asarray(y, np.float32))
    albedo, label, _ = ground_color(
        world.atlas, world.noise, xt, yt, torch.full_like(xt, footprint_m), world.look
    )
    height = world.ground_height(xt.double(), yt.double()).numpy().astype(np.float32)
    return label.numpy().astype(np.uint8), (albedo.numpy() * 255 + 0.5).astype(np.uint8), height


def observation_count(
    grid: BevGrid, elevation: np.ndarray, cameras: list[tuple[np.ndarray, np.ndarray, np.ndarray, int, int]]
) -> np.ndarray:
    """How many key-frame cameras see each cell within OBSERVATION_RANGE_M (no occlusion test), uint16.

    `cameras` holds (layout_from_cam_R, layout_from_cam_t, K, width, height) per key-frame image. Computed
    on a coarse grid and enlarged, which is plenty for a coverage map.
    """
    step = max(1, int(round(OBSERVATION_GRID_M / grid.resolution_m)))
    xs, ys = grid.cell_centres()
    yy, xx = np.meshgrid(ys[::step], xs[::step], indexing="ij")
    zz = elevation[::step, ::step]
    points = np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)
    count = np.zeros(points.shape[0], np.int32)
    for R, t, K, width, height in cameras:
        cam = (points - t) @ R
        near = (cam[:, 2] > 0.5) & (np.linalg.norm(cam, axis=1) < OBSERVATION_RANGE_M)
        uv = cam[near] @ K.T
        u, v = uv[:, 0] / uv[:, 2], uv[:, 1] / uv[:, 2]
        inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
        count[np.flatnonzero(near)[inside]] += 1
    coarse = count.reshape(yy.shape)
    full = np.repeat(np.repeat(coarse, step, axis=0), step, axis=1)[: grid.rows, : grid.cols]
    return full.astype(np.uint16)


def _line_with_z(world: World, coords: np.ndarray) -> list[list[float]]:
    """Vertices with the road-surface height (terrain, curbs excluded: elements lie on the road)."""
    x = torch.from_numpy(coords[:, 0].astype(np.float64))
    y = torch.from_numpy(coords[:, 1].astype(np.float64))
    z = world.terrain.height(x, y).numpy()
    return [[float(a), float(b), float(c)] for a, b, c in zip(coords[:, 0], coords[:, 1], z, strict=True)]


def vector_map(layout: RoadLayout, world: World, site_origin_xy: tuple[float, float]) -> list[dict]:
    """True map elements in global metres with elevation; polylines resampled to VERTEX_SPACING_M."""
    shift = np.array([site_origin_xy[0], site_origin_xy[1]])
    elements = []
    for element in layout.elements:
        geom = element.geometry
        if isinstance(geom, Polygon):
            coords = np.asarray(geom.exterior.coords)
        else:
            coords = resample(geom, VERTEX_SPACING_M)
        pts = _line_with_z(world, coords)
        pts = [[p[0] + shift[0], p[1] + shift[1], p[2]] for p in pts]
        elements.append(
            {
                "id": f"gt-{element.index:04d}",
                "index": element.index,
                "class": element.cls,
                "points": pts,
                "closed": isinstance(geom, Polygon),
                "color": element.color,
                "style": element.style,
            }
        )
    return elements


def baseline_map(layout: RoadLayout, site_origin_xy: tuple[float, float], rng: np.random.Generator) -> dict:
    """A flawed 2D map like the nuScenes map the paper criticises: no z, rule-based dividers over unpainted lane
    edges, one divider and one crosswalk missing, and a small global offset and rotation."""
    dividers = [e for e in layout.elements if e.cls == "divider"]
    crossings = [e for e in layout.elements if e.cls == "ped_crossing"]
    missing = {
        dividers[int(rng.integers(len(dividers)))].index,
        crossings[int(rng.integers(len(crossings)))].index,
    }
    centre = layout.main_centerline.centroid
    elements = []

    def place(geom: LineString | Polygon) -> list[list[float]]:
        moved = affinity.rotate(geom, BASELINE_ROTATION_DEG, origin=centre)
        moved = affinity.translate(
            moved, BASELINE_OFFSET_M[0] + site_origin_xy[0], BASELINE_OFFSET_M[1] + site_origin_xy[1]
        )
        coords = moved.exterior.coords if isinstance(moved, Polygon) else resample(moved, VERTEX_SPACING_M)
        return [[float(x), float(y)] for x, y in np.asarray(coords)[:, :2]]

    for element in layout.elements:
        if element.index not in missing:
            elements.append(
                {
                    "id": f"base-{element.index:04d}",
                    "class": element.cls,
                    "points": place(element.geometry),
                    "source": "survey",
                }
            )
    for k, line in enumerate(layout.unpainted_dividers):
        elements.append(
            {"id": f"base-rule-{k:02d}", "class": "divider", "points": place(line), "source": "rule"}
        )
    return {
        "elements": elements,
        "flaws": {
            "offset_m": list(BASELINE_OFFSET_M),
            "rotation_deg": BASELINE_ROTATION_DEG,
            "missing_ids": [f"gt-{i:04d}" for i in sorted(missing)],
            "rule_based_ids": [f"base-rule-{k:02d}" for k in range(len(layout.unpainted_dividers))],
            "has_elevation": False,
        },
    }


def unobserved_to_255(semantic: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The semantic raster with cells no camera saw set to Semantic.UNOBSERVED."""
    out = semantic.copy()
    out[count == 0] = int(Semantic.UNOBSERVED)
    return out
