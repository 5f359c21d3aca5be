"""One ego body per camera: the segmenter's per-image EGO pixels made consistent through the clips of a camera.

The ego body (the trunk lid in CAM_BACK) is fixed to the camera, so it covers the same pixels in every image the
camera takes. A per-image network gets its edges and reflections wrong differently from frame to frame (site
9001's CAM_BACK: 18 % of the true body labelled road), and sometimes marks a few ego pixels in cameras that see
no body. Here, per camera (calibrated_sensor), the body is

    the pixels the network labels EGO in at least `vote_share` of the camera's images (a per-pixel vote)
    united with the pixels that stay constant through the camera's moving clips (`cama_pipeline.segment.ego`,
    kept where at least half of the clips that give an estimate agree),

and every mask of the camera gets exactly that body: body pixels become EGO, EGO pixels outside it take the label
of the nearest non-EGO pixel. The constant-pixel witness is independent of the network, so it fills what the
network misses in every frame alike; the vote keeps the body of a camera whose clips stand still.
`bench/segment.py` reports the IoU with and without this step.
"""

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from cama_pipeline.segment.ego import EgoConfig
from cama_pipeline.semantics import Semantic

EGO = int(Semantic.EGO)


@dataclass(frozen=True)
class EgoClipConfig:
    """How the segment stage makes each camera's ego body consistent (see the module docstring)."""

    enabled: bool = True
    vote_share: float = 0.5
    """A pixel is body when the network labels it EGO in at least this share of the camera's images."""
    constant: EgoConfig = field(default_factory=EgoConfig)
    """How the constant-pixel witness is estimated per clip."""

    def __post_init__(self) -> None:
        if not 0 < self.vote_share <= 1:
            raise ValueError(f"EgoClipConfig.vote_share must be in (0, 1], got {self.vote_share}")

    def to_json(self) -> dict[str, object]:
        return {
            "enabled": self.enabled,
            "vote_share": self.vote_share,
            "constant": dict(self.constant.__dict__),
        }


class EgoVote:
    """Per-pixel count of the masks of one camera that label EGO, fed one mask at a time (masks are not held)."""

    def __init__(self) -> None:
        self.counts: np.ndarray | None = None
        self.masks = 0

    def add(self, semantic: np.ndarray) -> None:
        """Count one (H, W) semantic mask; all masks of a camera have one size (ValueError otherwise)."""
        ego = (semantic == EGO).astype(np.int32)
        if self.counts is None:
            self.counts = ego
        elif self.counts.shape != ego.shape:
            raise ValueError(f"mask of shape {semantic.shape} among masks of shape {self.counts.shape}")
        else:
            self.counts += ego
        self.masks += 1

    def voted(self, share: float) -> np.ndarray:
        """(H, W) bool: pixels labelled EGO in at least `share` of the masks counted."""
        if self.counts is None:
            raise ValueError("no mask was counted")
        return np.asarray(self.counts >= share * self.masks)


def agreed_constant(estimates: Sequence[np.ndarray]) -> np.ndarray | None:
    """(H, W) bool: the pixels found constant in at least half of the clips' estimates; None without one."""
    if not estimates:
        return None
    stacked = np.stack([np.asarray(e, bool) for e in estimates])
    return np.asarray(stacked.sum(axis=0) * 2 >= len(estimates))


def camera_body(vote: EgoVote, constant_estimates: Iterable[np.ndarray], share: float) -> np.ndarray:
    """(H, W) bool ego body of one camera: the network's vote united with the clips' agreed constant pixels."""
    body = vote.voted(share)
    constant = agreed_constant(list(constant_estimates))
    if constant is not None:
        if constant.shape != body.shape:
            raise ValueError(f"ego estimate of shape {constant.shape} for masks of shape {body.shape}")
        body = body | constant
    return body


def with_body(semantic: np.ndarray, body: np.ndarray) -> np.ndarray:
    """`semantic` with exactly `body` labelled EGO: body pixels become EGO; EGO pixels outside the body take the
    label of the nearest pixel that is neither (the whole mask is returned unchanged when nothing differs)."""
    if semantic.shape != body.shape:
        raise ValueError(f"mask of shape {semantic.shape} and ego body of shape {body.shape} differ")
    ego = semantic == EGO
    stray = ego & ~body
    out = semantic.copy()
    if stray.any():
        source = ~(ego | body)
        if source.any():
            _, (rows, cols) = ndimage.distance_transform_edt(~source, return_indices=True)
            out[stray] = semantic[rows[stray], cols[stray]]
        else:
            out[stray] = int(Semantic.BACKGROUND)
    out[body] = EGO
    return out
