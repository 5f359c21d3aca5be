"""Configuration of the synthetic driving-site generator, with the named presets tiny/default/large."""

import math
from dataclasses import dataclass, field, fields, replace
from typing import Literal

from cama_pipeline.synthetic.sensors import SensorNoiseConfig

PresetName = Literal["tiny", "default", "large"]
MAX_IMAGE_SIDE_PX = 4096
"""Largest image width or height the generator renders."""
STEEPEST_STREET_GRADE = 0.2
"""The steepest terrain `with_ramp` builds: 20 %, about the steepest streets vehicles drive."""


@dataclass(frozen=True)
class LayoutConfig:
    """The road network: one east-west main road crossed by north-south roads, its east end curving north."""

    main_west_length_m: float = 70.0
    """Length of the main road west of the first intersection."""
    main_east_length_m: float = 45.0
    """Straight length of the main road east of the last intersection, before the curve."""
    curve_radius_m: float = 45.0
    """Radius of the curve at the main road's east end (centreline)."""
    curve_angle_deg: float = 90.0
    """How far the curve turns (to the north)."""
    curve_exit_length_m: float = 25.0
    """Straight road after the curve."""
    cross_road_x_m: tuple[float, ...] = (0.0,)
    """x of each north-south cross road (each makes one 4-way intersection)."""
    cross_road_half_length_m: float = 60.0
    """Cross roads run from -this to +this in y."""
    main_lanes_per_direction: int = 2
    cross_lanes_per_direction: int = 2
    lane_width_m: float = 3.5
    bike_lane_width_m: float = 1.8
    """Bike lanes on both sides of the main road."""
    sidewalk_width_m: float = 3.5
    curb_height_m: float = 0.13
    curb_width_m: float = 0.2
    """Width of the curb strip labelled `curb` (top and face together)."""
    marking_width_m: float = 0.15
    dash_length_m: float = 3.0
    dash_gap_m: float = 6.0
    crosswalk_depth_m: float = 4.0
    stripe_width_m: float = 0.5
    unpainted_bike_line_m: float = 20.0
    """The bike-lane line is left unpainted for this length before the westmost intersection (the baseline
    2D map still has a divider there)."""
    building_setback_m: float = 2.0
    """Distance from the back of the sidewalk to building facades."""

    def __post_init__(self) -> None:
        for name in ("main_west_length_m", "main_east_length_m", "curve_radius_m", "lane_width_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"LayoutConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in (
            "dash_length_m",
            "dash_gap_m",
            "marking_width_m",
            "sidewalk_width_m",
            "crosswalk_depth_m",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"LayoutConfig.{name} must be > 0, got {getattr(self, name)}")
        if not 0 < self.curve_angle_deg <= 120:
            raise ValueError(f"LayoutConfig.curve_angle_deg must be in (0, 120], got {self.curve_angle_deg}")
        if not 1 <= self.main_lanes_per_direction <= 3 or not 1 <= self.cross_lanes_per_direction <= 3:
            raise ValueError("LayoutConfig: lanes per direction must be 1..3")
        outer_half_width = (
            self.main_lanes_per_direction * self.lane_width_m + self.bike_lane_width_m + self.sidewalk_width_m
        )
        if self.curve_radius_m <= outer_half_width:
            raise ValueError(
                f"LayoutConfig.curve_radius_m ({self.curve_radius_m}) must exceed the main road's half width "
                f"with its sidewalk ({outer_half_width:.1f} m), or the curve's inside edge folds over"
            )
        if not 0.10 <= self.curb_height_m <= 0.15:
            raise ValueError(
                f"LayoutConfig.curb_height_m must be in [0.10, 0.15] m, got {self.curb_height_m}"
            )
        if not self.cross_road_x_m:
            raise ValueError(
                "LayoutConfig.cross_road_x_m needs at least one cross road (the 4-way intersection)"
            )


@dataclass(frozen=True)
class TerrainConfig:
    """Smooth terrain: a tanh ramp along x, a cross slope and gentle waves; grades stay under `max_grade`."""

    rise_m: float = 4.0
    """Total rise of the ramp over the site."""
    ramp_width_m: float = 45.0
    """tanh width of the ramp: its steepest grade is rise / (2 * width)."""
    cross_slope: float = 0.01
    wave_amplitude_m: float = 0.3
    wave_length_m: float = 120.0
    max_grade: float = 0.09
    """Lipschitz bound used by the ray marcher; validated against the other fields."""

    def __post_init__(self) -> None:
        if self.ramp_width_m <= 0 or self.wave_length_m <= 0 or self.wave_amplitude_m < 0:
            raise ValueError(
                "TerrainConfig: ramp_width_m and wave_length_m must be > 0 and wave_amplitude_m >= 0"
            )
        steepest = abs(self.rise_m) / (2 * self.ramp_width_m) + self.grade_besides_ramp()
        if steepest > self.max_grade:
            raise ValueError(f"TerrainConfig: grade up to {steepest:.3f} exceeds max_grade {self.max_grade}")

    def grade_besides_ramp(self) -> float:
        """The bound on the grade the cross slope and the waves add to the ramp's steepest, rise / (2 width)."""
        return terrain_grade_besides_ramp(self.cross_slope, self.wave_amplitude_m, self.wave_length_m)


def terrain_grade_besides_ramp(cross_slope: float, wave_amplitude_m: float, wave_length_m: float) -> float:
    """The grade bound of a terrain's cross slope and waves (the waves' steepest slope with a 1.5 margin)."""
    return abs(cross_slope) + 2 * 3.14159 * wave_amplitude_m / wave_length_m * 1.5


def with_ramp(terrain: TerrainConfig, rise_m: float | None, ramp_width_m: float | None) -> TerrainConfig:
    """`terrain` with another ramp (None keeps that field): a hillier site, whose drives start metres apart in
    height. `max_grade` (the ray marcher's bound) rises with the terrain's steepest grade, up to
    `STEEPEST_STREET_GRADE`; a steeper ramp is a ValueError naming the narrowest ramp width that stays within it."""
    rise = terrain.rise_m if rise_m is None else float(rise_m)
    width = terrain.ramp_width_m if ramp_width_m is None else float(ramp_width_m)
    if not (math.isfinite(rise) and math.isfinite(width)) or width <= 0:
        raise ValueError(f"terrain ramp: rise {rise} m and width {width} m must be finite, the width > 0")
    besides = terrain.grade_besides_ramp()
    steepest = abs(rise) / (2 * width) + besides
    if steepest > STEEPEST_STREET_GRADE:
        raise ValueError(
            f"terrain ramp: a rise of {rise:g} m over a ramp width of {width:g} m is too steep (grade up to "
            f"{steepest:.3f} with the cross slope and waves, above {STEEPEST_STREET_GRADE}): widen the ramp to at "
            f"least {math.ceil(abs(rise) / (2 * (STEEPEST_STREET_GRADE - besides)))} m"
        )
    return replace(terrain, rise_m=rise, ramp_width_m=width, max_grade=max(terrain.max_grade, steepest))


@dataclass(frozen=True)
class CameraConfig:
    """Image size and the camera's optical and sensor imperfections; nuScenes intrinsics (1600x900) are scaled
    to the size."""

    width_px: int = 512
    """Image width, 64..4096 pixels."""
    height_px: int = 288
    """Image height, 36..4096 pixels."""
    jpeg_quality: int = 92
    """JPEG quality of the written images, 1..100 (lower: stronger block artefacts)."""
    noise_sigma: float = 0.0
    """Standard deviation of white Gaussian sensor noise added to every image (linear [0, 1] intensity), 0..0.2;
    night clips add their own 0.012 on top."""
    blur_sigma_px: float = 0.0
    """Gaussian blur (optics, focus) applied before the noise, in pixels, 0..5; 0 leaves images sharp."""

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px", "jpeg_quality"):
            if not isinstance(getattr(self, name), int) or isinstance(getattr(self, name), bool):
                raise ValueError(f"CameraConfig.{name} must be an integer, got {getattr(self, name)!r}")
        if not 64 <= self.width_px <= MAX_IMAGE_SIDE_PX or not 36 <= self.height_px <= MAX_IMAGE_SIDE_PX:
            raise ValueError(
                f"CameraConfig: image {self.width_px}x{self.height_px} is out of range "
                f"(width 64..{MAX_IMAGE_SIDE_PX}, height 36..{MAX_IMAGE_SIDE_PX} pixels)"
            )
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"CameraConfig.jpeg_quality must be in 1..100, got {self.jpeg_quality}")
        if not 0.0 <= self.noise_sigma <= 0.2:
            raise ValueError(f"CameraConfig.noise_sigma must be in [0, 0.2], got {self.noise_sigma}")
        if not 0.0 <= self.blur_sigma_px <= 5.0:
            raise ValueError(f"CameraConfig.blur_sigma_px must be in [0, 5] px, got {self.blur_sigma_px}")


