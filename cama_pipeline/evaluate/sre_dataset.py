"""SRE over a data set: every key-frame camera image of the chosen scenes, with coarse or true poses, under
the `strict` protocol (the project's own) or the `cama` protocol (CAMA's published metric code)."""

import logging
from collections.abc import Collection, Mapping, Sequence

import numpy as np

from cama_pipeline.data import CameraImage, Dataset, Frame, Pose
from cama_pipeline.evaluate.inputs import EvaluationInputError, VectorElement
from cama_pipeline.evaluate.projection import PinholeCamera, project_polyline
from cama_pipeline.evaluate.sre import ProjectedInstance, SreConfig, extract_instances, match_image
from cama_pipeline.evaluate.sre_cama_config import SreProtocol
from cama_pipeline.evaluate.sre_cama_protocol import DenseMap, densify_map, evaluate_frame
from cama_pipeline.evaluate.sre_report import ImageSre, SreReport
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)


def evaluate_sre(
    dataset: Dataset,
    elements: Sequence[VectorElement],
    config: SreConfig,
    *,
    true_poses: Mapping[str, Pose] | None = None,
    scenes: Sequence[str] | None = None,
    images: Collection[str] | None = None,
    show_progress: bool = False,
) -> SreReport:
    """SRE / precision / recall of a vector map over key-frame images (true poses when given, else coarse),
    under `config.protocol`; `images` restricts it to those image tokens (e.g. the ones a reconstruction
    posed)."""
    chosen = [s for s in dataset.scenes if scenes is None or s.name in scenes]
    if scenes is not None and len(chosen) != len(set(scenes)):
        missing = sorted(set(scenes) - {s.name for s in chosen})
        raise EvaluationInputError(f"{dataset.root}: no scene named {', '.join(missing)}")
    map_classes = {m for m, _ in config.class_pairs}
    used = [e for e in elements if e.cls in map_classes]
    cama = config.protocol == "cama"
    first = 1 if cama and config.cama.skip_first_frame else 0
    work = [
        (s.name, f, [im for im in f.images.values() if images is None or im.token in images])
        for s in chosen
        for f in s.frames[first:]
    ]
    dense = densify_map(used, config.cama) if cama else None
    results: list[ImageSre] = []
    with StageProgress("sre", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("images", total=sum(len(w[2]) for w in work))
        for scene, frame, frame_images in work:
            if dense is not None:
                results.extend(_evaluate_frame_cama(scene, frame, frame_images, true_poses, dense, config))
            else:
                for image in frame_images:
                    pose = _pose_for(image, true_poses)
                    results.append(_evaluate_image(scene, frame.token, image, pose, used, config))
            progress.advance(bar, len(frame_images))
    logger.info("evaluated %d images of %d scenes (%s protocol)", len(results), len(chosen), config.protocol)
    return SreReport.from_images(results, config)


def sre_for_dataset(
    dataset: Dataset,
    elements: Sequence[VectorElement],
    *,
    protocol: SreProtocol = "strict",
    poses: Mapping[str, Pose] | None = None,
    scenes: Sequence[str] | None = None,
    images: Collection[str] | None = None,
    show_progress: bool = False,
) -> SreReport:
    """SRE / precision / recall / F1 of lane markings under a protocol's default settings; `poses` are
    `global_from_ego` by camera sample_data token (the data set's logged ego poses when None)."""
    config = SreConfig(protocol=protocol)
    return evaluate_sre(
        dataset,
        elements,
        config,
        true_poses=poses,
        scenes=scenes,
        images=images,
        show_progress=show_progress,
    )


def camera_for(image: CameraImage, global_from_ego: Pose) -> PinholeCamera:
    """The pinhole camera of an image under a given ego pose."""
    global_from_cam = global_from_ego @ image.calibration.ego_from_cam
    calibration = image.calibration
    return PinholeCamera(
        global_from_cam.rotation_matrix(),
        global_from_cam.translation,
        calibration.intrinsic,
        calibration.width,
        calibration.height,
    )


def project_elements(
    elements: Sequence[VectorElement], camera: PinholeCamera, config: SreConfig, flat_z_m: float
) -> list[ProjectedInstance]:
    """Project every element into a camera; 2D elements get z = `flat_z_m` (the flat-ground assumption)."""
    out = []
    for element in elements:
        points = element.points
        if not element.has_elevation:
            points = np.column_stack([points, np.full(len(points), flat_z_m)])
        pieces = project_polyline(points, camera, config.projection, closed=element.closed)
        if pieces:
            out.append(ProjectedInstance(element.id, element.cls, tuple(pieces)))
    return out


def _evaluate_image(
    scene: str,
    frame: str,
    image: CameraImage,
    global_from_ego: Pose,
    elements: Sequence[VectorElement],
    config: SreConfig,
) -> ImageSre:
    """Project, extract, match one image."""
    camera = camera_for(image, global_from_ego)
    projected = project_elements(elements, camera, config, float(global_from_ego.translation[2]))
    scale = config.scale(camera.width)
    instances = extract_instances(
        image.load_instance(),
        {int(m) for _, m in config.class_pairs},
        max(1, round(config.min_skeleton_px * scale)),
    )
    match = match_image(projected, instances, config, camera.width)
    return ImageSre(scene, frame, image.channel, image.token, camera.width, match, config.reference_width_px)


def _evaluate_frame_cama(
    scene: str,
    frame: Frame,
    images: Sequence[CameraImage],
    true_poses: Mapping[str, Pose] | None,
    dense: DenseMap,
    config: SreConfig,
) -> list[ImageSre]:
    """One frame under the cama protocol: every camera through the ego pose of the frame's front camera (CAMA's
    chassis pose), or each through its own when `frame_pose_channel` is None. A frame without a front camera
    image, or whose front image the given poses lack, is skipped (logged), as CAMA's code skips a frame it has
    no pose for."""
    channel = config.cama.frame_pose_channel
    if not images:
        return []
    if channel is None:
        own = [_pose_for(image, true_poses) for image in images]
        return evaluate_frame(scene, frame.token, images, own, dense, config)
    front = frame.images.get(channel)
    if front is None or (true_poses is not None and front.token not in true_poses):
        logger.warning("frame %s of %s: no %s pose, skipped as CAMA's code does", frame.token, scene, channel)
        return []
    return evaluate_frame(scene, frame.token, images, _pose_for(front, true_poses), dense, config)


def _pose_for(image: CameraImage, true_poses: Mapping[str, Pose] | None) -> Pose:
    """The true pose of an image when true poses are given (missing one is an error), else its coarse pose."""
    if true_poses is None:
        return image.global_from_ego
    try:
        return true_poses[image.token]
    except KeyError:
        raise EvaluationInputError(f"true poses have no entry for camera image {image.token!r}") from None
