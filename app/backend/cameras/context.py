"""A site's camera context: its data set, the refined poses of its key-frame images and its elevation raster,
loaded once per site and kept in memory until one of the files it was read from changes (mtime or size).

The posed views are the key-frame camera images whose refined pose came from SfM (source `sfm`): only those
are offered by the view selection. A site without a data set or without a reconstruction gets a context with
no views and a notice saying why (the panel shows it); nothing here raises for a missing input.
"""

import hashlib
import logging
import os
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from annotations.schema import Georeference
from cama_pipeline.bev import layer_path, read_layer
from cama_pipeline.data import CameraImage, Dataset, Pose, load_dataset
from cama_pipeline.data.masks import MAKERS, has_masks, mask_roots
from cama_pipeline.data.schema import INSTANCE_DIR
from cama_pipeline.evaluate.projection import PinholeCamera
from cama_pipeline.evaluate.sre_dataset import camera_for
from cama_pipeline.refined_poses import RefinedPose, refined_poses, site_scenes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

NO_DATASET = "no camera images: the site was registered without a data set (dataset_root)"
UNREADABLE_DATASET = "the site's data set cannot be read; ask the server's operator"
NO_RECONSTRUCTION = "no reconstruction: camera views need `cama sfm`'s poses"
NO_SFM_IMAGES = "no key-frame image of the site has an SfM pose; camera views need `cama sfm`'s poses"


@dataclass(frozen=True)
class SiteSources:
    """Where one site's cameras come from (the site's registration), plain values, no database."""

    site_id: int
    georeference: Georeference
    """The site's raster georeference with its origin: site metres = global - site_origin_xy."""
    raster_dir: Path
    dataset_root: Path | None = None
    workspace_dir: Path | None = None
    recon_site_id: str | None = None


@dataclass(frozen=True, eq=False)
class PosedView:
    """One key-frame camera image with its refined pose and the pinhole camera it gives (global metres)."""

    token: str
    scene: str
    channel: str
    timestamp_us: int
    image: CameraImage
    global_from_ego: Pose
    pose_source: str
    camera: PinholeCamera

    @property
    def width(self) -> int:
        """Full image width in pixels."""
        return self.camera.width

    @property
    def height(self) -> int:
        """Full image height in pixels."""
        return self.camera.height


@dataclass(frozen=True, eq=False)
class CameraContext:
    """Everything the camera endpoints need of one site, read once (see the module docstring)."""

    sources: SiteSources
    dataset: Dataset | None
    views: tuple[PosedView, ...]
    """The posed views (key frames with an SfM pose), scene, time and channel order."""
    poses: dict[str, RefinedPose]
    """Refined pose of every camera image of the reconstruction's scenes (any source), by token."""
    elevation: np.ndarray | None
    """The site's elevation raster (global z, NaN unobserved), None when the raster folder has none."""
    images: int
    """Key-frame camera images (of the reconstruction's scenes when there is one, else of the data set)."""
    mask_source: str | None
    """Where the lane masks come from: `dataset`, `predicted`, `imported`, or None when there are none."""
    notice: str | None
    """Why there are no views (None when there are)."""
    poses_digest: str
    """A digest of the posed views' tokens and poses: changes whenever a reconstruction changes them."""
    scene_of: dict[str, str] = field(default_factory=dict)
    """Scene name of every camera image token of the data set."""
    by_token: dict[str, PosedView] = field(init=False)
    centres: np.ndarray = field(init=False)
    """(V, 3) camera centres of the views, global metres."""
    rotations: np.ndarray = field(init=False)
    """(V, 3, 3) global_from_cam rotations of the views."""
    intrinsics: np.ndarray = field(init=False)
    """(V, 3, 3) pinhole matrices of the views."""
    sizes: np.ndarray = field(init=False)
    """(V, 2) image width and height of the views."""

    def __post_init__(self) -> None:
        cameras = [view.camera for view in self.views]
        arrays = {
            "by_token": {view.token: view for view in self.views},
            "centres": np.array([c.global_from_cam_translation for c in cameras]).reshape(-1, 3),
            "rotations": np.array([c.global_from_cam_rotation for c in cameras]).reshape(-1, 3, 3),
            "intrinsics": np.array([c.intrinsic for c in cameras]).reshape(-1, 3, 3),
            "sizes": np.array([(c.width, c.height) for c in cameras], dtype=np.float64).reshape(-1, 2),
        }
        for name, value in arrays.items():
            object.__setattr__(self, name, value)

    @property
    def site_origin_xy(self) -> tuple[float, float]:
        """Global metres of the site origin."""
        return self.sources.georeference.site_origin_xy

    @property
    def available(self) -> bool:
        """Whether any view can be offered."""
        return bool(self.views)


