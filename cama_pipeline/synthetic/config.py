"""Configuration of the synthetic driving-site generator, with the named presets tiny/default/large."""

from dataclasses import dataclass, field, replace
from typing import Literal

from cama_pipeline.synthetic.sensors import SensorNoiseConfig

PresetName = Literal["tiny", "default", "large"]


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
        if not 1 <= self.main_lanes_per_direction <= 3 or not 1 <= self.cross_lanes_per_direction <= 3:
            raise ValueError("LayoutConfig: lanes per direction must be 1..3")
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
        steepest = self.rise_m / (2 * self.ramp_width_m) + self.cross_slope
        steepest += 2 * 3.14159 * self.wave_amplitude_m / self.wave_length_m * 1.5
        if steepest > self.max_grade:
            raise ValueError(f"TerrainConfig: grade up to {steepest:.3f} exceeds max_grade {self.max_grade}")


@dataclass(frozen=True)
class CameraConfig:
    """Image size; nuScenes intrinsics (1600x900) are scaled to it."""

    width_px: int = 512
    height_px: int = 288
    jpeg_quality: int = 92

    def __post_init__(self) -> None:
        if self.width_px < 64 or self.height_px < 36:
            raise ValueError(f"CameraConfig: image {self.width_px}x{self.height_px} is too small")


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
    ground_texel_m: float = 0.04
    """Resolution of the ground texture atlas the renderer samples."""
    bev_resolution_m: float = 0.1
    """Resolution of the ground-truth BEV rasters."""
    site_origin_xy: tuple[float, float] = (412.0, 1085.0)
    """Global coordinates of the layout's origin (nuScenes-like, not zero, so nothing assumes it)."""
    version: str = "v1.0-synth"

    def __post_init__(self) -> None:
        if self.ground_texel_m <= 0 or self.bev_resolution_m <= 0:
            raise ValueError("SynthConfig: ground_texel_m and bev_resolution_m must be > 0")


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
