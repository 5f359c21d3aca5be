"""MapTR-ready export: per nuScenes sample (key frame), the 3D vectors in its ego frame, clipped and resampled.

One JSON file: {"meta": {...}, "samples": [{"sample_token", "scene", "timestamp", "ego_pose": {"translation",
"rotation"}, "pose_source", "vectors": [{"class", "points": [[x, y, z] x 20], "source_id"}]}]}. Ego pose = the
CAM_FRONT key-frame image's `global_from_ego` (else the sample's first image by channel name) from the export's
pose lookup (`annotations.poses`: refined by default in `cama export`), `pose_source` saying which. Vectors are clipped to
MAPTR_RANGE (ego x forward, y left) and each piece resampled to 20 points, so import is not lossless w.r.t. the
original elements: it gives one element per exported vector, at its resampled points.
"""

import json
import logging
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import AliasChoices, BaseModel, ConfigDict, Field, ValidationError, model_validator

from annotations.cama_format import format_validation_error, read_json_file, validate_file
from annotations.geometry import MAPTR_RANGE, Box, clip_to_box, resample_fixed
from annotations.poses import PoseLookup, PoseSource
from annotations.schema import ELEMENT_CLASSES, AnnotationSet, ElementClass, Georeference, MapElement
from annotations.transforms import (
    ego_from_global_points,
    global_from_ego_points,
    global_from_site_points,
    rotation_from_quaternion,
    site_from_global_points,
)
from cama_pipeline.data import Dataset, Frame
from cama_pipeline.io import atomic_write_bytes

logger = logging.getLogger(__name__)

MAPTR_FORMAT: Literal["cama-studio-maptr-vectors"] = "cama-studio-maptr-vectors"
POINTS_PER_VECTOR = 20
REFERENCE_CHANNEL = "CAM_FRONT"
IMPORT_AUTHOR = "maptr-import"

Point3 = tuple[float, float, float]


class EgoPose(BaseModel):
    """global_from_ego of a sample: translation (global metres) and rotation quaternion w, x, y, z."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    translation: Point3
    rotation: tuple[float, float, float, float] = Field(description="Quaternion w, x, y, z.")


class MaptrVector(BaseModel):
    """One clipped, resampled vector in the sample's ego frame."""

    model_config = ConfigDict(
        extra="forbid",
        allow_inf_nan=False,
        validate_by_name=True,
        validate_by_alias=True,
        serialize_by_alias=True,
    )

    cls: ElementClass = Field(validation_alias=AliasChoices("class", "cls"), serialization_alias="class")
    points: list[Point3] = Field(min_length=2, description="[x, y, z] ego metres.")
    source_id: str = Field(description="Id of the element this vector was cut from.")


class MaptrSample(BaseModel):
    """One nuScenes sample (key frame) with its ego pose and vectors."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    sample_token: str = Field(min_length=1)
    scene: str
    timestamp: int = Field(description="Microseconds.")
    ego_pose: EgoPose
    pose_source: PoseSource = Field(
        default="coarse",
        description="Where ego_pose came from: sfm, wigo+sfm (WIGO corrected by SfM), wigo, or coarse (logged).",
    )
    vectors: list[MaptrVector]


class PerceptionRange(BaseModel):
    """The ego-frame box vectors are clipped to (metres)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    xmin: float
    xmax: float
    ymin: float
    ymax: float


class MaptrMeta(BaseModel):
    """File-level metadata a training-data converter needs."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    format: Literal["cama-studio-maptr-vectors"] = MAPTR_FORMAT
    format_version: Literal[1] = 1
    site_id: str
    classes: list[ElementClass] = Field(default_factory=lambda: list(ELEMENT_CLASSES))
    perception_range: PerceptionRange
    points_per_vector: int = Field(ge=2)
    ego_frame: Literal["x forward, y left, z up"] = "x forward, y left, z up"
    georeference: Georeference | None = Field(default=None, description="Site georeference, for import.")


class MaptrFile(BaseModel):
    """The whole MapTR vectors file."""

    model_config = ConfigDict(extra="forbid")

    meta: MaptrMeta
    samples: list[MaptrSample]

    @model_validator(mode="after")
    def _points_per_vector(self) -> "MaptrFile":
        """Every vector has `meta.points_per_vector` points."""
        n = self.meta.points_per_vector
        for i, sample in enumerate(self.samples):
            for j, vector in enumerate(sample.vectors):
                if len(vector.points) != n:
                    raise ValueError(
                        f"samples[{i}].vectors[{j}].points: {len(vector.points)} points, expected {n}"
                    )
        return self


def sample_pose(frame: Frame, poses: PoseLookup) -> tuple[EgoPose, PoseSource]:
    """global_from_ego of a key frame from `poses`: its CAM_FRONT image's, else its first image's by channel
    name; with the pose's source."""
    if not frame.images:
        raise ValueError(f"sample {frame.token!r}: no camera images, so no ego pose")
    image = frame.images.get(REFERENCE_CHANNEL) or frame.images[sorted(frame.images)[0]]
    sourced = poses(image)
    pose = sourced.global_from_ego
    ego = EgoPose(translation=tuple(pose.translation.tolist()), rotation=tuple(pose.rotation.tolist()))
    return ego, sourced.source


def element_global_points(element: MapElement, georef: Georeference, ground_z: float) -> np.ndarray:
    """(N, 3) global points of an element: its 3D points, else its 2D points at `ground_z`."""
    xyz = element.xyz()
    if xyz is None:
        xyz = np.column_stack([element.xy(), np.full(len(element.points_2d), ground_z)])
    return global_from_site_points(xyz, georef.site_origin_xy)