def parse_image_size(text: str) -> tuple[int, int]:
    """`"1600x900"` -> (1600, 900); a ValueError naming the text and the expected form otherwise."""
    parts = text.strip().lower().split("x")
    if len(parts) != 2 or not all(part.strip().isdigit() for part in parts):
        raise ValueError(f"image size {text!r} is not WIDTHxHEIGHT in pixels (e.g. 1600x900)")
    width, height = (int(part) for part in parts)
    CameraConfig(width_px=width, height_px=height)  # the range check, with its message
    return width, height


RGB = tuple[float, float, float]


@dataclass(frozen=True)
class AppearanceConfig:
    """How surfaces look and how they are lit; the defaults are the generator's one look (randomised sites draw
    others, see `cama_pipeline.synthetic.randomise`). Colours are linear RGB albedos in [0, 1]."""

    asphalt_rgb: RGB = (0.34, 0.34, 0.35)
    """Base colour of the road surface (brightness and tint of the asphalt)."""
    concrete_rgb: RGB = (0.60, 0.59, 0.56)
    """Base colour of the sidewalks."""
    curb_rgb: RGB = (0.70, 0.69, 0.66)
    """Base colour of the curb stones."""
    grass_rgb: RGB = (0.33, 0.42, 0.22)
    """Base colour of the verges beyond the sidewalks."""
    white_paint_rgb: RGB = (0.92, 0.92, 0.89)
    """Colour of white paint (lane lines, crosswalk stripes)."""
    yellow_paint_rgb: RGB = (0.90, 0.74, 0.20)
    """Colour of yellow paint (centre lines)."""
    sky_zenith_rgb: RGB = (0.42, 0.58, 0.85)
    """Sky colour straight up."""
    sky_horizon_rgb: RGB = (0.78, 0.82, 0.86)
    """Sky colour at the horizon (also the colour distant surfaces fade to)."""
    texture_contrast: float = 1.0
    """Scale of the ground's grain and wear marks (patches, stains, cracks), 0..3; 0 gives flat surfaces."""
    paint_fade: float = 0.0
    """Fraction by which all paint is faded towards the surface under it, 0..0.9."""
    paint_missing: float = 0.0
    """Fraction of the painted area where the paint is worn away entirely (in blotches), 0..0.9. The masks still
    label the whole marking, as an annotator draws a worn line whole."""
    sun_direction: tuple[float, float, float] = (0.45, 0.30, 0.84)
    """Unit vector towards the sun (layout frame, z up); its length must be within 2 % of 1, z >= 0.2."""
    exposure_gain: float = 1.0
    """Overall exposure multiplier (on top of each clip's small random exposure), 0.4..2."""

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name.endswith("_rgb"):
                value = getattr(self, f.name)
                if len(value) != 3 or not all(0.0 <= float(c) <= 1.0 for c in value):
                    raise ValueError(f"AppearanceConfig.{f.name} must be 3 values in [0, 1], got {value!r}")
        ranges = {"texture_contrast": (0.0, 3.0), "paint_fade": (0.0, 0.9), "paint_missing": (0.0, 0.9)}
        ranges["exposure_gain"] = (0.4, 2.0)
        for name, (low, high) in ranges.items():
            if not low <= getattr(self, name) <= high:
                raise ValueError(
                    f"AppearanceConfig.{name} must be in [{low}, {high}], got {getattr(self, name)}"
                )
        sun = self.sun_direction
        norm = math.sqrt(sum(float(c) ** 2 for c in sun)) if len(sun) == 3 else 0.0
        if len(sun) != 3 or not 0.98 <= norm <= 1.02 or sun[2] < 0.2:
            raise ValueError(
                f"AppearanceConfig.sun_direction must be a unit (x, y, z) with z >= 0.2, got {sun!r}"
            )


