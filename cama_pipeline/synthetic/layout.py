"""The synthetic site's road network in 2D: road surface, sidewalks, paint, and the true vector map.

Coordinates here are layout-local metres (x east, y north); `SynthConfig.site_origin_xy` shifts them to
global coordinates when written out. The main road runs along y = 0 and curves north at its east end;
each cross road runs along x = const and makes a 4-way intersection with zebra crossings.
"""

from dataclasses import dataclass
from typing import Literal

import numpy as np
from shapely import affinity
from shapely.geometry import LineString, MultiLineString, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import linemerge, unary_union

from cama_pipeline.synthetic.config import LayoutConfig
from cama_pipeline.synthetic.geometry2d import arc_points, dashes

VectorClass = Literal["divider", "ped_crossing", "boundary"]
PaintColor = Literal["white", "yellow"]
DividerStyle = Literal["solid", "dashed", "double_solid"]

CORNER_RADIUS_M = 6.0
STOP_GAP_M = 1.5
DOUBLE_LINE_SEPARATION_M = 0.3


@dataclass(frozen=True)
class MapElement:
    """One true map element: a divider or boundary polyline, or a crosswalk polygon (layout coordinates)."""

    index: int
    cls: VectorClass
    geometry: LineString | Polygon
    color: PaintColor | None = None
    style: DividerStyle | None = None


@dataclass(frozen=True)
class PaintPatch:
    """A painted polygon on the road and the map element it belongs to."""

    polygon: Polygon
    element_index: int
    color: PaintColor


@dataclass(frozen=True)
class RoadLayout:
    """Everything 2D about the site: surfaces, paint, true elements, lanes for traffic, and baseline extras."""

    config: LayoutConfig
    road: BaseGeometry
    sidewalk: BaseGeometry
    curb_strip: BaseGeometry
    elements: tuple[MapElement, ...]
    paint: tuple[PaintPatch, ...]
    unpainted_dividers: tuple[LineString, ...]
    """Lane edges with no paint (the baseline 2D map wrongly has dividers there)."""
    lanes: dict[str, LineString]
    """Traffic lanes by name, e.g. `main_east_0`, `main_west_1`, `cross0_north_0`, oriented in driving direction."""
    main_centerline: LineString
    cross_centerlines: tuple[LineString, ...]

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(minx, miny, maxx, maxy) of everything built, sidewalks included."""
        return unary_union([self.road, self.sidewalk]).bounds

    def main_half_width(self) -> float:
        """Half width of the main road between curbs."""
        cfg = self.config
        return cfg.main_lanes_per_direction * cfg.lane_width_m + cfg.bike_lane_width_m

    def cross_half_width(self) -> float:
        """Half width of a cross road between curbs."""
        return self.config.cross_lanes_per_direction * self.config.lane_width_m


def build_layout(cfg: LayoutConfig) -> RoadLayout:
    """Build the site's roads, paint and true vector map from the layout config."""
    main = _main_centerline(cfg)
    h_main = cfg.main_lanes_per_direction * cfg.lane_width_m + cfg.bike_lane_width_m
    h_cross = cfg.cross_lanes_per_direction * cfg.lane_width_m
    crosses = tuple(
        LineString([(x, -cfg.cross_road_half_length_m), (x, cfg.cross_road_half_length_m)])
        for x in cfg.cross_road_x_m
    )
    road = _rounded_union(
        [main.buffer(h_main, cap_style="flat")] + [c.buffer(h_cross, cap_style="flat") for c in crosses]
    )
    outer = _rounded_union(
        [main.buffer(h_main + cfg.sidewalk_width_m, cap_style="flat")]
        + [c.buffer(h_cross + cfg.sidewalk_width_m, cap_style="flat") for c in crosses]
    )
    sidewalk = outer.difference(road)
    curb_strip = sidewalk.intersection(road.buffer(cfg.curb_width_m))

    builder = _ElementBuilder(cfg)
    keep_out_main, keep_out_cross = _intersection_zones(cfg, h_main, h_cross)
    for piece in _pieces(main.difference(keep_out_main)):
        builder.add_main_dividers(piece)
    for cross in crosses:
        for piece in _pieces(cross.difference(keep_out_cross)):
            builder.add_cross_dividers(piece)
    for xc in cfg.cross_road_x_m:
        builder.add_crosswalks(xc, h_main, h_cross)
    builder.add_boundaries(road, _end_caps(main, crosses, h_main, h_cross))
    return RoadLayout(
        config=cfg,
        road=road,
        sidewalk=sidewalk,
        curb_strip=curb_strip,
        elements=tuple(builder.elements),
        paint=tuple(builder.paint),
        unpainted_dividers=tuple(builder.unpainted),
        lanes=_lanes(cfg, main, crosses),
        main_centerline=main,
        cross_centerlines=crosses,
    )


