"""Randomised sites: a whole `SynthConfig` drawn from one seed, for training data with variety.

A segmentation network or a map-element model trained on one site learns that site's look; randomised sites
vary what a real fleet sees from city to city: the road layout (lengths, curve, lanes, widths, dash patterns),
the terrain, surface and paint colours, paint wear, the sun and exposure, and the camera's blur, noise and JPEG
quality. The base preset sets the size (image size, clip durations, routes), so a randomised `tiny` site costs
about what the `tiny` preset costs.

Every seed gets its own `log.location` (`synth-random-<seed>`) and its own site origin, so that data sets of
several seeds can be split by location. The same seed always gives the same config (and so the same files).
"""

import math
from dataclasses import replace

import numpy as np

from cama_pipeline.synthetic.config import (
    RGB,
    AppearanceConfig,
    CameraConfig,
    LayoutConfig,
    SynthConfig,
    TerrainConfig,
    preset,
    terrain_grade_besides_ramp,
)

RANDOMISE_STREAM = 23
"""First word of the draw generator's seed, so that these draws never coincide with the site's own streams."""
ORIGIN_GRID = 20
"""Site origins lie on a ORIGIN_GRID x ORIGIN_GRID grid of cells (by seed modulo its size), each jittered."""
ORIGIN_SPACING_M = 200.0
"""Distance between neighbouring origin cells."""
_STOP_REACH_M = 6.0 + 1.5 + 2.5 + 4.0
"""Corner radius, stop gap, waiting distance and a margin east of a junction's crosswalk: the stationary
clip waits there, so the main road's east arm must be longer than the crossroad's half width plus this."""
_GRADE_SHARE = 0.95
"""Drawn terrain is scaled down, if needed, to this share of `TerrainConfig.max_grade`."""


def randomised_config(seed: int, *, base: str = "tiny") -> SynthConfig:
    """The config of randomised site `seed`, the size of preset `base` (tiny, default or large)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"random seed must be an integer >= 0, got {seed!r}")
    cfg = preset(base)
    rng = np.random.default_rng([RANDOMISE_STREAM, seed])
    layout = _layout(cfg.layout, rng)
    terrain = _terrain(cfg.terrain, rng)
    look = _appearance(rng)
    camera = _camera(cfg.camera, rng)
    return replace(
        cfg,
        seed=seed,
        layout=layout,
        terrain=terrain,
        camera=camera,
        appearance=look,
        site_origin_xy=_origin(seed, rng),
        location=f"synth-random-{seed}",
        random_seed=seed,
    )


def _u(rng: np.random.Generator, low: float, high: float, digits: int = 3) -> float:
    """A uniform draw rounded to `digits` (readable manifests; the config is what is hashed anyway)."""
    return round(float(rng.uniform(low, high)), digits)


def _layout(base: LayoutConfig, rng: np.random.Generator) -> LayoutConfig:
    """Lengths scaled around the base's, lanes, widths, paint and dash patterns drawn."""
    main_lanes = int(rng.choice([1, 2, 3], p=[0.25, 0.5, 0.25]))
    cross_lanes = int(rng.choice([1, 2, 3], p=[0.35, 0.5, 0.15]))
    lane_w = _u(rng, 2.9, 3.9)
    bike_w = _u(rng, 1.2, 2.2)
    sidewalk_w = _u(rng, 2.5, 4.5)
    crosswalk_d = _u(rng, 3.0, 5.0)
    dash = _u(rng, 1.5, 4.5)
    outer = main_lanes * lane_w + bike_w + sidewalk_w
    east_min = cross_lanes * lane_w + crosswalk_d + _STOP_REACH_M
    return replace(
        base,
        main_west_length_m=_u(rng, 0.8, 1.25) * base.main_west_length_m,
        main_east_length_m=max(_u(rng, 0.8, 1.3) * base.main_east_length_m, round(east_min, 3)),
        curve_radius_m=max(_u(rng, 0.75, 1.4) * base.curve_radius_m, round(outer + 8.0, 3)),
        curve_angle_deg=_u(rng, 40.0, 110.0, 1),
        curve_exit_length_m=_u(rng, 0.8, 1.5) * base.curve_exit_length_m,
        cross_road_half_length_m=_u(rng, 0.9, 1.25) * base.cross_road_half_length_m,
        main_lanes_per_direction=main_lanes,
        cross_lanes_per_direction=cross_lanes,
        lane_width_m=lane_w,
        bike_lane_width_m=bike_w,
        sidewalk_width_m=sidewalk_w,
        curb_height_m=_u(rng, 0.10, 0.15),
        curb_width_m=_u(rng, 0.15, 0.3),
        marking_width_m=_u(rng, 0.10, 0.20),
        dash_length_m=dash,
        dash_gap_m=round(dash * _u(rng, 0.6, 3.0), 3),
        crosswalk_depth_m=crosswalk_d,
        stripe_width_m=_u(rng, 0.4, 0.6),
        building_setback_m=_u(rng, 1.0, 4.0),
    )