@dataclass(frozen=True)
class ClipConfig:
    """Clips (scenes) to drive: durations and which special clips to include."""

    moving_duration_s: float = 8.0
    stationary_duration_s: float = 4.0
    night_duration_s: float = 5.0
    routes: tuple[str, ...] = ("east", "west", "south_turn_east")
    """Named routes for the moving day clips (see `routes.ROUTES`)."""
    speed_mps: float = 8.0
    sweep_hz: float = 12.0
    sample_hz: float = 2.0
    moving_vehicles_per_clip: int = 3

    def __post_init__(self) -> None:
        if self.moving_duration_s <= 1 or self.sample_hz <= 0 or self.sweep_hz < self.sample_hz:
            raise ValueError("ClipConfig: durations must be > 1 s and sweep_hz >= sample_hz > 0")


@dataclass(frozen=True)
class MaskNoiseConfig:
    """Degradation of the semantic / instance masks, as a real segmentation network would err."""

    boundary_jitter_px: int = 0
    """Random erosion/dilation radius applied per class region."""
    miss_rate: float = 0.0
    """Probability that a lane-marking instance is missed in an image (labelled road instead)."""

    def __post_init__(self) -> None:
        if self.boundary_jitter_px < 0 or not 0.0 <= self.miss_rate < 1.0:
            raise ValueError("MaskNoiseConfig: boundary_jitter_px >= 0 and 0 <= miss_rate < 1 required")


