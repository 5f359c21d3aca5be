"""Refined ego poses of a site's images, for the exports: the SfM pose where SfM posed the image, else the WIGO
trajectory corrected by the SfM keyframes around it.

For an image SfM posed (not flagged) the pose is its `poses.json` world_from_ego (source `sfm`). For any other
image of the site's scenes with a WIGO pose: at every SfM-posed image of the scene the correction
`global_from_global = T_sfm @ T_wigo^-1` is known; the image's correction is interpolated in SE(3) by timestamp
between the nearest SfM-posed images before and after it (slerp of the rotation, lerp of the translation) and
applied to its WIGO pose (source `wigo+sfm`). With an SfM keyframe on one side only (the clip's ends), that
side's correction is held when it lies within `max_gap_us`; with none near, the WIGO pose stands alone
(source `wigo`). Images with no WIGO pose fall back to the data set's logged pose (source `coarse`).
"""

import bisect
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from annotations.poses import PoseLookup, PoseSource, SourcedPose
from cama_pipeline.data import CameraImage, Dataset, Pose
from cama_pipeline.sfm.io import matrix_to_quaternion, read_refined_poses
from cama_pipeline.site.io import manifest_scenes, read_site_manifest
from cama_pipeline.wigo.io import read_wigo
from cama_pipeline.workspace import Workspace

MAX_GAP_US = 5_000_000
"""How far (microseconds) a one-sided SfM correction is held beyond the last SfM keyframe."""


@dataclass(frozen=True)
class RefinedPose:
    """One image's refined global_from_ego and where it came from."""

    global_from_ego: Pose
    source: PoseSource


@dataclass(frozen=True)
class TimedPose:
    """A pose at a time (microseconds)."""

    timestamp_us: int
    pose: Pose


def pose_from_matrix(matrix: np.ndarray) -> Pose:
    """The Pose of a (4, 4) rigid matrix."""
    return Pose(np.asarray(matrix)[:3, 3], matrix_to_quaternion(np.asarray(matrix)[:3, :3]))


def slerp(q0: np.ndarray, q1: np.ndarray, alpha: float) -> np.ndarray:
    """Spherical interpolation of unit quaternions [w, x, y, z] (the shorter arc), alpha in [0, 1]."""
    q0, q1 = np.asarray(q0, dtype=np.float64), np.asarray(q1, dtype=np.float64)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 1.0 - 1e-12:
        q = q0 + alpha * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(min(dot, 1.0))
    return (np.sin((1.0 - alpha) * theta) * q0 + np.sin(alpha * theta) * q1) / np.sin(theta)


def interpolate_pose(a: TimedPose, b: TimedPose, timestamp_us: int) -> Pose:
    """SE(3) interpolation between two timed poses (slerp rotation, lerp translation); a == b time gives a."""
    span = b.timestamp_us - a.timestamp_us
    alpha = 0.0 if span == 0 else min(max((timestamp_us - a.timestamp_us) / span, 0.0), 1.0)
    translation = (1.0 - alpha) * a.pose.translation + alpha * b.pose.translation
    return Pose(translation, slerp(a.pose.rotation, b.pose.rotation, alpha))


def corrected_pose(
    wigo: Pose, timestamp_us: int, corrections: list[TimedPose], *, max_gap_us: int = MAX_GAP_US
) -> RefinedPose:
    """A WIGO pose corrected by the corrections (time-sorted global_from_global at SfM keyframes) around it."""
    times = [c.timestamp_us for c in corrections]
    after = bisect.bisect_left(times, timestamp_us)
    before = after - 1 if after == len(times) or times[after] != timestamp_us else after
    if 0 <= before and after < len(times):
        correction = interpolate_pose(corrections[before], corrections[after], timestamp_us)
    elif 0 <= before and timestamp_us - times[before] <= max_gap_us:
        correction = corrections[before].pose
    elif after < len(times) and times[after] - timestamp_us <= max_gap_us:
        correction = corrections[after].pose
    else:
        return RefinedPose(wigo, "wigo")
    return RefinedPose(correction @ wigo, "wigo+sfm")


def site_scenes(workspace: Workspace, site_id: str) -> list[str]:
    """The scenes of a site, from its manifest (FileNotFoundError naming it when absent)."""
    path = workspace.site_manifest(site_id)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no site manifest for {site_id!r}")
    return manifest_scenes(read_site_manifest(path))


def _required(path: Path) -> Path:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    return path


def refined_poses(
    dataset: Dataset,
    workspace: Workspace,
    site_id: str,
    *,
    max_gap_us: int = MAX_GAP_US,
    scenes: Sequence[str] | None = None,
) -> dict[str, RefinedPose]:
    """sample_data token -> refined global_from_ego for every camera image of the site's scenes (see the module
    docstring; `scenes`: the site's as `site_scenes` read them, when the caller has); FileNotFoundError naming
    the first missing input (site manifest, SfM poses, WIGO file)."""
    scenes = site_scenes(workspace, site_id) if scenes is None else scenes
    sfm = read_refined_poses(_required(workspace.sfm_poses(site_id)))
    by_name = {scene.name: scene for scene in dataset.scenes}
    out: dict[str, RefinedPose] = {}
    for name in scenes:
        wigo = read_wigo(_required(workspace.wigo(name)))
        wigo_poses = {r.token: TimedPose(r.timestamp_us, Pose(r.translation, r.rotation)) for r in wigo.poses}
        corrections = sorted(
            (
                TimedPose(timed.timestamp_us, pose_from_matrix(sfm[token]) @ timed.pose.inverse())
                for token, timed in wigo_poses.items()
                if token in sfm
            ),
            key=lambda c: c.timestamp_us,
        )
        scene = by_name.get(name)
        images = scene.all_images() if scene is not None else []
        for image in images:
            if image.token in sfm:
                out[image.token] = RefinedPose(pose_from_matrix(sfm[image.token]), "sfm")
            elif image.token in wigo_poses:
                timed = wigo_poses[image.token]
                out[image.token] = corrected_pose(
                    timed.pose, timed.timestamp_us, corrections, max_gap_us=max_gap_us
                )
    return out


def refined_pose_lookup(poses: dict[str, RefinedPose]) -> PoseLookup:
    """The exports' pose lookup over refined poses; an image without one gets its logged pose (`coarse`)."""

    def lookup(image: CameraImage) -> SourcedPose:
        refined = poses.get(image.token)
        if refined is None:
            return SourcedPose(image.global_from_ego, "coarse")
        return SourcedPose(refined.global_from_ego, refined.source)

    return lookup