def _pose_digest(views: list[PosedView]) -> str:
    """sha256 (shortened) over the posed views' tokens and ego poses."""
    digest = hashlib.sha256()
    for view in views:
        digest.update(view.token.encode())
        digest.update(np.ascontiguousarray(view.global_from_ego.matrix(), dtype=np.float64).tobytes())
    return digest.hexdigest()[:16]


def _mask_roots(sources: SiteSources, dataset_root: Path) -> tuple[tuple[Path, ...], str | None]:
    """The lane-mask roots (data set first, then the workspace's predicted and imported) and the first one's
    name; only the data set's own masks without a workspace."""
    if sources.workspace_dir is None:
        roots: tuple[Path, ...] = (dataset_root,) if has_masks(dataset_root) else ()
    else:
        roots = mask_roots("auto", dataset_root, Workspace(sources.workspace_dir))
    with_lanes = [root for root in roots if (root / INSTANCE_DIR).is_dir()]
    if not with_lanes:
        return roots, None
    first = with_lanes[0]
    if first == dataset_root.absolute():
        return roots, "dataset"
    return roots, next((name for name in MAKERS if first.name == name), "imported")


def _elevation(raster_dir: Path, georeference: Georeference) -> np.ndarray | None:
    """The elevation layer as float64 when present and shaped as the georeference; None (logged) otherwise."""
    try:
        elevation = np.asarray(read_layer(raster_dir, "elevation"), dtype=np.float64)
    except (FileNotFoundError, ValueError) as error:
        logger.info("%s: no usable elevation raster for the camera panel: %s", raster_dir, error)
        return None
    if elevation.shape != georeference.shape:
        logger.warning("%s: elevation shape %s does not match the georeference", raster_dir, elevation.shape)
        return None
    return elevation


def _posed_views(dataset: Dataset, poses: dict[str, RefinedPose], scenes: list[str]) -> list[PosedView]:
    """Key-frame images of `scenes` with an SfM pose, as posed views."""
    views = []
    for scene in dataset.scenes:
        if scene.name not in scenes:
            continue
        for frame in scene.frames:
            for channel in sorted(frame.images):
                image = frame.images[channel]
                refined = poses.get(image.token)
                if refined is None or refined.source != "sfm":
                    continue
                pose = refined.global_from_ego
                camera = camera_for(image, pose)
                views.append(
                    PosedView(
                        image.token, scene.name, channel, image.timestamp_us, image, pose, "sfm", camera
                    )
                )
    return views


def _reconstruction_scenes(sources: SiteSources) -> list[str] | None:
    """The scenes of the site's reconstruction, the only ones the panel shows, so that only they are read of a large
    data set; None (every scene) when there is no reconstruction to read them from."""
    if sources.workspace_dir is None or sources.recon_site_id is None:
        return None
    try:
        return site_scenes(Workspace(sources.workspace_dir), sources.recon_site_id) or None
    except (FileNotFoundError, ValueError, KeyError) as error:
        logger.info("site %d: no reconstruction for the camera panel: %s", sources.site_id, error)
        return None


def _reconstruction(
    sources: SiteSources, dataset: Dataset, scenes: list[str] | None
) -> tuple[dict[str, RefinedPose], list[str], str | None]:
    """Refined poses, the reconstruction's scenes (`_reconstruction_scenes`) and a notice when there is no
    reconstruction."""
    if sources.workspace_dir is None or sources.recon_site_id is None or scenes is None:
        return {}, [], NO_RECONSTRUCTION
    workspace = Workspace(sources.workspace_dir)
    try:
        poses = refined_poses(dataset, workspace, sources.recon_site_id, scenes=scenes)
    except (FileNotFoundError, ValueError, KeyError) as error:
        logger.info("site %d: no reconstruction for the camera panel: %s", sources.site_id, error)
        return {}, [], NO_RECONSTRUCTION
    return poses, scenes, None


