"""Procedural colours: multi-scale asphalt, worn paint, concrete, grass, facades and car bodies.

All noise comes from one seeded periodic noise tile sampled at several scales, and octaves finer than
the pixel footprint fade out (a cheap mip-map), so far ground does not alias into sparkle.
"""

import math
from statistics import NormalDist

import numpy as np
import torch

from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic.atlas import PAINT_YELLOW, GroundAtlas
from cama_pipeline.synthetic.config import AppearanceConfig
from cama_pipeline.synthetic.scenery import BoxKind

TILE_PX = 256
_TEXELS_PER_WAVELENGTH = 4.0
_PAINT_BLOTCHES = ((0.9, 0.7), (0.25, 0.5))
"""Octaves (wavelength_m, amplitude) of the field whose highest values are the worn-away paint blotches."""


class NoiseBank:
    """A seeded, periodic, smooth noise tile and fractal sums of it over world coordinates."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        white = rng.standard_normal((TILE_PX, TILE_PX))
        freq = np.fft.fftfreq(TILE_PX)
        radius2 = freq[:, None] ** 2 + freq[None, :] ** 2
        smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * np.exp(-radius2 * (2 * math.pi * 1.2) ** 2 / 2)))
        smooth = (smooth - smooth.mean()) / smooth.std()
        self.tile = torch.from_numpy(smooth.astype(np.float32)).reshape(-1)
        self.offsets = rng.uniform(0, TILE_PX, size=(16, 2))
        self.angles = rng.uniform(0, 2 * math.pi, size=16)

    def sample(self, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Bilinear, wrapping lookup at tile coordinates (u, v) in texels; about unit variance."""
        u0, v0 = torch.floor(u), torch.floor(v)
        fu, fv = (u - u0).float(), (v - v0).float()
        iu = u0.long() % TILE_PX
        iv = v0.long() % TILE_PX
        iu1 = (iu + 1) % TILE_PX
        iv1 = (iv + 1) % TILE_PX
        t = self.tile
        a = t[iv * TILE_PX + iu] + (t[iv * TILE_PX + iu1] - t[iv * TILE_PX + iu]) * fu
        b = t[iv1 * TILE_PX + iu] + (t[iv1 * TILE_PX + iu1] - t[iv1 * TILE_PX + iu]) * fu
        return a + (b - a) * fv

    def octave(
        self, index: int, x: torch.Tensor, y: torch.Tensor, wavelength_m: float, footprint_m: torch.Tensor
    ) -> torch.Tensor:
        """One noise octave of `wavelength_m` at world (x, y), faded where the pixel footprint resolves it poorly."""
        c, s = math.cos(self.angles[index]), math.sin(self.angles[index])
        scale = _TEXELS_PER_WAVELENGTH / wavelength_m
        u = (c * x - s * y) * scale + self.offsets[index, 0]
        v = (s * x + c * y) * scale + self.offsets[index, 1]
        fade = (2.0 - 4.0 * footprint_m / wavelength_m).clamp(0.0, 1.0)
        return self.sample(u, v) * fade

    def fbm(
        self,
        x: torch.Tensor,
        y: torch.Tensor,
        footprint_m: torch.Tensor,
        octaves: tuple[tuple[float, float], ...],
        first_index: int = 0,
    ) -> torch.Tensor:
        """Sum of octaves given as (wavelength_m, amplitude)."""
        total = torch.zeros_like(x, dtype=torch.float32)
        for k, (wavelength, amplitude) in enumerate(octaves):
            total = total + amplitude * self.octave(first_index + k, x, y, wavelength, footprint_m)
        return total


def _rgb(color: tuple[float, float, float], like: torch.Tensor) -> torch.Tensor:
    return torch.tensor(color, dtype=torch.float32).expand(like.shape[0], 3)


