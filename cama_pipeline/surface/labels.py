"""Cell classes from the class votes of the observation pass, with curbs seen at curb height.

A curb is raised: its face and top, projected onto the road plane, land up to a metre beyond the curb
line (farther the farther the camera), so road-level votes smear the curb over the sidewalk. Cells whose
road-level vote is a road class keep it; the others (curb or background) take the vote of the same cell
sampled at curb height, where the curb top and the sidewalk beyond it are seen in place.
"""

import torch

from cama_pipeline.semantics import BEV_CLASSES, Semantic

ROAD_SURFACE = (Semantic.ROAD, Semantic.LANE_MARKING, Semantic.CROSSWALK)
OFF_ROAD = (Semantic.BACKGROUND, Semantic.CURB)
EPSILON = 1e-3
"""Floor of the class frequencies before the logarithm (logits stay finite)."""


def fused_logits(ground: torch.Tensor, raised: torch.Tensor | None) -> torch.Tensor:
    """(V, 5) logits from (V, 5) class frequencies sampled at road level and at curb height (None: the
    road-level votes alone)."""
    logits = torch.log(ground + EPSILON)
    if raised is None:
        return logits
    road_classes = torch.tensor([int(c) for c in ROAD_SURFACE], device=ground.device)
    columns = [BEV_CLASSES.index(c) for c in OFF_ROAD]
    votes = torch.zeros_like(ground)
    votes[:, columns] = raised[:, columns]
    off_road = ~torch.isin(ground.argmax(dim=1), road_classes) & (votes.sum(dim=1) > 0)
    logits[off_road] = torch.log(votes[off_road] + EPSILON)
    return logits
