"""Cell classes from the class votes of the observation pass, with curbs seen at curb height.

A curb is raised: its face and top, projected onto the road plane, land up to a metre beyond the curb
line (farther the farther the camera), so road-level votes smear the curb over the sidewalk; and the
cells of the curb top itself are voted road at road level by the rays that hit the foot of the face (the
image masks label the face's lower part road). So every cell is voted at two heights, road level and
curb height, and takes the classes of the height at which its views agree more (the larger top class
share): a cell really at that height is seen in place from every camera, the other height smears it
differently for each camera distance. Curb height may only give off-road classes (curb or background);
cells whose road-level vote is not a road class take the curb-height vote as before.
"""

import torch

from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS, Semantic

OFF_ROAD = (Semantic.BACKGROUND, Semantic.CURB)
PAINT = (Semantic.LANE_MARKING, Semantic.CROSSWALK)
"""The paint on the road: never a kerb's foot (`steps`)."""
EPSILON = 1e-3
"""Floor of the class frequencies before the logarithm (logits stay finite)."""


def shares(votes: torch.Tensor) -> torch.Tensor:
    """(V, 5) class votes scaled to shares summing to 1 per row (rows without votes stay 0)."""
    return votes / votes.sum(dim=1, keepdim=True).clamp(min=1e-12)


def fused_logits(ground: torch.Tensor, raised: torch.Tensor | None) -> torch.Tensor:
    """(V, 5) logits from (V, 5) class votes sampled at road level and at curb height (None: the
    road-level votes alone); see the module docstring."""
    ground = shares(ground)
    logits = torch.log(ground + EPSILON)
    if raised is None:
        return logits
    raised = shares(raised)
    road_classes = torch.tensor(ROAD_SURFACE_IDS, device=ground.device)
    off_road_classes = torch.tensor([int(c) for c in OFF_ROAD], device=ground.device)
    has_votes = _off_road_votes(raised).sum(dim=1) > 0
    ground_off_road = ~torch.isin(ground.argmax(dim=1), road_classes)
    raised_agrees_more = torch.isin(raised.argmax(dim=1), off_road_classes) & (
        raised.max(dim=1).values > ground.max(dim=1).values
    )
    off_road = (ground_off_road | raised_agrees_more) & has_votes
    logits[off_road] = curb_height_logits(raised[off_road])
    return logits


def _off_road_votes(raised: torch.Tensor) -> torch.Tensor:
    """(V, 5) the curb-height shares of the off-road classes, 0 for the road classes."""
    columns = [BEV_CLASSES.index(c) for c in OFF_ROAD]
    votes = torch.zeros_like(raised)
    votes[:, columns] = raised[:, columns]
    return votes


def curb_height_logits(raised: torch.Tensor) -> torch.Tensor:
    """(V, 5) logits of cells seen at curb height from their (V, 5) class votes there: off-road classes only
    (curb height may only give curb or background)."""
    return torch.log(_off_road_votes(shares(raised)) + EPSILON)


def curb_logits(count: int, device: torch.device) -> torch.Tensor:
    """(count, 5) logits of cells that are curb whatever their votes: a kerb's foot (`steps`), which the road-level
    vote calls road and the curb-height vote may call sidewalk."""
    shares = torch.zeros((count, len(BEV_CLASSES)), device=device)
    shares[:, BEV_CLASSES.index(Semantic.CURB)] = 1.0
    return torch.log(shares + EPSILON)
