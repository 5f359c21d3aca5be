"""A hand-built data set (in memory, no files) for the CAMA release tests: three scenes of six cameras driving
along site x with the ego unrotated, so every camera position and the maps' world origins are hand-computable.

Site origin (1000, 2000). Scene `scene-a` drives y = 0, scene `scene-b` y = 60, scene `scene-c` (not exported:
the night scene) y = 30; each from x = 0 to 40 in 10 m steps, one key frame a second with one sweep between.
The camera offsets are symmetric about ego (1, 0), so a scene's mean camera position is its mean ego position +
(1, 0): scene-a's clip-mode origin is global (1021, 2000). The pose lookup is the logged pose moved up by
`LOOKUP_SHIFT_Z`, source `sfm` for key frames and `wigo+sfm` for sweeps: odometry must carry it.
`annotation_set()` places elements around scene-a and scene-b; `export_release` exports them.
"""

from pathlib import Path

import numpy as np

from annotations.cama_release import CamaReleaseResult, export_cama_release
from annotations.lift import lift_element
from annotations.poses import SourcedPose
from annotations.schema import AnnotationSet, Georeference, MapElement
from cama_pipeline.data import CameraCalibration, CameraImage, Dataset, Frame, Pose, Scene
from tests.annotations.annotation_helpers import element_kwargs

SITE_ORIGIN = (1000.0, 2000.0)
CHANNEL_OFFSETS = {
    "CAM_FRONT": (1.5, 0.0),
    "CAM_FRONT_LEFT": (1.5, 0.5),
    "CAM_FRONT_RIGHT": (1.5, -0.5),
    "CAM_BACK": (0.5, 0.0),
    "CAM_BACK_LEFT": (0.5, 0.5),
    "CAM_BACK_RIGHT": (0.5, -0.5),
}
CAMERA_HEIGHT_M = 1.6
SCENE_Y = {"scene-a": 0.0, "scene-c": 30.0, "scene-b": 60.0}
SCENE_T0_US = {"scene-a": 1_000_000_000, "scene-c": 2_000_000_000, "scene-b": 3_000_000_000}
STEPS_X = (0.0, 10.0, 20.0, 30.0, 40.0)
LOOKUP_SHIFT_Z = 0.25
CAMERA_ROTATION = (0.5, -0.5, 0.5, -0.5)
"""ego_from_cam of a forward-looking camera (cam z forward -> ego x)."""
RASTER_RESOLUTION_M = 0.5
RASTER_ORIGIN_SITE = (-30.0, 100.0)
"""Site metres of our raster's pixel (0, 0) centre; it spans x in [-30, 89.5], y in [-19.5, 100]."""
RASTER_SHAPE = (240, 240)
PLANE = (0.02, -0.01, 5.0)
"""Our raster's heights: z = a * x_site + b * y_site + c."""
RADIUS_M = 10.0
"""The exports' observed radius: scene-a (cameras at y in [-0.5, 0.5]) sees y in [-10.5, 10.5]."""
SITE = "site-7"
SCENES = ("scene-a", "scene-b")
"""The exported scenes (scene-c, the night scene, is left out)."""