def sample_vectors(
    annotations: AnnotationSet, pose: EgoPose, *, box: Box = MAPTR_RANGE, n_points: int = POINTS_PER_VECTOR
) -> list[MaptrVector]:
    """The set's vectors in one sample's ego frame, clipped to `box`, each piece resampled to `n_points`."""
    rotation = rotation_from_quaternion(pose.rotation)
    vectors = []
    for element in annotations.elements:
        xyz = element_global_points(element, annotations.georeference, pose.translation[2])
        ego = ego_from_global_points(xyz, rotation, pose.translation)
        for piece in clip_to_box(ego, *box, closed=element.closed):
            points = resample_fixed(piece, n_points)
            vectors.append(
                MaptrVector(cls=element.cls, points=[tuple(p) for p in points.tolist()], source_id=element.id)
            )
    return vectors


def build_maptr(
    annotations: AnnotationSet,
    dataset: Dataset,
    *,
    poses: PoseLookup,
    box: Box = MAPTR_RANGE,
    n_points: int = POINTS_PER_VECTOR,
    frame_pose: Callable[[Frame], tuple[EgoPose, PoseSource]] | None = None,
    on_sample: Callable[[], None] | None = None,
    scenes: Collection[str] | None = None,
) -> MaptrFile:
    """The MapTR file model for every key frame of the data set (of `scenes` when given), ego poses (and their
    sources) from `poses`.

    `frame_pose`: another choice of a sample's reference ego pose (the nuScenes-CAMAv2 export takes LIDAR_TOP's
    where there is one); None: `sample_pose`. `on_sample`: called after each sample (progress)."""
    flat = sum(1 for e in annotations.elements if e.points_3d is None)
    if flat:
        logger.warning("%d elements have no 3D points: exported at the ego pose's height", flat)
    samples = []
    for scene in dataset.scenes:
        if scenes is not None and scene.name not in scenes:
            continue
        for frame in scene.frames:
            pose, source = sample_pose(frame, poses) if frame_pose is None else frame_pose(frame)
            vectors = sample_vectors(annotations, pose, box=box, n_points=n_points)
            samples.append(
                MaptrSample(
                    sample_token=frame.token,
                    scene=scene.name,
                    timestamp=frame.timestamp_us,
                    ego_pose=pose,
                    pose_source=source,
                    vectors=vectors,
                )
            )
            if on_sample is not None:
                on_sample()
    meta = MaptrMeta(
        site_id=annotations.site_id,
        perception_range=PerceptionRange(**box._asdict()),
        points_per_vector=n_points,
        georeference=annotations.georeference,
    )
    return MaptrFile(meta=meta, samples=samples)


def export_maptr(
    annotations: AnnotationSet,
    dataset: Dataset,
    out: Path,
    *,
    poses: PoseLookup,
    box: Box = MAPTR_RANGE,
    n_points: int = POINTS_PER_VECTOR,
    scenes: Collection[str] | None = None,
) -> Path:
    """Write the MapTR vectors JSON to `out` (the key frames of `scenes`, else of every scene), validated as import
    will read it; returns the path."""
    model = build_maptr(annotations, dataset, poses=poses, box=box, n_points=n_points, scenes=scenes)
    return write_maptr(model, out)


def write_maptr(model: MaptrFile, out: Path) -> Path:
    """Write a MapTR file model to `out`, validated as import will read it; returns the path."""
    text = model.model_dump_json(by_alias=True, indent=1)
    validate_file(MaptrFile, json.loads(text), Path(out))
    atomic_write_bytes(Path(out), text.encode("utf-8"))
    logger.info("exported %d samples to %s", len(model.samples), out)
    return Path(out)


def read_maptr(path: Path) -> MaptrFile:
    """Read and validate a MapTR vectors file; ValueError naming the file and field."""
    return validate_file(MaptrFile, read_json_file(Path(path)), Path(path))


def import_maptr(
    path: Path, *, site_id: str | None = None, georeference: Georeference | None = None
) -> AnnotationSet:
    """Vectors back to site coordinates, one element per vector (id `<sample>/<source_id>/<k>`)."""
    data = read_maptr(path)
    georef = georeference or data.meta.georeference
    if georef is None:
        raise ValueError(f"{path}: meta.georeference: missing; pass a georeference to import")
    elements = []
    for i, sample in enumerate(data.samples):
        rotation = rotation_from_quaternion(sample.ego_pose.rotation)
        for k, vector in enumerate(sample.vectors):
            xyz = global_from_ego_points(vector.points, rotation, sample.ego_pose.translation)
            site = site_from_global_points(xyz, georef.site_origin_xy)
            try:
                elements.append(
                    MapElement(
                        id=f"{sample.sample_token}/{vector.source_id}/{k}",
                        cls=vector.cls,
                        points_2d=[(x, y) for x, y in site[:, :2].tolist()],
                        points_3d=[(x, y, z) for x, y, z in site.tolist()],
                        source="human",
                        author=IMPORT_AUTHOR,
                    )
                )
            except ValidationError as error:
                where = f"samples[{i}].vectors[{k}]"
                raise ValueError(f"{path}: {where}: {format_validation_error('element', error)}") from error
    return AnnotationSet(site_id=site_id or data.meta.site_id, georeference=georef, elements=elements)
