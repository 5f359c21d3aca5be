"""The learned VMA proposer: a small MapTR-style network in torch.

A CNN backbone turns the (one-hot semantic + RGB) BEV patch into a stride-8 feature map; a transformer
decoder runs hierarchical queries (instance query + point query, as MapTR) over it, each layer refining the
points; an instance's class scores come from its pooled point features. Outputs are logits per class
(sigmoid scores, no background class) and normalised patch points in [0, 1]. The anchored variant
(`ModelConfig.anchored`, `models.vma.anchors`) initialises instance queries and reference points from
rule-based candidates; its point heads start at zero, so an untrained model returns the candidates' points.
"""

import math

import torch
from torch import nn

from models.vma.anchors import ANCHOR_FEATURES
from models.vma.config import ModelConfig
from models.vma.vectors import CLASSES


def _conv(cin: int, cout: int, stride: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)
    )


def _sine_positions(height: int, width: int, dim: int) -> torch.Tensor:
    """(H * W, dim) 2D sine position encoding of feature cells, in normalised coordinates."""
    quarter = dim // 4
    freq = torch.exp(torch.arange(quarter) * (-math.log(1000.0) / quarter)) * 2 * math.pi
    ys, xs = torch.meshgrid(
        (torch.arange(height) + 0.5) / height, (torch.arange(width) + 0.5) / width, indexing="ij"
    )
    parts = [f(c.reshape(-1, 1) * freq) for c in (xs, ys) for f in (torch.sin, torch.cos)]
    return torch.cat(parts, dim=1)


class VmaNet(nn.Module):
    """MapTR-style vector detector over one BEV patch."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        d = config.dim
        self.backbone = nn.Sequential(
            _conv(config.in_channels, 32, 2),
            _conv(32, 64, 2),
            _conv(64, d, 1),
            _conv(d, d, 2),
            _conv(d, d, 1),
        )
        side = config.patch_px // 8
        self.register_buffer("memory_pos", _sine_positions(side, side, d), persistent=False)
        self.instance_queries = nn.Embedding(config.num_queries, d)
        self.point_queries = nn.Embedding(config.num_points, d)
        self.layers = nn.ModuleList(
            nn.TransformerDecoderLayer(d, config.heads, 2 * d, dropout=0.0, batch_first=True, norm_first=True)
            for _ in range(config.decoder_layers)
        )
        self.point_in = nn.Linear(2, d)
        self.point_heads = nn.ModuleList(nn.Linear(d, 2) for _ in range(config.decoder_layers))
        class_out = nn.Linear(d, len(CLASSES))
        nn.init.constant_(class_out.bias, -4.0)  # rare positives: start with low scores
        self.class_head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, d), nn.ReLU(), class_out)
        self.reference = nn.Linear(d, 2)
        if config.anchored:
            self.anchor_embed = nn.Sequential(
                nn.Linear(ANCHOR_FEATURES + 2 * config.num_points, d), nn.ReLU(), nn.Linear(d, d)
            )
            for parameter in self.point_heads.parameters():
                nn.init.zeros_(parameter)

    def forward(
        self, images: torch.Tensor, anchors: tuple[torch.Tensor, torch.Tensor] | None = None
    ) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """(B, C, S, S) [+ anchor points (B, Q, P, 2) and features (B, Q, F)] -> class logits (B, Q, K) and
        per-layer points [(B, Q, P, 2) in [0, 1]]. Anchors are required by, and only accepted by, anchored models."""
        if (anchors is not None) != self.config.anchored:
            raise ValueError(
                f"VmaNet: anchored={self.config.anchored} model given anchors={anchors is not None}"
            )
        batch = images.shape[0]
        q, p, d = self.config.num_queries, self.config.num_points, self.config.dim
        features = self.backbone(images).flatten(2).transpose(1, 2)
        memory = features + self.memory_pos
        instance = self.instance_queries.weight.unsqueeze(0).expand(batch, -1, -1)
        if anchors is not None:
            anchor_points, anchor_features = anchors
            filled = anchor_features[..., -1:]
            embedded = self.anchor_embed(torch.cat([anchor_features, anchor_points.flatten(2)], dim=2))
            instance = instance + filled * embedded
        queries = (instance[:, :, None, :] + self.point_queries.weight[None, None]).reshape(batch, q * p, d)
        logit_points = self.reference(queries)
        if anchors is not None:
            anchored = torch.logit(anchor_points.clamp(1e-3, 1 - 1e-3)).reshape(batch, q * p, 2)
            logit_points = torch.where(filled.repeat_interleave(p, dim=1) > 0, anchored, logit_points)
        all_points = []
        for layer, head in zip(self.layers, self.point_heads, strict=True):
            hidden = layer(queries + self.point_in(torch.sigmoid(logit_points)), memory)
            logit_points = logit_points.detach() + head(hidden)
            all_points.append(torch.sigmoid(logit_points).reshape(batch, q, p, 2))
            queries = hidden
        logits = self.class_head(queries.reshape(batch, q, p, d).mean(dim=2))
        return logits, all_points