def plane_z(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    """The plane the test raster is sampled from (site metres)."""
    a, b, c = PLANE
    return np.asarray(a * np.asarray(x) + b * np.asarray(y) + c)


def raster_georeference() -> Georeference:
    """Our raster's georeference (global metres)."""
    return Georeference(
        site_origin_xy=SITE_ORIGIN,
        origin_xy=(SITE_ORIGIN[0] + RASTER_ORIGIN_SITE[0], SITE_ORIGIN[1] + RASTER_ORIGIN_SITE[1]),
        resolution=RASTER_RESOLUTION_M,
        width=RASTER_SHAPE[1],
        height=RASTER_SHAPE[0],
    )


def plane_raster() -> np.ndarray:
    """Our float32 raster of the plane at the cell centres (columns +x, rows -y)."""
    rows, cols = np.mgrid[0 : RASTER_SHAPE[0], 0 : RASTER_SHAPE[1]]
    x = RASTER_ORIGIN_SITE[0] + cols * RASTER_RESOLUTION_M
    y = RASTER_ORIGIN_SITE[1] - rows * RASTER_RESOLUTION_M
    return plane_z(x, y).astype(np.float32)


def _calibration(channel: str) -> CameraCalibration:
    dx, dy = CHANNEL_OFFSETS[channel]
    return CameraCalibration(
        token=f"calib-{channel}",
        channel=channel,
        ego_from_cam=Pose(np.array([dx, dy, CAMERA_HEIGHT_M]), np.array(CAMERA_ROTATION)),
        intrinsic=np.array([[10.0, 0.0, 8.0], [0.0, 10.0, 4.0], [0.0, 0.0, 1.0]]),
        width=16,
        height=8,
    )


def _scene(name: str) -> Scene:
    """One scene: a key frame per step of STEPS_X a second apart, one sweep half-way to the next."""
    images: dict[str, list[CameraImage]] = {channel: [] for channel in CHANNEL_OFFSETS}
    frames = []
    for index, x in enumerate(STEPS_X):
        sample = f"{name}-sample-{index}"
        key: dict[str, CameraImage] = {}
        for stagger, channel in enumerate(CHANNEL_OFFSETS):
            for sweep in (0, 1) if index < len(STEPS_X) - 1 else (0,):
                t_us = SCENE_T0_US[name] + index * 1_000_000 + sweep * 500_000 + stagger * 8_333
                ego_xy = (SITE_ORIGIN[0] + x + 5.0 * sweep, SITE_ORIGIN[1] + SCENE_Y[name])
                image = CameraImage(
                    token=f"{name}-{channel}-{index}-{sweep}",
                    sample_token=sample,
                    channel=channel,
                    timestamp_us=t_us,
                    is_key_frame=sweep == 0,
                    path=Path(f"/nowhere/{name}/{channel}/{index}-{sweep}.jpg"),
                    global_from_ego=Pose(np.array([*ego_xy, 0.0]), np.array([1.0, 0.0, 0.0, 0.0])),
                    calibration=_calibration(channel),
                )
                images[channel].append(image)
                if sweep == 0:
                    key[channel] = image
        frames.append(Frame(sample, SCENE_T0_US[name] + index * 1_000_000, key))
    return Scene(
        token=f"token-{name}",
        name=name,
        description="Night" if name == "scene-c" else "",
        log_token="log",
        location="test",
        frames=tuple(frames),
        images={channel: tuple(ims) for channel, ims in images.items()},
    )


def release_dataset() -> Dataset:
    """The three scenes as a data set (nothing on disk)."""
    return Dataset(root=Path("/nowhere"), version="v1.0-test", scenes=tuple(_scene(n) for n in SCENE_Y))


def shifted_lookup(image: CameraImage) -> SourcedPose:
    """The test's 'refined' poses: the logged ones moved up by LOOKUP_SHIFT_Z."""
    moved = Pose(
        image.global_from_ego.translation + np.array([0.0, 0.0, LOOKUP_SHIFT_Z]),
        image.global_from_ego.rotation,
    )
    return SourcedPose(moved, "sfm" if image.is_key_frame else "wigo+sfm")


def lookup_camera_pose(image: CameraImage) -> Pose:
    """Camera to global of an image through `shifted_lookup`."""
    return shifted_lookup(image).global_from_ego @ image.calibration.ego_from_cam


def _element(element_id: str, points: list[list[float]], cls: str = "divider") -> MapElement:
    return MapElement.model_validate(element_kwargs(id=element_id, points_2d=points, **{"class": cls}))


def annotation_set(*, site_id: str = "bev", lifted: bool = True) -> AnnotationSet:
    """Hand-placed elements (site metres) around scene-a (y = 0) and scene-b (y = 60)."""
    elements = [
        _element("near-a", [[10.0, 2.0], [20.0, 2.0]]),
        _element("near-b", [[5.0, 58.0], [35.0, 58.0]], "boundary"),
        _element("cross", [[20.0, -19.0], [20.0, 30.0]]),
        _element("zigzag", [[5.0, 5.0], [15.0, 5.0], [15.0, 25.0], [25.0, 25.0], [25.0, 5.0], [35.0, 5.0]]),
        _element("cw", [[30.0, 5.0], [34.0, 5.0], [34.0, 15.0], [30.0, 15.0], [30.0, 5.0]], "ped_crossing"),
        _element("far", [[70.0, 30.0], [80.0, 30.0]]),
        _element("tip", [[20.0, 10.2], [20.0, 30.0]]),
    ]
    georef = raster_georeference()
    if lifted:
        elements = [lift_element(e, plane_raster(), georef) for e in elements]
    return AnnotationSet(site_id=site_id, georeference=georef, elements=elements)


def export_release(out: Path, mode: str = "clip", **kwargs: object) -> CamaReleaseResult:
    """`export_cama_release` of `annotation_set()` over SCENES with the shifted lookup and the plane raster;
    `kwargs` replace any argument (`annotations` too)."""
    args: dict = {  # type: ignore[type-arg]
        "dataset": release_dataset(),
        "poses": shifted_lookup,
        "scenes": SCENES,
        "site_name": SITE,
        "mode": mode,
        "elevation": plane_raster(),
        "observed_radius_m": RADIUS_M,
        **kwargs,
    }
    annotations = args.pop("annotations", annotation_set())
    return export_cama_release(annotations, out, **args)
