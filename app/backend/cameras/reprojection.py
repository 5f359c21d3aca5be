"""Per-element reprojection figures: how well one map element agrees with the lane masks of the images that see it.

This is the paper's Algorithm 2 (`cama_pipeline.evaluate.sre`) applied to one element at a time: the element is
lifted through the elevation raster (`views.lift_site_points`), the images that see it are the camera panel's
own choice (`views.select`: every candidate, or the 12 best spread along the element when more see it), and in
each image it is projected (`project_polyline` under the SRE's projection settings), the image's lane instances
of its class are skeletonised (`extract_instances`; divider -> lane marking, boundary -> curb) and matched
(`match_image`, Hungarian under the 30 px gate at 960 px width).

The element is matched alone, not together with its neighbours, so its figures depend only on its own geometry
and the site's poses, elevation and masks: exactly what the cache key (element id, element version, inputs
digest) names. Alone, the one-to-one assignment picks the image instance nearest to it under the gate.

Figures (`ReprojectionFigures`):
- `sre_px`: the SRE at 960x540 (`SreSummary.sre_ref_px`: mean matched error, averaged per frame, then scene);
  None when no image matched it;
- `matched_share`: of the images where the element was scored (projected long enough, the image has a lane
  mask), the share where it matched an instance; None when none was scored;
- `images`: how many images were scored.

Crosswalks are not scored: Algorithm 2 compares line markings and curbs with the skeleton of their mask
instances, and a crosswalk's outline is not the skeleton of its painted area (figures None, with a notice).
"""

import hashlib
import logging
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from weakref import WeakKeyDictionary

import numpy as np
from numpy.typing import ArrayLike

from app.backend.cameras.context import CameraContext, PosedView
from app.backend.cameras.views import LiftedElement, lift_site_points, select
from cama_pipeline.data import DatasetError
from cama_pipeline.evaluate.projection import project_polyline
from cama_pipeline.evaluate.sre import (
    ImageInstance,
    ProjectedInstance,
    SreConfig,
    extract_instances,
    match_image,
)
from cama_pipeline.evaluate.sre_report import ImageSre, summarise
from cama_pipeline.semantics import Semantic

logger = logging.getLogger(__name__)

MAX_IMAGES = 12
"""At most this many images score an element (the best spread along it when more see it)."""
MASK_CLASSES: dict[str, Semantic] = {"divider": Semantic.LANE_MARKING, "boundary": Semantic.CURB}
"""The lane-instance class each scored map class is matched against."""
SRE_CONFIG = SreConfig(class_pairs=tuple((cls, int(mask)) for cls, mask in MASK_CLASSES.items()))
"""The strict protocol's settings (30 px gate at 960 px, 50 m range), dividers and boundaries."""
NOT_SCORED = "crosswalks are not scored: Algorithm 2 matches line markings and curbs, not painted areas"
NO_LANE_MASKS = "no lane masks for the images that see this element"
INSTANCE_CACHE_ENTRIES = 1024
"""Images whose skeletonised lane instances are kept in memory."""


@dataclass(frozen=True)
class ReprojectionFigures:
    """One element's figures (see the module docstring)."""

    sre_px: float | None
    matched_share: float | None
    images: int
    notice: str | None = None
    """Why there are no figures (no reconstruction, a crosswalk, no masks), else None."""


