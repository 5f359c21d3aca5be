"""The CAMA release layout (nuScenes-CAMAv2 labels): export an annotation set to it and import it back.

Layout written under `<out>/<name>/` (name = scene or site):
  maps/map_labels.json   list of instances {"attrs": {"type"}, "data": [[u, v], ...], "id", "luid",
                         "point_attrs", "shape_type": "polyline", "struct_type": "parsing", "track_id"};
                         `data` in BEV pixels of the map raster (u = column, v = row, floats; our georeference
                         convention: column grows with +x, row with -y, pixel (0, 0)'s centre at `origin_xy`).
  maps/elevation.npy     the (H, W) float32 elevation raster (global z, NaN = unobserved), when given.
  maps/georeference.json our extension: site id + Georeference, so import restores site coordinates.
  odometry/camera_<CHANNEL>.txt  TUM rows `t x y z qx qy qz qw` (camera to global, t seconds), with a data set.
  odometry/pose_sources.json     our extension: per odometry file, the count of rows per pose source and each
                                 row's source (`annotations.poses`), in row order.

A plain CAMA release folder (no georeference.json) imports too: its raster (`maps/elevation.npy` or the single
`maps/*.npy`) fixes a scene-local frame centred on the map, see `release_georeference` for the axis mapping.

Type table (one place): divider <-> lane_marking, boundary <-> Road_teeth, ped_crossing <-> Crosswalk_Line.
`Stop_Line` has no class of ours: import skips it (logging the count) unless `stop_line_as_divider`.
"""

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, RootModel, ValidationError

from annotations.lift import lift_element
from annotations.poses import POSE_SOURCES, PoseLookup, PoseSource
from annotations.schema import POLYGON_CLASSES, AnnotationSet, ElementClass, Georeference, MapElement
from annotations.transforms import pixel_from_site_points, site_from_pixel_points
from cama_pipeline.data import Dataset
from cama_pipeline.io import atomic_write_bytes, atomic_write_npy

logger = logging.getLogger(__name__)

CamaType = Literal["lane_marking", "Road_teeth", "Crosswalk_Line", "Stop_Line"]
CAMA_TYPE_FROM_CLASS: dict[ElementClass, CamaType] = {
    "divider": "lane_marking",
    "boundary": "Road_teeth",
    "ped_crossing": "Crosswalk_Line",
}
CLASS_FROM_CAMA_TYPE: dict[str, ElementClass] = {cama: ours for ours, cama in CAMA_TYPE_FROM_CLASS.items()}
MAP_LABELS = Path("maps/map_labels.json")
ELEVATION = Path("maps/elevation.npy")
GEOREFERENCE = Path("maps/georeference.json")
ODOMETRY_DIR = Path("odometry")
POSE_SOURCES_FILE = "pose_sources.json"
IMPORT_AUTHOR = "cama-import"
DEFAULT_RELEASE_RESOLUTION_M = 0.1
"""Metres per BEV pixel in the public CAMA release."""
_M = TypeVar("_M", bound=BaseModel)


class CamaAttrs(BaseModel):
    """Instance attributes; the reference code reads only `type`."""

    model_config = ConfigDict(extra="allow")

    type: CamaType = Field(description="CAMA element type.")


class CamaInstance(BaseModel):
    """One instance of `map_labels.json`: a polyline in BEV-raster pixels [u = column, v = row]."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False)

    attrs: CamaAttrs
    data: list[tuple[float, float]] = Field(min_length=2, description="[u, v] BEV pixels (column, row).")
    id: str | int = Field(description="Instance id (ours: the element id).")
    luid: str | int | None = Field(default=None, description="Label unique id.")
    point_attrs: list[list[Any]] = Field(default_factory=list, description="One list per point.")
    shape_type: Literal["polyline"] = "polyline"
    struct_type: Literal["parsing"] = "parsing"
    track_id: str | int | None = None


class CamaMapLabels(RootModel[list[CamaInstance]]):
    """The whole `map_labels.json`: a list of instances."""


class CamaGeoreferenceFile(BaseModel):
    """`maps/georeference.json` (our extension): which site, and where its raster pixels sit."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["cama-studio-georeference"] = "cama-studio-georeference"
    format_version: Literal[1] = 1
    site_id: str = Field(min_length=1)
    georeference: Georeference


