"""The MapTR loss: permutation-equivalent point matching and Hungarian instance matching.

A ground-truth polyline of P fixed points is equivalent to itself reversed; a ring (first == last point)
to every cyclic shift in both directions. The point cost of a prediction against a ground truth is the
smallest mean L1 over those equivalent orderings. Instances are matched one-to-one with the Hungarian
algorithm (scipy) on class cost + point cost; matched predictions learn their class (sigmoid focal loss) and
points (L1 against the best ordering), unmatched ones learn to score low.
"""

import numpy as np
import torch
import torch.nn.functional as F
from scipy.optimize import linear_sum_assignment

from annotations.schema import POLYGON_CLASSES
from models.vma.vectors import CLASSES

_CLOSED_INDICES = [CLASSES.index(c) for c in POLYGON_CLASSES]


def equivalent_orderings(points: torch.Tensor, closed: bool) -> torch.Tensor:
    """(K, P, 2) orderings of one (P, 2) target: both directions, and every start point for rings."""
    if not closed:
        return torch.stack([points, points.flip(0)])
    ring = points[:-1]
    shifts = [torch.roll(ring, -k, dims=0) for k in range(ring.shape[0])]
    forward = [torch.cat([s, s[:1]]) for s in shifts]
    return torch.stack(forward + [f.flip(0) for f in forward])


def focal_cost(
    logits: torch.Tensor, labels: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0
) -> torch.Tensor:
    """(Q, G) focal-loss class cost of assigning each ground truth's label to each prediction (DETR style)."""
    prob = logits.sigmoid()
    neg = (1 - alpha) * prob**gamma * -(1 - prob + 1e-8).log()
    pos = alpha * (1 - prob) ** gamma * -(prob + 1e-8).log()
    return (pos - neg)[:, labels]


def stack_orderings(labels: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """(G, K, P, 2) equivalent orderings of every target, padded to the most orderings by repeating the first."""
    options = [
        equivalent_orderings(t, int(c) in _CLOSED_INDICES) for c, t in zip(labels, points, strict=True)
    ]
    most = max(o.shape[0] for o in options)
    return torch.stack([torch.cat([o, o[:1].expand(most - o.shape[0], -1, -1)]) for o in options])


def point_costs(pred: torch.Tensor, orderings: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(Q, G) mean L1 under each target's best ordering, and (Q, G) index of that ordering."""
    l1 = (pred[:, None, None] - orderings[None]).abs().mean(dim=(3, 4))  # (Q, G, K)
    return l1.min(dim=2)


def match_and_loss(
    logits: torch.Tensor,
    points_per_layer: list[torch.Tensor],
    labels: list[torch.Tensor],
    targets: list[torch.Tensor],
    class_weight: float,
    point_weight: float,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Total loss over a batch (points of every decoder layer supervised with the final layer's matching)."""
    class_target = torch.zeros_like(logits)
    point_loss = logits.new_zeros(())
    matched = 0
    for b in range(logits.shape[0]):
        if labels[b].numel() == 0:
            continue
        orderings = stack_orderings(labels[b], targets[b])
        with torch.no_grad():
            cost_points, best = point_costs(points_per_layer[-1][b], orderings)
            cost = class_weight * focal_cost(logits[b], labels[b]) + point_weight * cost_points
            rows, cols = linear_sum_assignment(cost.cpu().numpy())
        rows_t = torch.as_tensor(rows, device=logits.device)
        cols_t = torch.as_tensor(cols, device=logits.device)
        class_target[b, rows_t, labels[b][cols_t]] = 1.0
        chosen = orderings[cols_t, best[rows_t, cols_t]]  # (M, P, 2)
        for layer_points in points_per_layer:
            point_loss = point_loss + (layer_points[b][rows_t] - chosen).abs().mean(dim=(1, 2)).sum()
        matched += len(rows)
    class_loss = _sigmoid_focal(logits, class_target).sum() / max(1, matched)
    point_loss = point_loss / max(1, matched) / len(points_per_layer)
    total = class_weight * class_loss + point_weight * point_loss
    return total, {
        "class": float(class_loss.detach()),
        "points": float(point_loss.detach()),
        "matched": float(matched),
    }


def _sigmoid_focal(
    logits: torch.Tensor, target: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0
) -> torch.Tensor:
    prob = logits.sigmoid()
    ce = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    p_t = prob * target + (1 - prob) * (1 - target)
    weight = alpha * target + (1 - alpha) * (1 - target)
    return weight * ce * (1 - p_t) ** gamma


def batch_targets(samples_labels: list[np.ndarray], samples_points: list[np.ndarray], device: torch.device):
    """Per-sample label and point tensors on `device`."""
    return (
        [torch.as_tensor(lab, device=device) for lab in samples_labels],
        [torch.as_tensor(pts, device=device) for pts in samples_points],
    )