def _main_centerline(cfg: LayoutConfig) -> LineString:
    """Main road: straight east along y = 0, then a left curve of `curve_radius_m`, then a straight exit."""
    x_west = min(cfg.cross_road_x_m) - cfg.main_west_length_m
    x_east = max(cfg.cross_road_x_m) + cfg.main_east_length_m
    r = cfg.curve_radius_m
    angle = np.radians(cfg.curve_angle_deg)
    arc = arc_points((x_east, r), r, -np.pi / 2, -np.pi / 2 + angle)
    heading = angle
    exit_end = arc[-1] + cfg.curve_exit_length_m * np.array([np.cos(heading), np.sin(heading)])
    pts = np.vstack([[x_west, 0.0], arc, exit_end])
    return LineString(pts)


def _rounded_union(parts: list[BaseGeometry]) -> BaseGeometry:
    """Union of road pieces with their inner corners rounded (closing by CORNER_RADIUS_M), as real curbs are."""
    return (
        unary_union(parts)
        .buffer(CORNER_RADIUS_M, join_style="round")
        .buffer(-CORNER_RADIUS_M, join_style="round")
    )


def _intersection_zones(
    cfg: LayoutConfig, h_main: float, h_cross: float
) -> tuple[BaseGeometry, BaseGeometry]:
    """Areas where dividers stop: the junction, its rounded corners, crosswalks and stop gaps."""
    reach_x = h_cross + CORNER_RADIUS_M + cfg.crosswalk_depth_m + STOP_GAP_M
    reach_y = h_main + CORNER_RADIUS_M + cfg.crosswalk_depth_m + STOP_GAP_M
    main_zone = unary_union(
        [box(xc - reach_x, -h_main - 1, xc + reach_x, h_main + 1) for xc in cfg.cross_road_x_m]
    )
    cross_zone = box(-1e4, -reach_y, 1e4, reach_y)
    return main_zone, cross_zone


def _pieces(geom: BaseGeometry) -> list[LineString]:
    """The LineStrings of a (Multi)LineString result, longest first, dropping slivers."""
    parts = list(geom.geoms) if isinstance(geom, MultiLineString) else [geom]
    return sorted((p for p in parts if isinstance(p, LineString) and p.length > 1.0), key=lambda p: -p.length)


def _end_caps(
    main: LineString, crosses: tuple[LineString, ...], h_main: float, h_cross: float
) -> BaseGeometry:
    """Thin boxes over the roads' open ends, where the road polygon's edge is not a curb."""
    caps = []
    for line, half in [(main, h_main)] + [(c, h_cross) for c in crosses]:
        for end, nxt in ((line.coords[0], line.coords[1]), (line.coords[-1], line.coords[-2])):
            direction = np.subtract(nxt, end)
            angle = np.degrees(np.arctan2(direction[1], direction[0]))
            cap = box(-0.05, -half - 0.5, 0.05, half + 0.5)
            caps.append(affinity.translate(affinity.rotate(cap, angle, origin=(0, 0)), end[0], end[1]))
    return unary_union(caps)


def _lanes(cfg: LayoutConfig, main: LineString, crosses: tuple[LineString, ...]) -> dict[str, LineString]:
    """Lane centre paths in driving direction (right-hand traffic: a road's right side carries its direction)."""
    lanes: dict[str, LineString] = {}
    w = cfg.lane_width_m
    for k in range(cfg.main_lanes_per_direction):
        lanes[f"main_east_{k}"] = main.offset_curve(-(k + 0.5) * w)
        lanes[f"main_west_{k}"] = main.offset_curve((k + 0.5) * w).reverse()
    for i, cross in enumerate(crosses):
        for k in range(cfg.cross_lanes_per_direction):
            lanes[f"cross{i}_north_{k}"] = cross.offset_curve(-(k + 0.5) * w)
            lanes[f"cross{i}_south_{k}"] = cross.offset_curve((k + 0.5) * w).reverse()
    return lanes


