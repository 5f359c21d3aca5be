"""SRE results: per-image records, the CAMA aggregation (camera -> frame -> scene -> overall means), JSON.

An image's SRE is the mean error of its matched pairs, its precision matched / projected, its recall
matched / image instances; each is left out of the means where undefined (no match, nothing projected, no
instance). Under the `cama` protocol an image without a matched pair is left out of all three, as CAMA's code
leaves out such a camera. F1 is computed from the mean precision and recall, as the CAMA code does.
"""

import math
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from cama_pipeline.evaluate.sre import ImageMatch, SreConfig


@dataclass(frozen=True)
class ImageSre:
    """The evaluation of one camera image."""

    scene: str
    frame: str
    """Sample token."""
    channel: str
    image: str
    """sample_data token."""
    width_px: int
    match: ImageMatch
    reference_width_px: int = 960
    require_match: bool = False
    """True: without a matched pair the image does not count at all (precision and recall undefined too), the
    `cama` protocol's rule; False: precision and recall count whenever something was projected / seen."""

    @property
    def counted(self) -> bool:
        """Whether precision and recall may count: always, or only with a match when `require_match`."""
        return bool(self.match.pairs) or not self.require_match

    @property
    def sre_px(self) -> float | None:
        """Mean matched error in the image's own pixels, None without matches."""
        errors = [p.error_px for p in self.match.pairs]
        return sum(errors) / len(errors) if errors else None

    @property
    def sre_ref_px(self) -> float | None:
        """The same at the reference width (960 px)."""
        sre = self.sre_px
        return None if sre is None else sre * self.reference_width_px / self.width_px

    @property
    def precision(self) -> float | None:
        """Matched / projected instances."""
        if not self.counted or not self.match.projected:
            return None
        return len(self.match.pairs) / self.match.projected

    @property
    def recall(self) -> float | None:
        """Matched / image instances."""
        n = self.match.image_instances
        return len(self.match.pairs) / n if n and self.counted else None


@dataclass(frozen=True)
class SreSummary:
    """Aggregated figures over a set of images."""

    sre_px: float | None
    """SRE in the images' own pixels."""
    sre_ref_px: float | None
    """SRE at the reference width (960x540 for 16:9 images), comparable with the paper."""
    precision: float | None
    recall: float | None
    f1: float | None
    images: int
    scored_images: int
    """Images with at least one matched pair (the only ones the `cama` protocol counts)."""
    projected: int
    image_instances: int
    matched: int


def hierarchical_mean(images: Sequence[ImageSre], value: Callable[[ImageSre], float | None]) -> float | None:
    """Mean over scenes of the mean over frames of the mean over cameras, skipping undefined values."""
    by_scene: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for image in images:
        v = value(image)
        if v is not None:
            by_scene[image.scene][image.frame].append(v)
    scene_means = [_mean([_mean(cams) for cams in frames.values()]) for frames in by_scene.values()]
    return _mean(scene_means) if scene_means else None


def summarise(images: Sequence[ImageSre]) -> SreSummary:
    """The CAMA aggregation of a set of image results."""
    precision = hierarchical_mean(images, lambda im: im.precision)
    recall = hierarchical_mean(images, lambda im: im.recall)
    f1 = None
    if precision is not None and recall is not None:
        f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return SreSummary(
        sre_px=hierarchical_mean(images, lambda im: im.sre_px),
        sre_ref_px=hierarchical_mean(images, lambda im: im.sre_ref_px),
        precision=precision,
        recall=recall,
        f1=f1,
        images=len(images),
        scored_images=sum(bool(im.match.pairs) for im in images),
        projected=sum(im.match.projected for im in images),
        image_instances=sum(im.match.image_instances for im in images),
        matched=sum(len(im.match.pairs) for im in images),
    )


@dataclass(frozen=True)
class SreReport:
    """SRE / precision / recall / F1 overall, per scene and per camera, with the per-image records."""

    overall: SreSummary
    per_scene: dict[str, SreSummary]
    per_camera: dict[str, SreSummary]
    images: tuple[ImageSre, ...]
    config: SreConfig

    @classmethod
    def from_images(cls, images: Sequence[ImageSre], config: SreConfig) -> "SreReport":
        """Aggregate image results into the report."""
        scenes = sorted({im.scene for im in images})
        cameras = sorted({im.channel for im in images})
        return cls(
            overall=summarise(images),
            per_scene={s: summarise([im for im in images if im.scene == s]) for s in scenes},
            per_camera={c: summarise([im for im in images if im.channel == c]) for c in cameras},
            images=tuple(images),
            config=config,
        )

    def to_json(self, *, with_images: bool = True) -> dict[str, Any]:
        """A JSON-ready dict (NaN-free: undefined figures are null)."""
        out: dict[str, Any] = {
            "protocol": self.config.protocol,
            "overall": asdict(self.overall),
            "per_scene": {k: asdict(v) for k, v in self.per_scene.items()},
            "per_camera": {k: asdict(v) for k, v in self.per_camera.items()},
            "config": config_json(self.config),
        }
        if with_images:
            out["images"] = [_image_json(im) for im in self.images]
        return out


def config_json(config: SreConfig) -> dict[str, Any]:
    """The settings that applied: the strict fields, or the protocol constants of `cama`."""
    out = asdict(config)
    if config.protocol == "cama":
        return {k: out[k] for k in ("protocol", "class_pairs", "reference_width_px", "cama")}
    del out["cama"]
    return out


def _image_json(image: ImageSre) -> dict[str, Any]:
    """One image's record for the JSON report."""
    return {
        "scene": image.scene,
        "frame": image.frame,
        "channel": image.channel,
        "image": image.image,
        "width_px": image.width_px,
        "projected": image.match.projected,
        "image_instances": image.match.image_instances,
        "sre_px": image.sre_px,
        "pairs": [[p.element_id, p.instance_value, round(p.error_px, 4)] for p in image.match.pairs],
    }


def _mean(values: Sequence[float]) -> float:
    """Arithmetic mean of a non-empty sequence."""
    total = math.fsum(values)
    return total / len(values)
