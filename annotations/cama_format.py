"""Our older CAMA layout (one folder per site, `export_cama`), kept until its callers move to the public release
layout (`annotations.cama_release.export_cama_release`); and the CAMA names other modules import from here.

Layout written under `<out>/<name>/` (name = scene or site):
  maps/map_labels.json   list of instances (`annotations.cama_labels`); `data` in pixels of the annotation set's
                         raster (our convention: column grows with +x, row with -y, pixel (0, 0)'s centre at
                         `origin_xy`).
  maps/elevation.npy     the (H, W) float32 elevation raster (global z, NaN = unobserved), when given.
  maps/georeference.json our extension (sidecar version 1, `annotations.cama_sidecar`): site id + Georeference.
  odometry/camera_<CHANNEL>.txt  TUM rows `t x y z qx qy qz qw` (camera to global, t seconds), with a data set.
  odometry/pose_sources.json     our extension: per odometry file, the count of rows per pose source and each
                                 row's source (`annotations.poses`), in row order.

Import of every CAMA layout is `annotations.cama_import.import_cama` (re-exported here).
"""

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from annotations.cama_import import (
    DEFAULT_RELEASE_RESOLUTION_M,
    ELEVATION,
    IMPORT_AUTHOR,
    import_cama,
    release_elevation_path,
)
from annotations.cama_labels import (
    CAMA_TYPE_FROM_CLASS,
    CLASS_FROM_CAMA_TYPE,
    MAP_LABELS,
    CamaAttrs,
    CamaInstance,
    CamaMapLabels,
    CamaType,
    class_from_cama_type,
    format_validation_error,
    read_json_file,
    validate_file,
)
from annotations.cama_sidecar import CamaGeoreferenceFile
from annotations.poses import POSE_SOURCES, PoseLookup, PoseSource
from annotations.schema import AnnotationSet
from annotations.transforms import pixel_from_site_points
from cama_pipeline.data import Dataset
from cama_pipeline.io import atomic_write_bytes, atomic_write_npy

__all__ = [
    "CAMA_TYPE_FROM_CLASS",
    "CLASS_FROM_CAMA_TYPE",
    "DEFAULT_RELEASE_RESOLUTION_M",
    "ELEVATION",
    "GEOREFERENCE",
    "IMPORT_AUTHOR",
    "MAP_LABELS",
    "CamaAttrs",
    "CamaGeoreferenceFile",
    "CamaInstance",
    "CamaMapLabels",
    "CamaType",
    "cama_instances",
    "class_from_cama_type",
    "export_cama",
    "format_validation_error",
    "import_cama",
    "read_json_file",
    "release_elevation_path",
    "validate_file",
    "write_odometry",
]

logger = logging.getLogger(__name__)

GEOREFERENCE = Path("maps/georeference.json")
ODOMETRY_DIR = Path("odometry")
POSE_SOURCES_FILE = "pose_sources.json"


def cama_instances(annotations: AnnotationSet) -> list[dict[str, Any]]:
    """The `map_labels.json` instances of a set, validated against the model."""
    georef = annotations.georeference
    instances = []
    for index, element in enumerate(annotations.elements):
        uv = pixel_from_site_points(element.xy(), georef)
        instances.append(
            {
                "attrs": {"type": CAMA_TYPE_FROM_CLASS[element.cls]},
                "data": uv.tolist(),
                "id": element.id,
                "luid": element.id,
                "point_attrs": [[] for _ in range(len(uv))],
                "shape_type": "polyline",
                "struct_type": "parsing",
                "track_id": index,
            }
        )
    validated = validate_file(CamaMapLabels, instances, MAP_LABELS)
    return [item.model_dump(mode="json") for item in validated.root]


def export_cama(
    annotations: AnnotationSet,
    out: Path,
    *,
    name: str | None = None,
    elevation: np.ndarray | None = None,
    dataset: Dataset | None = None,
    poses: PoseLookup | None = None,
    scenes: Sequence[str] | None = None,
) -> Path:
    """Write the CAMA layout under `out/<name or site_id>/`; returns that folder. Odometry is written when a
    data set is given, and then `poses` (refined, or `annotations.poses.coarse_pose` when asked) is needed."""
    georef = annotations.georeference
    if elevation is not None:
        elevation = np.asarray(elevation, dtype=np.float32)
        if elevation.shape != georef.shape:
            raise ValueError(
                f"elevation: shape {elevation.shape} != georeference (height, width) {georef.shape}"
            )
    folder = Path(out) / (name or annotations.site_id)
    labels = cama_instances(annotations)
    geo_file = CamaGeoreferenceFile(site_id=annotations.site_id, georeference=georef)
    if elevation is not None:
        atomic_write_npy(folder / ELEVATION, elevation)
    atomic_write_bytes(folder / GEOREFERENCE, geo_file.model_dump_json(indent=2).encode("utf-8"))
    if dataset is not None:
        if poses is None:
            raise ValueError("odometry: no pose lookup given (refined poses, or coarse_pose when asked for)")
        write_odometry(dataset, folder / ODOMETRY_DIR, poses=poses, scenes=scenes)
    atomic_write_bytes(folder / MAP_LABELS, json.dumps(labels, indent=1).encode("utf-8"))
    logger.info("exported %d elements to %s", len(labels), folder)
    return folder


def write_odometry(
    dataset: Dataset, folder: Path, *, poses: PoseLookup, scenes: Sequence[str] | None = None
) -> list[Path]:
    """One TUM file per camera channel (`t x y z qx qy qz qw`, camera to global) over the chosen scenes, ego
    poses from `poses`; `pose_sources.json` beside them says which source each row came from."""
    wanted = [s for s in dataset.scenes if scenes is None or s.name in scenes]
    if scenes is not None and len(wanted) != len(set(scenes)):
        known = sorted(s.name for s in dataset.scenes)
        raise ValueError(f"scenes: {sorted(set(scenes) - {s.name for s in wanted})} not in data set {known}")
    rows: dict[str, list[tuple[int, str, PoseSource]]] = {}
    for scene in wanted:
        for image in scene.all_images():
            sourced = poses(image)
            pose = sourced.global_from_ego @ image.calibration.ego_from_cam
            (x, y, z), (qw, qx, qy, qz) = pose.translation, pose.rotation
            line = (
                f"{image.timestamp_us / 1e6:.6f} {x:.6f} {y:.6f} {z:.6f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}"
            )
            rows.setdefault(image.channel, []).append((image.timestamp_us, line, sourced.source))
    paths = []
    sources: dict[str, Any] = {}
    for channel, lines in sorted(rows.items()):
        path = folder / f"camera_{channel}.txt"
        ordered = sorted(lines, key=lambda row: row[:2])
        text = "# t x y z qx qy qz qw (camera to global, t in seconds)\n"
        text += "".join(line + "\n" for _, line, _ in ordered)
        atomic_write_bytes(path, text.encode("utf-8"))
        paths.append(path)
        row_sources = [source for _, _, source in ordered]
        sources[path.name] = {
            "counts": {s: row_sources.count(s) for s in POSE_SOURCES if s in row_sources},
            "rows": row_sources,
        }
    atomic_write_bytes(folder / POSE_SOURCES_FILE, json.dumps(sources, indent=1).encode("utf-8"))
    return paths
