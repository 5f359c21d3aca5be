"""Smooth terrain elevation of the site: an analytic height field with its gradient (torch, vectorised)."""

import math

import torch

from cama_pipeline.synthetic.config import TerrainConfig


class Terrain:
    """z = rise/2 * tanh(x / width) + cross_slope * y + waves; all in layout-local metres."""

    def __init__(self, cfg: TerrainConfig) -> None:
        self.cfg = cfg
        self._k = 2 * math.pi / cfg.wave_length_m

    def height(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Terrain height (m) at layout-local (x, y)."""
        c = self.cfg
        ramp = 0.5 * c.rise_m * torch.tanh(x / c.ramp_width_m)
        waves = c.wave_amplitude_m * (torch.sin(self._k * x + 0.7) * torch.cos(0.8 * self._k * y + 0.3))
        return ramp + c.cross_slope * y + waves

    def gradient(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(dz/dx, dz/dy) of `height`, analytic."""
        c = self.cfg
        sech2 = 1.0 - torch.tanh(x / c.ramp_width_m) ** 2
        a, k = c.wave_amplitude_m, self._k
        dx = 0.5 * c.rise_m / c.ramp_width_m * sech2 + a * k * torch.cos(k * x + 0.7) * torch.cos(
            0.8 * k * y + 0.3
        )
        dy = c.cross_slope - a * 0.8 * k * torch.sin(k * x + 0.7) * torch.sin(0.8 * k * y + 0.3)
        return dx, dy