def format_validation_error(path: Path | str, error: ValidationError) -> str:
    """`file: [3].attrs.type: unknown type 'Foo' ...`, one line per problem, for a ValueError."""
    lines = []
    for item in error.errors():
        loc = "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in item["loc"])
        loc = loc.lstrip(".") or "(root)"
        message = item["msg"]
        if item["type"] == "literal_error" and item["loc"]:
            expected = item.get("ctx", {}).get("expected", "")
            message = f"unknown {item['loc'][-1]} {item['input']!r}; expected {expected}"
        lines.append(f"{Path(path).name}: {loc}: {message}")
    return f"{path}: invalid file\n" + "\n".join(lines) if len(lines) > 1 else lines[0]


def read_json_file(path: Path) -> Any:
    """Parse a JSON file; FileNotFoundError / ValueError naming it."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from error


def validate_file(model: type[_M], obj: Any, path: Path) -> _M:
    """Validate a parsed file against its model; ValueError naming the file and field path."""
    try:
        return model.model_validate(obj)
    except ValidationError as error:
        raise ValueError(format_validation_error(path, error)) from error


def class_from_cama_type(cama_type: str, *, stop_line_as_divider: bool = False) -> ElementClass | None:
    """Our class for a CAMA type; None for `Stop_Line` unless mapped to divider; ValueError when unknown."""
    if cama_type in CLASS_FROM_CAMA_TYPE:
        return CLASS_FROM_CAMA_TYPE[cama_type]
    if cama_type == "Stop_Line":
        return "divider" if stop_line_as_divider else None
    raise ValueError(f"type: unknown CAMA type {cama_type!r}")


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


def import_cama(
    folder: Path,
    *,
    site_id: str | None = None,
    stop_line_as_divider: bool = False,
    resolution_m: float = DEFAULT_RELEASE_RESOLUTION_M,
) -> AnnotationSet:
    """Read a CAMA folder into an annotation set: our export (with `maps/georeference.json`) or a plain release.

    With `maps/georeference.json` (our extension) pixels map through the stored georeference and z is lifted from
    `maps/elevation.npy` when present. Without it the folder is a plain release (`release_georeference`): the
    elevation raster beside `map_labels.json` is required and fixes the frame; `resolution_m` is its pixel size
    and the site id defaults to the folder name. Crosswalk lines whose first point != last point are closed by
    appending the first point (a ring that is then not simple is rejected, naming the instance).
    """
    folder = Path(folder)
    if (folder / GEOREFERENCE).is_file():
        geo_file = validate_file(
            CamaGeoreferenceFile, read_json_file(folder / GEOREFERENCE), folder / GEOREFERENCE
        )
        georef, stored_site_id = geo_file.georeference, geo_file.site_id
        elevation = _read_elevation(folder / ELEVATION, georef)
    else:
        elevation_path = release_elevation_path(folder)
        elevation = _load_npy(elevation_path)
        if elevation.ndim != 2 or 0 in elevation.shape:
            raise ValueError(
                f"{elevation_path}: expected a non-empty (H, W) raster, got shape {elevation.shape}"
            )
        georef = release_georeference(elevation.shape, resolution_m=resolution_m)
        stored_site_id = folder.resolve().name
    labels = validate_file(CamaMapLabels, read_json_file(folder / MAP_LABELS), folder / MAP_LABELS)
    elements: list[MapElement] = []
    skipped = 0
    for index, instance in enumerate(labels.root):
        cls = class_from_cama_type(instance.attrs.type, stop_line_as_divider=stop_line_as_divider)
        if cls is None:
            skipped += 1
            continue
        elements.append(_element(instance, cls, georef, elevation, f"{folder / MAP_LABELS}: [{index}]"))
    if skipped:
        logger.warning("%s: skipped %d Stop_Line instances (no class of ours)", folder / MAP_LABELS, skipped)
    try:
        return AnnotationSet(site_id=site_id or stored_site_id, georeference=georef, elements=elements)
    except ValidationError as error:
        raise ValueError(format_validation_error(folder / MAP_LABELS, error)) from error


def release_georeference(
    shape: tuple[int, ...], *, resolution_m: float = DEFAULT_RELEASE_RESOLUTION_M
) -> Georeference:
    """The scene-local georeference of a plain CAMA release raster of `shape` = (rows, cols).

    The release convention (notes): x_cama = v * r - H/2, y_cama = u * r - W/2 in metres, with [u, v] = [column,
    row] pixels, r = `resolution_m`, and H = rows * r, W = cols * r the raster's height and width in metres (so the
    map is centred at 0; pixel centres sit at integer u, v). x_cama grows with the row, which our convention
    (column -> +x, row -> -y) cannot express, so imported points use our axes, a proper 90-degree rotation of
    the release frame: x = y_cama = u * r - W/2, y = -x_cama = H/2 - v * r (and back: x_cama = -y, y_cama = x).
    That is exactly this georeference: site origin (0, 0), pixel (0, 0)'s centre at (-W/2, H/2).
    """
    if not (np.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m: expected a finite value > 0, got {resolution_m}")
    rows, cols = int(shape[0]), int(shape[1])
    return Georeference(
        site_origin_xy=(0.0, 0.0),
        origin_xy=(-cols * resolution_m / 2, rows * resolution_m / 2),
        resolution=resolution_m,
        width=cols,
        height=rows,
    )


def release_elevation_path(folder: Path) -> Path:
    """`maps/elevation.npy`, else the single `maps/*.npy`; FileNotFoundError / ValueError naming the folder."""
    maps = Path(folder) / MAP_LABELS.parent
    if (Path(folder) / ELEVATION).is_file():
        return Path(folder) / ELEVATION
    candidates = sorted(p for p in maps.glob("*.npy") if p.is_file()) if maps.is_dir() else []
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        raise FileNotFoundError(
            f"{folder}: cannot place the CAMA labels: need {GEOREFERENCE} (our export) or, for a plain CAMA "
            f"release, the elevation raster as a .npy in {maps} beside map_labels.json"
        )
    names = [p.name for p in candidates]
    raise ValueError(
        f"{maps}: several .npy files {names} and no elevation.npy; keep one or name it elevation.npy"
    )


def _load_npy(path: Path) -> np.ndarray:
    """A numpy array file; ValueError naming it when it is not one."""
    try:
        return np.asarray(np.load(path, allow_pickle=False), dtype=float)
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a numpy array file: {error}") from error


def _read_elevation(path: Path, georef: Georeference) -> np.ndarray | None:
    """The elevation raster if the file exists; ValueError naming it when its shape is wrong."""
    if not path.is_file():
        return None
    elevation = _load_npy(path)
    if elevation.shape != georef.shape:
        raise ValueError(f"{path}: shape {elevation.shape} != georeference (height, width) {georef.shape}")
    return elevation


def _element(
    instance: CamaInstance, cls: ElementClass, georef: Georeference, elevation: np.ndarray | None, where: str
) -> MapElement:
    """One imported element (a reviewable human label), lifted when a raster is given."""
    uv = np.asarray(instance.data, dtype=float)
    if cls in POLYGON_CLASSES and not np.array_equal(uv[0], uv[-1]):
        uv = np.vstack([uv, uv[:1]])  # release crosswalk lines may be open: close the ring
    xy = site_from_pixel_points(uv, georef)
    try:
        element = MapElement(
            id=str(instance.id),
            cls=cls,
            points_2d=[(x, y) for x, y in xy.tolist()],
            source="human",
            review_state="proposed",
            author=IMPORT_AUTHOR,
        )
    except ValidationError as error:
        raise ValueError(f"{where}: {format_validation_error('element', error)}") from error
    if elevation is None:
        return element
    return lift_element(element, elevation, georef, strict=False)
