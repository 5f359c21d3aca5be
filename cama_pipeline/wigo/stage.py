"""The WIGO stage: fuse every scene of a data set and write `wigo/<scene>.json` into the workspace."""

import logging
import time
from collections.abc import Sequence
from pathlib import Path

from scipy.spatial.transform import Rotation

from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, Scene, load_dataset
from cama_pipeline.data.schema import CAN_DIR, CAN_MESSAGES, can_file_name
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.fusion import FusedPoses, fuse_clip, height_is_free
from cama_pipeline.wigo.inputs import NoWheelSpeeds, clip_inputs, logged_poses
from cama_pipeline.wigo.io import PoseRecord, WigoFile, read_wigo, write_wigo
from cama_pipeline.wigo.logged_only import logged_pose_clip
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


def select_scenes(dataset: Dataset, names: Sequence[str] | None) -> tuple[Scene, ...]:
    """The named scenes (all when None); ValueError naming an unknown one and listing the known."""
    if not names:
        return dataset.scenes
    known = {s.name: s for s in dataset.scenes}
    missing = [n for n in names if n not in known]
    if missing:
        raise ValueError(f"unknown scene(s) {missing}; the data set has {sorted(known)}")
    return tuple(known[n] for n in names)


def scene_fingerprint(dataset: Dataset, scene: Scene, config: WigoConfig) -> str:
    """Hash of the config and of the tables and CAN files the fusion of `scene` reads."""
    inputs = [dataset.version_dir / "sample_data.json", dataset.version_dir / "ego_pose.json"]
    inputs += [dataset.root / CAN_DIR / can_file_name(scene.name, m) for m in CAN_MESSAGES]
    return fingerprint(
        "wigo", code_version("cama_pipeline.wigo"), config.to_json(), scene.token, file_stats(inputs)
    )


def fuse_scene(scene: Scene, config: WigoConfig) -> FusedPoses:
    """WIGO's poses of one scene: the fusion of its inputs, or for a scene without wheel speeds its logged poses
    passed through (`WigoConfig.without_wheels`; NoWheelSpeeds when that is `refuse`)."""
    cameras = logged_poses(scene)
    try:
        inputs = clip_inputs(scene, cameras)
    except NoWheelSpeeds as error:
        if config.without_wheels == "refuse":
            raise
        logger.warning("%s: passing the logged ego poses through", error)
        return logged_pose_clip(scene.name, cameras, config)
    return fuse_clip(inputs, config)


def to_wigo_file(fused: FusedPoses, scene: Scene, digest: str, config: WigoConfig) -> WigoFile:
    """The on-disk record of one scene's fused poses."""
    quats = Rotation.from_matrix(fused.rotation).as_quat(canonical=True, scalar_first=True)
    poses = tuple(
        PoseRecord(token, channel, int(t), fused.translation[i], quats[i], fused.covariance[i])
        for i, (token, channel, t) in enumerate(
            zip(fused.tokens, fused.channels, fused.times_us, strict=True)
        )
    )
    return WigoFile(
        scene.name, scene.token, digest, config.to_json(), fused.report, fused.node_times_us.tolist(), poses
    )


def run(
    config: WigoConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    scenes: Sequence[str] | None = None,
    overwrite: bool = False,
    show_progress: bool = True,
    dataset: Dataset | None = None,
) -> StageResult:
    """Fuse the scenes of the data set at `dataset_root` (default workspace: beside the data set); one item
    per scene, its report the fusion's (as stored in the pose file).

    A scene whose output holds the same fingerprint (config + input files) is skipped unless `overwrite`.
    `dataset` may pass an already loaded data set of the same root.
    """
    started = time.perf_counter()
    if dataset is None:
        dataset = load_dataset(Path(dataset_root), check_files=False, scenes=scenes or None)
    ws = Workspace.resolve(workspace, Path(dataset_root))
    chosen = select_scenes(dataset, scenes)
    items: list[ItemResult] = []
    with StageProgress("wigo", logger=logger, enabled=show_progress, transient=True) as progress:
        bar = progress.add_task("fuse scenes", total=len(chosen))
        for scene in chosen:
            path = ws.wigo(scene.name)
            digest = scene_fingerprint(dataset, scene, config)
            if not overwrite and is_up_to_date(path, digest):
                logger.info("scene %s: %s is up to date", scene.name, path)
                items.append(ItemResult(scene.name, path, read_wigo(path).report, skipped=True))
            else:
                wigo = to_wigo_file(fuse_scene(scene, config), scene, digest, config)
                write_wigo(path, wigo)
                items.append(ItemResult(scene.name, path, wigo.report, skipped=False))
            progress.advance(bar)
    return StageResult("wigo", ws, tuple(items), time.perf_counter() - started)


def free_height_scenes(workspace: Workspace, scenes: Sequence[str]) -> frozenset[str]:
    """The scenes whose WIGO poses left the height free (2D logged poses, no GNSS; a scene without a WIGO file
    counts as measured)."""
    free = set()
    for scene in scenes:
        path = workspace.wigo(scene)
        if path.is_file() and height_is_free(read_wigo(path).report):
            free.add(scene)
    return frozenset(free)
