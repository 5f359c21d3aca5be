"""The segmentation network: a compact U-Net predicting the nine image classes of `cama_pipeline.semantics`.

Encoder: a strided 3x3 convolution per level (strides 2..32) followed by a depthwise-separable residual block;
decoder: bilinear upsampling, concatenation with the encoder's features of that stride and a depthwise-separable
block, up to stride 2, then a 1x1 classifier whose logits are upsampled to the input size. Thin classes (lane
markings a few pixels wide) need the stride-2 skip; the stride-32 level gives the context that tells a road from
a sidewalk. A refinement at the input's own resolution (`NetworkConfig.full_resolution_width` channels: a 3x3
convolution of the image and a separable block over it and the upsampled decoder features) adds a per-pixel
correction to the upsampled logits, because stride-2 logits cannot draw a line one or two pixels wide. About
0.45 M parameters (under 1 MB in float16).

`SegmentationNet.for_inference` is the copy the segment stage runs: each batch norm folded into the convolution
before it and the weights in channels-last order, which oneDNN's CPU convolutions run fastest; its labels are
the trained network's up to float rounding.

`SegmentationNet.predict` takes RGB uint8 images of any size: it resizes them to the configured input width
(aspect kept, padded to a multiple of 32), runs the network and resizes its scores back.
"""

import copy
import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

from cama_pipeline.segment.config import NetworkConfig
from cama_pipeline.semantics import Semantic

IMAGE_CLASSES: tuple[Semantic, ...] = tuple(s for s in Semantic if s != Semantic.UNOBSERVED)
"""The classes the network predicts; the output channel index is the class id (0..8)."""
NUM_CLASSES = len(IMAGE_CLASSES)
_MEAN = (0.45, 0.45, 0.45)
_STD = (0.25, 0.25, 0.25)