@dataclass(frozen=True)
class SynthConfig:
    """Everything that determines a generated site; the same config and seed give identical files."""

    preset: str = "default"
    seed: int = 7
    layout: LayoutConfig = field(default_factory=LayoutConfig)
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    clips: ClipConfig = field(default_factory=ClipConfig)
    masks: MaskNoiseConfig = field(default_factory=MaskNoiseConfig)
    sensors: SensorNoiseConfig = field(default_factory=SensorNoiseConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)
    ground_texel_m: float = 0.04
    """Resolution of the ground texture atlas the renderer samples."""
    bev_resolution_m: float = 0.1
    """Resolution of the ground-truth BEV rasters."""
    site_origin_xy: tuple[float, float] = (412.0, 1085.0)
    """Global coordinates of the layout's origin (nuScenes-like, not zero, so nothing assumes it)."""
    version: str = "v1.0-synth"
    location: str | None = None
    """`log.location` of every scene (each location is its own map frame); None: `synthetic-<preset>`."""
    random_seed: int | None = None
    """The seed `randomise.randomised_config` drew this config from; None for a named preset as it is."""

    def __post_init__(self) -> None:
        if self.ground_texel_m <= 0 or self.bev_resolution_m <= 0:
            raise ValueError("SynthConfig: ground_texel_m and bev_resolution_m must be > 0")
        if self.location is not None and not self.location.strip():
            raise ValueError("SynthConfig.location must not be blank (None for the preset's own)")

    @property
    def log_location(self) -> str:
        """The `log.location` written for every scene."""
        return self.location if self.location is not None else f"synthetic-{self.preset}"


def preset(name: str, **overrides: object) -> SynthConfig:
    """Return a named preset: `tiny` (tests, seconds), `default` (demo), `large` (benchmarks)."""
    if name == "tiny":
        cfg = SynthConfig(
            preset="tiny",
            layout=LayoutConfig(
                main_west_length_m=40.0,
                main_east_length_m=25.0,
                curve_radius_m=30.0,
                curve_exit_length_m=10.0,
                cross_road_half_length_m=35.0,
            ),
            terrain=TerrainConfig(rise_m=2.0, ramp_width_m=25.0),
            camera=CameraConfig(width_px=256, height_px=144),
            clips=ClipConfig(
                moving_duration_s=1.5,
                stationary_duration_s=1.0,
                night_duration_s=1.0,
                routes=("east", "west"),
                moving_vehicles_per_clip=2,
            ),
            ground_texel_m=0.05,
        )
    elif name == "default":
        cfg = SynthConfig(preset="default", masks=MaskNoiseConfig(boundary_jitter_px=1, miss_rate=0.03))
    elif name == "large":
        cfg = SynthConfig(
            preset="large",
            layout=LayoutConfig(
                main_west_length_m=150.0,
                main_east_length_m=60.0,
                curve_radius_m=60.0,
                curve_exit_length_m=60.0,
                cross_road_x_m=(-90.0, 0.0),
                cross_road_half_length_m=150.0,
                main_lanes_per_direction=3,
            ),
            terrain=TerrainConfig(rise_m=6.0, ramp_width_m=70.0),
            camera=CameraConfig(width_px=640, height_px=360),
            clips=ClipConfig(
                moving_duration_s=22.0,
                night_duration_s=12.0,
                stationary_duration_s=8.0,
                routes=("east", "west", "north", "south_turn_east", "west_far", "north_far"),
                moving_vehicles_per_clip=5,
            ),
            masks=MaskNoiseConfig(boundary_jitter_px=1, miss_rate=0.03),
            ground_texel_m=0.05,
        )
    else:
        raise ValueError(f"unknown preset {name!r}; choose one of tiny, default, large")
    return replace(cfg, **overrides) if overrides else cfg  # type: ignore[arg-type]
