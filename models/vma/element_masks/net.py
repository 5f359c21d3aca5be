"""The element-mask network: a small U-Net over the BEV input, one sigmoid mask per vector class.

Three downsampled stages (stride 8, 1.6 m cells at 0.2 m/px) end in dilated convolutions, so a cell sees
some 30 m of road: enough to carry a lane line across a dash gap or a stretch of faded paint, and a kerb past a
parked car. Skip connections keep the full-resolution detail a 0.6 m line band needs.
"""

import torch
from torch import nn
from torch.nn import functional

from models.vma.element_masks.config import MaskModelConfig

STRIDE = 8
"""Input sides must be multiples of this (`models.vma.element_masks.propose` pads)."""


def _block(cin: int, cout: int, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class ElementMaskNet(nn.Module):
    """(B, C, H, W) rasters -> (B, K, H, W) logits of the per-class element masks."""

    def __init__(self, config: MaskModelConfig) -> None:
        super().__init__()
        self.config = config
        widths = [min(96, config.base_channels * 2**level) for level in range(4)]
        self.stem = nn.Sequential(_block(config.in_channels, widths[0]), _block(widths[0], widths[0]))
        self.down = nn.ModuleList(
            nn.Sequential(
                nn.MaxPool2d(2),
                _block(widths[level], widths[level + 1]),
                _block(widths[level + 1], widths[level + 1]),
            )
            for level in range(3)
        )
        self.context = nn.Sequential(*(_block(widths[3], widths[3], d) for d in (2, 4, 8)))
        self.up = nn.ModuleList(
            nn.Sequential(
                _block(widths[level + 1] + widths[level], widths[level]), _block(widths[level], widths[level])
            )
            for level in reversed(range(3))
        )
        head = nn.Conv2d(widths[0], config.out_channels, 1)
        assert head.bias is not None
        nn.init.constant_(head.bias, -3.0)  # rare positives: start with low probabilities
        self.head = head

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        if images.shape[-1] % STRIDE or images.shape[-2] % STRIDE:
            raise ValueError(
                f"ElementMaskNet: input sides must be multiples of {STRIDE}, got {tuple(images.shape)}"
            )
        skips = [self.stem(images)]
        for stage in self.down:
            skips.append(stage(skips[-1]))
        features = self.context(skips.pop())
        for stage in self.up:
            skip = skips.pop()
            features = functional.interpolate(
                features, size=skip.shape[-2:], mode="bilinear", align_corners=False
            )
            features = stage(torch.cat([features, skip], dim=1))
        return self.head(features)