def _conv_bn(cin: int, cout: int, stride: int = 1, kernel: int = 3, groups: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, kernel, stride, kernel // 2, groups=groups, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class _Separable(nn.Module):
    """Depthwise 3x3 then pointwise 1x1 (each with BN), ReLU; residual when the widths agree."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.depthwise = nn.Sequential(
            nn.Conv2d(cin, cin, 3, 1, 1, groups=cin, bias=False), nn.BatchNorm2d(cin)
        )
        self.pointwise = nn.Sequential(nn.Conv2d(cin, cout, 1, bias=False), nn.BatchNorm2d(cout))
        self.residual = cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # In-place ReLUs: on the CPU a fresh ReLU output cost a fifth of the network's time (README, "Segmenting
        # faster"); neither the batch norm's nor the sum's backward needs the tensor they overwrite.
        y = self.pointwise(F.relu(self.depthwise(x), inplace=True))
        return F.relu_(y + x if self.residual else y)


class _FullResolutionRefinement(nn.Module):
    """A per-pixel correction of the upsampled stride-2 logits from the image at stride 1 and the decoder's
    stride-2 features. Its classifier starts at zero, so a network that gains it (a checkpoint trained without
    one, going on with `cama train-segmenter --init`) starts from the same output."""

    def __init__(self, decoder_width: int, width: int) -> None:
        super().__init__()
        self.image = _conv_bn(3, width)
        self.mix = _Separable(decoder_width + width, width)
        self.classifier = nn.Conv2d(width, NUM_CLASSES, 1)
        for parameter in self.classifier.parameters():
            nn.init.zeros_(parameter)

    def forward(self, image: torch.Tensor, features: torch.Tensor, logits: torch.Tensor) -> torch.Tensor:
        """Logits at the image's size: `logits` (stride 2) upsampled plus the correction."""
        size = image.shape[-2:]
        upsampled = F.interpolate(features, size=size, mode="bilinear", align_corners=False)
        correction = self.classifier(self.mix(torch.cat([upsampled, self.image(image)], dim=1)))
        return F.interpolate(logits, size=size, mode="bilinear", align_corners=False) + correction


class SegmentationNet(nn.Module):
    """Compact U-Net: (B, 3, H, W) normalised RGB -> (B, NUM_CLASSES, H, W) logits; H, W multiples of 32."""

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, config: NetworkConfig) -> None:
        super().__init__()
        self.config = config
        widths = config.widths
        self.down = nn.ModuleList()
        cin = 3
        for width in widths:
            self.down.append(nn.Sequential(_conv_bn(cin, width, stride=2), _Separable(width, width)))
            cin = width
        self.up = nn.ModuleList(
            _Separable(widths[i + 1] + widths[i], widths[i]) for i in reversed(range(len(widths) - 1))
        )
        self.head = nn.Conv2d(widths[0], NUM_CLASSES, 1)
        self.refine = (
            _FullResolutionRefinement(widths[0], config.full_resolution_width)
            if config.full_resolution_width
            else None
        )
        self.register_buffer("mean", torch.tensor(_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits at the input's size; `x` is RGB in [0, 1], (B, 3, H, W) with H and W multiples of 32."""
        size = x.shape[-2:]
        image = x = (x - self.mean) / self.std
        skips = []
        for level in self.down:
            x = level(x)
            skips.append(x)
        x = skips.pop()
        for block in self.up:
            skip = skips.pop()
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = block(torch.cat([x, skip], dim=1))
        if self.refine is not None:
            return self.refine(image, x, self.head(x))
        return F.interpolate(self.head(x), size=size, mode="bilinear", align_corners=False)

    def for_inference(self) -> "SegmentationNet":
        """A copy for running, not training: in eval mode, every batch norm folded into the convolution before it
        (one operation instead of two, the same function in eval mode) and the weights in channels-last memory
        order; it stays on this network's device."""
        net = copy.deepcopy(self).eval()
        for module in net.modules():
            if isinstance(module, nn.Sequential):
                _fold_batch_norms(module)
        return net.to(memory_format=torch.channels_last)  # type: ignore[call-overload]

    @torch.inference_mode()
    def predict(
        self, images: list[np.ndarray], device: torch.device | None = None, *, flip_average: bool = False
    ) -> list[np.ndarray]:
        """(H, W) uint8 class ids of each (H, W, 3) RGB uint8 image (sizes may differ; same-size images are
        run as one batch). `flip_average`: the class probabilities of the image and of its mirror image averaged
        at the network's size, then resized to the image's once (twice the network's cost; the network trained on
        mirrored crops, and the two views' errors on thin paint and kerbs differ)."""
        device = device or next(self.parameters()).device
        out: list[np.ndarray | None] = [None] * len(images)
        by_size: dict[tuple[int, int], list[int]] = {}
        for i, image in enumerate(images):
            if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
                raise ValueError(f"image {i}: expected (H, W, 3) uint8 RGB, got {image.dtype} {image.shape}")
            by_size.setdefault(image.shape[:2], []).append(i)
        for (height, width), indices in by_size.items():
            batch = torch.from_numpy(np.stack([images[i] for i in indices])).to(device)
            rgb = batch.permute(0, 3, 1, 2).float() / 255.0
            scores = self.input_logits(rgb)
            if flip_average:  # averaged at the network's size: one resize, not two, of an image's scores
                mirrored = self.input_logits(rgb.flip(-1)).flip(-1)
                scores = scores.softmax(dim=1) + mirrored.softmax(dim=1)
            scores = _resized(scores, (height, width))
            labels = (
                scores.max(dim=1).indices.to(torch.uint8).cpu().numpy()
            )  # argmax(dim=1) is ~8x slower on CPU
            for k, i in enumerate(indices):
                out[i] = labels[k]
        return [labels for labels in out if labels is not None]

    def logits_at_size(self, rgb: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        """Logits of (B, 3, h, w) RGB in [0, 1] run at the configured input width, resized to `size`."""
        return _resized(self.input_logits(rgb), size)

    def input_logits(self, rgb: torch.Tensor) -> torch.Tensor:
        """Logits of (B, 3, h, w) RGB in [0, 1] at the size the network runs it: `input_width_px` wide, the
        image's aspect kept (padded to a multiple of 32 for the network, cropped back)."""
        height, width = rgb.shape[-2:]
        in_w = self.config.input_width_px
        in_h = max(32, int(round(height * in_w / width)))
        x = (
            rgb
            if (height, width) == (in_h, in_w)
            else F.interpolate(
                rgb, size=(in_h, in_w), mode="bilinear", align_corners=False, antialias=width > in_w
            )
        )
        padded_h = math.ceil(in_h / 32) * 32
        if padded_h != in_h:
            x = F.pad(x, (0, 0, 0, padded_h - in_h), mode="replicate")
        return self(x.contiguous(memory_format=torch.channels_last))[..., :in_h, :]


def _resized(scores: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """(B, C, h, w) scores resized bilinearly to `size` (unchanged when they have it)."""
    if tuple(scores.shape[-2:]) == tuple(size):
        return scores
    return F.interpolate(scores, size=size, mode="bilinear", align_corners=False)


def _fold_batch_norms(sequence: nn.Sequential) -> None:
    """Fold each (eval-mode) batch norm of `sequence` that follows a convolution into it, in place; the norm's
    slot becomes an identity, so the modules keep their indices."""
    for i in range(len(sequence) - 1):
        conv, norm = sequence[i], sequence[i + 1]
        if isinstance(conv, nn.Conv2d) and isinstance(norm, nn.BatchNorm2d):
            sequence[i] = fuse_conv_bn_eval(conv, norm)
            sequence[i + 1] = nn.Identity()


def parameter_count(net: nn.Module) -> int:
    """Trainable parameters of a network."""
    return sum(p.numel() for p in net.parameters() if p.requires_grad)