@dataclass
class InstanceCache:
    """Skeletonised lane instances by image (LRU), keyed by the mask file's path, mtime and size: skeletons are
    the costly part of scoring, and neighbouring elements share their images."""

    entries: int = INSTANCE_CACHE_ENTRIES
    _items: "OrderedDict[tuple[str, int, int], list[ImageInstance]]" = field(default_factory=OrderedDict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def get(self, view: PosedView) -> list[ImageInstance] | None:
        """The view's lane instances of the scored classes; None when it has no lane mask."""
        path = view.image.instance_mask_path
        if path is None:
            return None
        try:
            stat = os.stat(path)
        except OSError:
            return None
        key = (str(path), stat.st_mtime_ns, stat.st_size)
        with self._lock:
            found = self._items.get(key)
            if found is not None:
                self._items.move_to_end(key)
                return found
        instances = _extract(view)
        with self._lock:
            self._items[key] = instances
            while len(self._items) > self.entries:
                self._items.popitem(last=False)
        return instances


def _extract(view: PosedView) -> list[ImageInstance]:
    """Skeletonised instances of the scored classes of a view's instance mask (empty when unreadable, logged)."""
    try:
        mask = view.image.load_instance()
    except (DatasetError, OSError, ValueError) as error:
        logger.warning("image %s: lane mask unreadable: %s", view.token, error)
        return []
    min_px = max(1, round(SRE_CONFIG.min_skeleton_px * SRE_CONFIG.scale(view.width)))
    return extract_instances(mask, {int(mask_class) for mask_class in MASK_CLASSES.values()}, min_px)


_DIGESTS: "WeakKeyDictionary[CameraContext, str]" = WeakKeyDictionary()
_DIGESTS_LOCK = threading.Lock()


def inputs_digest(context: CameraContext) -> str:
    """What the figures depend on besides the element: the posed views' poses (`poses_digest`), the elevation
    raster the element is lifted through and where the masks come from; computed once per context."""
    with _DIGESTS_LOCK:
        found = _DIGESTS.get(context)
    if found is not None:
        return found
    digest = hashlib.sha256(context.poses_digest.encode())
    digest.update(str(context.mask_source).encode())
    if context.elevation is not None:
        digest.update(np.ascontiguousarray(context.elevation).tobytes())
    value = digest.hexdigest()[:32]
    with _DIGESTS_LOCK:
        _DIGESTS[context] = value
    return value


def scoring_views(context: CameraContext, lifted: LiftedElement) -> list[PosedView]:
    """The views that score an element: every one that sees it, or the MAX_IMAGES best spread along it."""
    chosen = select(context, lifted, MAX_IMAGES, all_=True)
    if len(chosen) > MAX_IMAGES:
        chosen = sorted(chosen, key=lambda choice: (-choice.score, choice.token))[:MAX_IMAGES]
    return [context.by_token[choice.token] for choice in chosen]


def score_view(
    view: PosedView, element: ProjectedInstance | None, instances: list[ImageInstance]
) -> ImageSre:
    """One image's Algorithm 2 record for one projected element (None: nothing of it long enough in view)."""
    match = match_image([element] if element is not None else [], instances, SRE_CONFIG, view.width)
    return ImageSre(
        view.scene,
        view.image.sample_token,
        view.channel,
        view.token,
        view.width,
        match,
        SRE_CONFIG.reference_width_px,
    )


def element_figures(
    context: CameraContext,
    cls: str,
    points_site_2d: ArrayLike,
    *,
    instances: InstanceCache,
    element_id: str = "element",
) -> ReprojectionFigures:
    """The reprojection figures of one element (class and 2D site polyline); ValueError for a bad polyline."""
    if not context.available:
        return ReprojectionFigures(None, None, 0, context.notice)
    if cls not in MASK_CLASSES:
        return ReprojectionFigures(None, None, 0, NOT_SCORED)
    lifted = lift_site_points(context, points_site_2d)
    points = lifted.global_points(context.site_origin_xy)
    records: list[ImageSre] = []
    views = scoring_views(context, lifted)
    masked = 0
    for view in views:
        image_instances = instances.get(view)
        if image_instances is None:
            continue
        masked += 1
        pieces = project_polyline(points, view.camera, SRE_CONFIG.projection)
        projected = ProjectedInstance(element_id, cls, tuple(pieces)) if pieces else None
        record = score_view(view, projected, image_instances)
        if record.match.projected:
            records.append(record)
    return figures_of(records, notice=NO_LANE_MASKS if views and not masked else None)


def figures_of(records: Sequence[ImageSre], *, notice: str | None = None) -> ReprojectionFigures:
    """Figures of an element's scored images (each with the element projected in it)."""
    if not records:
        return ReprojectionFigures(None, None, 0, notice)
    summary = summarise(records)
    sre = summary.sre_ref_px
    return ReprojectionFigures(
        sre_px=None if sre is None else round(sre, 3),
        matched_share=round(summary.scored_images / summary.images, 4),
        images=summary.images,
        notice=notice,
    )