class _ElementBuilder:
    """Accumulates true map elements and their paint as the layout is built."""

    def __init__(self, cfg: LayoutConfig) -> None:
        self.cfg = cfg
        self.elements: list[MapElement] = []
        self.paint: list[PaintPatch] = []
        self.unpainted: list[LineString] = []

    def _add(
        self,
        cls: VectorClass,
        geom: LineString | Polygon,
        color: PaintColor | None = None,
        style: DividerStyle | None = None,
    ) -> int:
        index = len(self.elements)
        self.elements.append(MapElement(index, cls, geom, color, style))
        return index

    def _paint_line(self, index: int, line: LineString, color: PaintColor) -> None:
        self.paint.append(
            PaintPatch(line.buffer(self.cfg.marking_width_m / 2, cap_style="flat"), index, color)
        )

    def divider(self, line: LineString, color: PaintColor, style: DividerStyle, phase_m: float = 0.0) -> None:
        """Add a painted divider element and its paint."""
        index = self._add("divider", line, color, style)
        if style == "solid":
            self._paint_line(index, line, color)
        elif style == "double_solid":
            for side in (-0.5, 0.5):
                self._paint_line(index, line.offset_curve(side * DOUBLE_LINE_SEPARATION_M), color)
        else:
            for dash in dashes(line, self.cfg.dash_length_m, self.cfg.dash_gap_m, phase_m):
                self._paint_line(index, dash, color)

    def add_main_dividers(self, piece: LineString) -> None:
        """Centre double yellow, white dashed lane lines and white solid bike-lane lines on a main-road piece."""
        cfg = self.cfg
        w = cfg.lane_width_m
        is_west_arm = piece.bounds[2] < min(cfg.cross_road_x_m)
        west_arm_end_x = piece.bounds[2] if is_west_arm else None
        self.divider(piece, "yellow", "double_solid")
        for sign in (-1.0, 1.0):
            for k in range(1, cfg.main_lanes_per_direction):
                self.divider(piece.offset_curve(sign * k * w), "white", "dashed", phase_m=1.0)
            bike_line = piece.offset_curve(sign * cfg.main_lanes_per_direction * w)
            self._bike_line(bike_line, west_arm_end_x)

    def _bike_line(self, line: LineString, west_arm_end_x: float | None) -> None:
        """Bike-lane line; on the west arm it is left unpainted just before the junction (a real-world gap)."""
        if west_arm_end_x is None or self.cfg.unpainted_bike_line_m <= 0:
            self.divider(line, "white", "solid")
            return
        gap = box(west_arm_end_x - self.cfg.unpainted_bike_line_m, -1e4, west_arm_end_x + 1.0, 1e4)
        for part in _pieces(line.difference(gap)):
            self.divider(part, "white", "solid")
        self.unpainted.extend(_pieces(line.intersection(gap)))

    def add_cross_dividers(self, piece: LineString) -> None:
        """Centre yellow dashed and white dashed lane lines on a cross-road piece."""
        w = self.cfg.lane_width_m
        self.divider(piece, "yellow", "dashed")
        for sign in (-1.0, 1.0):
            for k in range(1, self.cfg.cross_lanes_per_direction):
                self.divider(piece.offset_curve(sign * k * w), "white", "dashed", phase_m=2.0)

    def add_crosswalks(self, xc: float, h_main: float, h_cross: float) -> None:
        """A zebra crossing on each of the four arms of the intersection at x = xc."""
        cfg = self.cfg
        near_x = h_cross + CORNER_RADIUS_M
        near_y = h_main + CORNER_RADIUS_M
        d = cfg.crosswalk_depth_m
        areas = [
            (box(xc - near_x - d, -h_main, xc - near_x, h_main), "y"),
            (box(xc + near_x, -h_main, xc + near_x + d, h_main), "y"),
            (box(xc - h_cross, near_y, xc + h_cross, near_y + d), "x"),
            (box(xc - h_cross, -near_y - d, xc + h_cross, -near_y), "x"),
        ]
        for area, across in areas:
            index = self._add("ped_crossing", area)
            for stripe in _zebra_stripes(area, across, cfg.stripe_width_m):
                self.paint.append(PaintPatch(stripe, index, "white"))

    def add_boundaries(self, road: BaseGeometry, caps: BaseGeometry) -> None:
        """Road boundaries: the curb lines of the road polygon, minus the open road ends."""
        edges = road.boundary.difference(caps.buffer(0.05))
        merged = linemerge(edges) if not isinstance(edges, LineString) else edges
        for piece in _pieces(merged):
            self._add("boundary", piece.simplify(0.02))


def _zebra_stripes(area: Polygon, across: str, stripe_m: float) -> list[Polygon]:
    """Stripes parallel to traffic, spaced across the road (`across` is the axis the crossing spans)."""
    minx, miny, maxx, maxy = area.bounds
    lo, hi = (minx, maxx) if across == "x" else (miny, maxy)
    starts = np.arange(lo + stripe_m / 2, hi - stripe_m, 2 * stripe_m)
    if across == "x":
        return [box(s, miny, s + stripe_m, maxy) for s in starts]
    return [box(minx, s, maxx, s + stripe_m) for s in starts]
