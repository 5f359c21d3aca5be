"""A hand-made reconstruction for the fixture data set: a site manifest, WIGO poses and SfM poses, each a known
global shift of the logged poses, so every refined pose has a hand-computable value."""

import numpy as np

from cama_pipeline.data import CameraImage, Dataset, Pose
from cama_pipeline.sfm.io import PoseEntry, write_poses
from cama_pipeline.site.io import write_site_manifest, write_sites_index
from cama_pipeline.wigo.io import PoseRecord, WigoFile, write_wigo
from cama_pipeline.workspace import Workspace

SITE_ID = "site-a"
WIGO_SHIFT = np.array([1.0, 2.0, 0.0])
"""WIGO poses: the logged poses moved by this (global metres)."""


def shifted(pose: Pose, shift: np.ndarray) -> Pose:
    """`pose` moved by a global translation."""
    return Pose(np.zeros(3) + shift, np.array([1.0, 0.0, 0.0, 0.0])) @ pose


def sfm_images(dataset: Dataset) -> list[CameraImage]:
    """The images SfM 'posed': the CAM_FRONT key frames."""
    return [im for im in dataset.scenes[0].images["CAM_FRONT"] if im.is_key_frame]


def sfm_shift(index: int) -> np.ndarray:
    """The SfM pose of the index-th SfM image: the logged one moved up by 0.5 + index metres."""
    return np.array([0.0, 0.0, 0.5 + index])


def write_reconstruction(dataset: Dataset, workspace: Workspace, *, with_sfm: bool = True) -> None:
    """Sites index, manifest and WIGO file of the fixture's one scene, and (with_sfm) its SfM poses.json."""
    scene = dataset.scenes[0]
    write_sites_index(
        workspace.sites_index(),
        {
            "fingerprint": "f",
            "config": {},
            "sites": [{"site_id": SITE_ID, "scenes": [scene.name]}],
            "dropped": [],
        },
    )
    write_site_manifest(
        workspace.site_manifest(SITE_ID), {"site_id": SITE_ID, "scenes": [{"scene": scene.name}], "poses": {}}
    )
    records = [
        PoseRecord(
            token=im.token,
            channel=im.channel,
            timestamp_us=im.timestamp_us,
            translation=np.array(shifted(im.global_from_ego, WIGO_SHIFT).translation),
            rotation=np.array(im.global_from_ego.rotation),
            covariance=None,
        )
        for im in scene.all_images()
    ]
    write_wigo(workspace.wigo(scene.name), WigoFile(scene.name, scene.token, "f", {}, {}, [], tuple(records)))
    if with_sfm:
        entries = {
            im.token: PoseEntry(
                name=str(im.path),
                scene=scene.name,
                channel=im.channel,
                world_from_ego=shifted(im.global_from_ego, sfm_shift(i)).matrix(),
                flagged=False,
            )
            for i, im in enumerate(sfm_images(dataset))
        }
        write_poses(workspace.sfm_poses(SITE_ID), site_id=SITE_ID, digest="f", poses=entries)


def expected_shift(dataset: Dataset, image: CameraImage) -> np.ndarray:
    """Hand computation of an image's refined shift over its logged pose: the SfM shifts interpolated linearly
    in time between the SfM images around it (held beyond the ends, which lie within the gap in the fixture)."""
    times = [im.timestamp_us for im in sfm_images(dataset)]
    z = [sfm_shift(i)[2] for i in range(len(times))]
    return np.array([0.0, 0.0, float(np.interp(image.timestamp_us, times, z))])