def _without_images(sources: SiteSources, elevation: np.ndarray | None, notice: str) -> CameraContext:
    """The context of a site whose data set is missing or unreadable."""
    return CameraContext(sources, None, (), {}, elevation, 0, None, notice, poses_digest="")


def load_context(sources: SiteSources) -> CameraContext:
    """Read a site's camera context (seconds for a large data set: the caller caches it, see `ContextCache`)."""
    elevation = _elevation(sources.raster_dir, sources.georeference)
    if sources.dataset_root is None:
        return _without_images(sources, elevation, NO_DATASET)
    root = sources.dataset_root
    scenes_read = _reconstruction_scenes(sources)
    try:
        roots, mask_source = _mask_roots(sources, root)
        dataset = load_dataset(root, check_files=False, mask_roots=roots, scenes=scenes_read)
    except (OSError, ValueError) as error:
        logger.warning("site %d: data set %s unreadable: %s", sources.site_id, root, error)
        return _without_images(sources, elevation, UNREADABLE_DATASET)
    poses, scenes, notice = _reconstruction(sources, dataset, scenes_read)
    views = _posed_views(dataset, poses, scenes)
    if notice is None and not views:
        notice = NO_SFM_IMAGES
    counted = [s for s in dataset.scenes if not scenes or s.name in scenes]
    scene_of = {im.token: s.name for s in dataset.scenes for ims in s.images.values() for im in ims}
    logger.info("site %d: camera context with %d posed views", sources.site_id, len(views))
    return CameraContext(
        sources=sources,
        dataset=dataset,
        views=tuple(views),
        poses=poses,
        elevation=elevation,
        images=sum(len(frame.images) for scene in counted for frame in scene.frames),
        mask_source=mask_source,
        notice=notice,
        poses_digest=_pose_digest(views),
        scene_of=scene_of,
    )


def watched_files(sources: SiteSources) -> list[Path]:
    """The files a context is read from (present or not): any change to one of them reloads it."""
    files = [layer_path(sources.raster_dir, "elevation")]
    root = sources.dataset_root
    if root is not None and root.is_dir():
        for version in sorted(p for p in root.iterdir() if (p / "scene.json").is_file()):
            files.extend(sorted(version.glob("*.json")))
    if sources.workspace_dir is not None and sources.recon_site_id is not None:
        workspace = Workspace(sources.workspace_dir)
        files += [workspace.sfm_poses(sources.recon_site_id), workspace.site_manifest(sources.recon_site_id)]
        files += [workspace.wigo(scene) for scene in workspace.wigo_scenes()]
        files += [workspace.masks_manifest(source) for source in MAKERS]
    return files


def signature(files: list[Path]) -> tuple[tuple[str, int, int], ...]:
    """(path, mtime_ns, size) of each file; (path, -1, -1) for a missing one."""
    out = []
    for path in files:
        try:
            stat = os.stat(path)
            out.append((str(path), stat.st_mtime_ns, stat.st_size))
        except OSError:
            out.append((str(path), -1, -1))
    return tuple(out)


@dataclass
class _Entry:
    sources: SiteSources
    files: list[Path]
    signature: tuple[tuple[str, int, int], ...]
    context: CameraContext


@dataclass
class ContextCache:
    """Camera contexts by site id, reloaded when the site's sources or the files they were read from change;
    one lock per site, so concurrent first requests load once."""

    entries: dict[int, _Entry] = field(default_factory=dict)
    locks: dict[int, threading.Lock] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def get(self, sources: SiteSources) -> CameraContext:
        """The site's context, loaded on first use and after any change."""
        with self.lock:
            site_lock = self.locks.setdefault(sources.site_id, threading.Lock())
        with site_lock:
            entry = self.entries.get(sources.site_id)
            if entry is not None and entry.sources == sources and signature(entry.files) == entry.signature:
                return entry.context
            files = watched_files(sources)
            before = signature(files)
            context = load_context(sources)
            self.entries[sources.site_id] = _Entry(sources, files, before, context)
            return context

    def forget(self, site_id: int) -> None:
        """Drop a site's context (e.g. a deleted site)."""
        with self.lock:
            self.entries.pop(site_id, None)