def ground_color(
    atlas: GroundAtlas,
    noise: NoiseBank,
    x: torch.Tensor,
    y: torch.Tensor,
    footprint_m: torch.Tensor,
    look: AppearanceConfig,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Albedo (N, 3), semantic label (N,) and instance value (N,) of the ground at layout points (x, y).

    One multi-scale grain is shared by all surfaces, each with its own base colour (from `look`) and grain
    strength: asphalt (with aggregate specks), curb stone, sidewalk concrete (with slab joints) and grass.
    `look.texture_contrast` scales grain, specks and wear marks together.
    """
    label = atlas.nearest(atlas.label, x, y)
    instance = atlas.nearest(atlas.instance, x, y)
    raised = atlas.nearest(atlas.raised, x, y) > 127
    grain = noise.fbm(x, y, footprint_m, ((4.0, 0.05), (1.0, 0.06), (0.3, 0.10), (0.12, 0.12), (0.05, 0.16)))
    is_curb = label == Semantic.CURB
    is_background = label == Semantic.BACKGROUND
    sidewalk = is_background & raised
    grass = is_background & ~raised
    base = _rgb(look.asphalt_rgb, x).clone()
    base[is_curb] = torch.tensor(look.curb_rgb)
    base[sidewalk] = torch.tensor(look.concrete_rgb)
    base[grass] = torch.tensor(look.grass_rgb)
    contrast = float(look.texture_contrast)
    strength = torch.where(grass, 1.8, torch.where(is_curb | sidewalk, 0.7, 1.0)) * contrast
    specks = (
        (noise.octave(4, x, y, 0.035, footprint_m) > 1.6).float() * 0.12 * (~is_background & ~is_curb).float()
    )
    joints = (
        ((torch.remainder(x, 1.5) < 0.03) | (torch.remainder(y, 1.5) < 0.03))
        & sidewalk
        & (footprint_m < 0.05)
    )
    wear = _wear_marks(noise, x, y, footprint_m) * (~is_background & ~is_curb).float()
    color = (
        base * (1.0 + strength * grain + contrast * specks - 0.25 * joints.float() - contrast * wear)[:, None]
    )
    painted = torch.nonzero(atlas.nearest(atlas.paint_alpha, x, y) > 0).squeeze(1)
    if painted.numel():
        color[painted] = _paint_over(
            atlas, noise, x[painted], y[painted], footprint_m[painted], color[painted], look
        )
    return color.clamp(0.0, 1.0), label.to(torch.uint8), instance.to(torch.int32)


def _wear_marks(noise: NoiseBank, x: torch.Tensor, y: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
    """Darkening by crisp-edged repair patches, oil stains and sealed cracks: the corners and blobs that
    give real asphalt its matchable features."""
    patches = (noise.octave(14, x, y, 3.0, footprint) > 1.0).float() * 0.16
    stains = (noise.octave(15, x, y, 0.7, footprint) > 1.3).float() * 0.12
    crack_field = noise.octave(6, x, y, 2.5, footprint).abs()
    cracks = (crack_field < 0.05).float() * 0.3 * (footprint < 0.04).float()
    return patches + stains + cracks


def _paint_over(
    atlas: GroundAtlas,
    noise: NoiseBank,
    x: torch.Tensor,
    y: torch.Tensor,
    footprint: torch.Tensor,
    under: torch.Tensor,
    look: AppearanceConfig,
) -> torch.Tensor:
    """Blend slightly worn white or yellow paint over the surface colour (anti-aliased edges), faded by
    `look.paint_fade` and with `look.paint_missing` of it worn away."""
    alpha = atlas.bilinear(atlas.paint_alpha, x, y)
    wear = (noise.fbm(x, y, footprint, ((0.6, 0.6), (0.12, 0.5)), first_index=11) - 0.55).clamp(0.0, 1.0)
    alpha = alpha * (1.0 - 1.4 * wear).clamp(0.0, 1.0)
    if look.paint_fade > 0:
        alpha = alpha * (1.0 - look.paint_fade)
    if look.paint_missing > 0:
        alpha = alpha * _paint_kept(noise, x, y, footprint, look.paint_missing)
    yellow = atlas.nearest(atlas.paint_color, x, y) == PAINT_YELLOW
    paint = torch.where(yellow[:, None], _rgb(look.yellow_paint_rgb, x), _rgb(look.white_paint_rgb, x))
    paint = paint * (1.0 + 0.08 * noise.octave(3, x, y, 0.25, footprint))[:, None]
    return under + (paint - under) * alpha[:, None]


def _paint_kept(
    noise: NoiseBank, x: torch.Tensor, y: torch.Tensor, footprint: torch.Tensor, missing: float
) -> torch.Tensor:
    """Share of the paint left (0 or 1 in crisp blotches where pixels resolve them) so that about `missing` of
    the painted area is bare. Where the footprint blurs the blotch field, its spread shrinks; the threshold
    follows that spread, and the unresolved part tends to the area average 1 - missing."""
    field = noise.fbm(x, y, footprint, _PAINT_BLOTCHES, first_index=7)
    full = math.sqrt(sum(a * a for _, a in _PAINT_BLOTCHES))
    resolved_var = torch.zeros_like(footprint)
    for wavelength, amplitude in _PAINT_BLOTCHES:
        resolved_var = resolved_var + (amplitude * (2.0 - 4.0 * footprint / wavelength).clamp(0.0, 1.0)) ** 2
    resolved = torch.sqrt(resolved_var)
    threshold = NormalDist().inv_cdf(1.0 - missing) * resolved
    crisp = (field <= threshold).float()
    share = resolved / full
    return share * crisp + (1.0 - share) * (1.0 - missing)


def sky_color(direction_z: torch.Tensor, look: AppearanceConfig) -> torch.Tensor:
    """Sky gradient from the horizon colour to the zenith colour by ray elevation."""
    w = direction_z.clamp(0.0, 1.0).sqrt()[:, None]
    horizon = _rgb(look.sky_horizon_rgb, direction_z)
    return horizon + (_rgb(look.sky_zenith_rgb, direction_z) - horizon) * w


def box_color(
    kind: torch.Tensor,
    base_rgb: torch.Tensor,
    noise: NoiseBank,
    u: torch.Tensor,
    height_m: torch.Tensor,
    box_height_m: torch.Tensor,
    is_top: torch.Tensor,
    footprint_m: torch.Tensor,
) -> torch.Tensor:
    """Albedo of box faces at face coordinates (u along the face, height above the box bottom), per pixel:
    building facades get windows, cars glass bands and tyres, all a multi-scale grain."""
    grain = noise.fbm(u, height_m, footprint_m, ((2.0, 0.10), (0.5, 0.10), (0.1, 0.08)), first_index=13)
    color = base_rgb * (1.0 + grain)[:, None]
    in_window = (torch.remainder(u, 3.0) > 0.8) & (torch.remainder(u, 3.0) < 2.3)
    in_window &= (torch.remainder(height_m, 3.2) > 1.0) & (torch.remainder(height_m, 3.2) < 2.6)
    in_window &= (height_m > 1.0) & ~is_top & (kind == BoxKind.BUILDING)
    glass = torch.tensor([0.16, 0.19, 0.24]) * (1.0 + 0.8 * grain)[:, None]
    is_car = (kind == BoxKind.CAR) | (kind == BoxKind.EGO)
    car_dark = ((height_m > 0.55 * box_height_m) & (height_m < 0.92 * box_height_m) & ~is_top) | (
        height_m < 0.3
    )
    dark = torch.tensor([0.08, 0.09, 0.1]) * (1.0 + grain)[:, None]
    color = torch.where(in_window[:, None], glass, color)
    color = torch.where((is_car & car_dark)[:, None], dark, color)
    return color.clamp(0.0, 1.0)