def _terrain(base: TerrainConfig, rng: np.random.Generator) -> TerrainConfig:
    """Rise (either sign), ramp width, cross slope and waves drawn, then scaled to stay within the grade bound."""
    rise = _u(rng, -1.5, 1.5) * base.rise_m
    ramp = _u(rng, 0.7, 1.5) * base.ramp_width_m
    cross = _u(rng, -0.02, 0.02, 4)
    amplitude = _u(rng, 0.0, 0.45)
    wave_length = _u(rng, 60.0, 160.0, 1)
    steepest = abs(rise) / (2 * ramp) + terrain_grade_besides_ramp(cross, amplitude, wave_length)
    scale = min(1.0, _GRADE_SHARE * base.max_grade / steepest) if steepest > 0 else 1.0
    return replace(
        base,
        rise_m=round(rise * scale, 3),
        ramp_width_m=ramp,
        cross_slope=round(cross * scale, 4),
        wave_amplitude_m=round(amplitude * scale, 3),
        wave_length_m=wave_length,
    )


def _tinted(rng: np.random.Generator, brightness: float, tint: float) -> RGB:
    """A grey of `brightness` with each channel shifted by up to `tint` (relative)."""
    return _rgb(tuple(brightness * (1.0 + float(rng.uniform(-tint, tint))) for _ in range(3)))


def _rgb(values: tuple[float, ...]) -> RGB:
    r, g, b = (round(min(max(v, 0.0), 1.0), 3) for v in values)
    return (r, g, b)


def _appearance(rng: np.random.Generator) -> AppearanceConfig:
    """Surface and paint colours, texture contrast, paint wear, sky, sun and exposure."""
    concrete = _tinted(rng, _u(rng, 0.45, 0.75), 0.05)
    curb_gain = _u(rng, 1.0, 1.2)
    white = _u(rng, 0.75, 0.95)
    overcast = bool(rng.uniform() < 0.3)
    horizon = _tinted(rng, _u(rng, 0.7, 0.9), 0.04)
    zenith = (
        _tinted(rng, _u(rng, 0.6, 0.8), 0.03)
        if overcast
        else _rgb((_u(rng, 0.3, 0.55), _u(rng, 0.5, 0.7), _u(rng, 0.75, 0.95)))
    )
    azimuth = math.radians(_u(rng, 0.0, 360.0, 1))
    elevation = math.radians(_u(rng, 20.0, 75.0, 1))
    return AppearanceConfig(
        asphalt_rgb=_tinted(rng, _u(rng, 0.18, 0.5), 0.04),
        concrete_rgb=concrete,
        curb_rgb=_rgb(tuple(c * curb_gain for c in concrete)),
        grass_rgb=_rgb((_u(rng, 0.22, 0.42), _u(rng, 0.32, 0.5), _u(rng, 0.12, 0.28))),
        white_paint_rgb=_rgb((white, white, white * _u(rng, 0.9, 1.0))),
        yellow_paint_rgb=_rgb((_u(rng, 0.8, 0.95), _u(rng, 0.6, 0.8), _u(rng, 0.1, 0.3))),
        sky_zenith_rgb=zenith,
        sky_horizon_rgb=horizon,
        texture_contrast=_u(rng, 0.5, 1.8),
        paint_fade=_u(rng, 0.0, 0.45),
        paint_missing=_u(rng, 0.0, 0.3),
        sun_direction=(
            round(math.cos(elevation) * math.cos(azimuth), 4),
            round(math.cos(elevation) * math.sin(azimuth), 4),
            round(math.sin(elevation), 4),
        ),
        exposure_gain=_u(rng, 0.7, 1.35),
    )


def _camera(base: CameraConfig, rng: np.random.Generator) -> CameraConfig:
    """Blur, noise and JPEG quality drawn; the base's image size kept."""
    return replace(
        base,
        jpeg_quality=int(rng.integers(60, 96)),
        noise_sigma=_u(rng, 0.0, 0.02, 4),
        blur_sigma_px=_u(rng, 0.0, 1.0),
    )


def _origin(seed: int, rng: np.random.Generator) -> tuple[float, float]:
    """A global origin of the seed's own: a grid cell by seed, jittered by up to 20 m."""
    cell = seed % (ORIGIN_GRID * ORIGIN_GRID)
    x = 500.0 + ORIGIN_SPACING_M * (cell % ORIGIN_GRID) + _u(rng, -20.0, 20.0)
    y = 500.0 + ORIGIN_SPACING_M * (cell // ORIGIN_GRID) + _u(rng, -20.0, 20.0)
    return round(x, 3), round(y, 3)
