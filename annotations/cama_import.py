"""Read CAMA labels back into an annotation set: our release layout (sidecar version 2), our older folder-per-site
layout (version 1), or a plain CAMA release without our sidecar.

`import_cama(path)` takes:
  - a scene folder (holding `maps/map_labels.json`): `<out>/all_clips/<scene>`, an older export's `<out>/<site>`,
    or a plain release scene;
  - a site map: `<out>/site2clip/<site>_map_labels.json`, or the folder `<out>/site2clip` or the release root
    `<out>` when it holds one site map (several: name the file).
With a version 2 sidecar the pixels go back to global through its world origin and the set's georeference is
restored; z is lifted from the release raster with its filled cells treated as unobserved (a vertex without an
observed cell within the lift's search radius leaves the element unlifted). Version 1: the pixels are those of
the stored georeference, z from `maps/elevation.npy`. A plain release has no global frame: the labels land in
the release's own world frame (the one its odometry uses): x = v r - rows r / 2, y = u r - cols r / 2, through a
georeference centred on 0 (`annotations.cama_frame.release_georeference`), site id = the folder's (or site's)
name; its elevation raster is required (`maps/elevation.npy`, else the single `maps/*.npy`).
Crosswalk lines whose first point != last point are closed by appending the first point.
"""

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from pydantic import ValidationError

from annotations.cama_frame import ReleaseFrame, our_pixels_from_uv, our_view, release_georeference
from annotations.cama_labels import (
    MAP_LABELS,
    CamaInstance,
    CamaMapLabels,
    class_from_cama_type,
    format_validation_error,
    read_json_file,
    validate_file,
)
from annotations.cama_release import (
    ALL_CLIPS,
    SCENE_ELEVATION,
    SCENE_SIDECAR,
    SITE2CLIP,
    SITE_ELEVATION_SUFFIX,
    SITE_LABELS_SUFFIX,
    SITE_SIDECAR_SUFFIX,
)
from annotations.cama_sidecar import CamaGeoreferenceFile, CamaReleaseGeoreference, read_sidecar
from annotations.geometry import simplify
from annotations.lift import lift_element
from annotations.schema import POLYGON_CLASSES, AnnotationSet, ElementClass, Georeference, MapElement
from annotations.transforms import site_from_pixel_points

logger = logging.getLogger(__name__)

ELEVATION = Path("maps/elevation.npy")
"""The older layout's elevation raster (our convention, NaN unobserved)."""
IMPORT_AUTHOR = "cama-import"
DENSIFIED_TOLERANCE_M = 1e-6
"""Points within this of the line through their neighbours were added by the export's densifying (they lie on the
segment exactly, up to float rounding): import drops them, giving back the exported vertices."""
DEFAULT_RELEASE_RESOLUTION_M = 0.1
"""Metres per BEV pixel in the public CAMA release."""


@dataclass(frozen=True)
class _Source:
    """Where one map's files are."""

    labels: Path
    sidecar: Path
    elevation: Path | None
    """The release raster; None for a scene folder (version 1: maps/elevation.npy; plain: looked up)."""
    name: str
    """Default site id of a plain release (the scene folder's or the site's name)."""


@dataclass(frozen=True, eq=False)
class _Placement:
    """How label pixels become site metres and where z comes from."""

    site_from_uv: Callable[[np.ndarray], np.ndarray]
    georeference: Georeference
    """The imported set's georeference."""
    site_id: str
    raster: np.ndarray | None = None
    raster_georeference: Georeference | None = None
    unobserved: np.ndarray | None = None
    densified: bool = False
    """The export densified the labels (our sidecar's label_spacing_m): drop the points it added."""


def import_cama(
    path: Path,
    *,
    site_id: str | None = None,
    stop_line_as_divider: bool = False,
    resolution_m: float = DEFAULT_RELEASE_RESOLUTION_M,
) -> AnnotationSet:
    """Read CAMA labels (see the module docstring for what `path` may be) into an annotation set of reviewable
    human labels; `resolution_m` is a plain release's pixel size; `site_id` replaces the stored one."""
    source = _locate(Path(path))
    if source.sidecar.is_file():
        sidecar = read_sidecar(source.sidecar)
        if isinstance(sidecar, CamaReleaseGeoreference):
            placement = _release_placement(source, sidecar)
        else:
            placement = _v1_placement(source, sidecar)
    else:
        placement = _plain_placement(source, resolution_m)
    labels = validate_file(CamaMapLabels, read_json_file(source.labels), source.labels)
    elements: list[MapElement] = []
    skipped = 0
    for index, instance in enumerate(labels.root):
        cls = class_from_cama_type(instance.attrs.type, stop_line_as_divider=stop_line_as_divider)
        if cls is None:
            skipped += 1
            continue
        elements.append(_element(instance, cls, placement, f"{source.labels}: [{index}]"))
    if skipped:
        logger.warning("%s: skipped %d Stop_Line instances (no class of ours)", source.labels, skipped)
    try:
        return AnnotationSet(
            site_id=site_id or placement.site_id, georeference=placement.georeference, elements=elements
        )
    except ValidationError as error:
        raise ValueError(format_validation_error(source.labels, error)) from error


def _locate(path: Path) -> _Source:
    """The map files `path` names; ValueError saying what to pass when it is ambiguous."""
    if path.is_file():
        if not path.name.endswith(SITE_LABELS_SUFFIX):
            raise ValueError(f"{path}: expected a scene folder or a site map <site>{SITE_LABELS_SUFFIX}")
        return _site_source(path)
    site2clip = path if path.name == SITE2CLIP else path / SITE2CLIP
    if not (path / MAP_LABELS).is_file() and site2clip.is_dir():
        maps = sorted(site2clip.glob(f"*{SITE_LABELS_SUFFIX}"))
        if len(maps) == 1:
            return _site_source(maps[0])
        if len(maps) > 1:
            sites = [p.name.removesuffix(SITE_LABELS_SUFFIX) for p in maps]
            raise ValueError(f"{site2clip}: site maps of {sites}; pass one <site>{SITE_LABELS_SUFFIX} file")
    if not (path / MAP_LABELS).is_file() and (path / ALL_CLIPS).is_dir():
        scenes = sorted(p.name for p in (path / ALL_CLIPS).iterdir() if p.is_dir())
        raise ValueError(
            f"{path}: a release without a site map: import one scene folder {path / ALL_CLIPS}/<scene> "
            f"(scenes: {scenes})"
        )
    return _Source(path / MAP_LABELS, path / SCENE_SIDECAR, None, path.resolve().name)


def _site_source(labels: Path) -> _Source:
    """The files of the site map `<site>_map_labels.json`."""
    site = labels.name.removesuffix(SITE_LABELS_SUFFIX)
    folder = labels.parent
    return _Source(
        labels, folder / f"{site}{SITE_SIDECAR_SUFFIX}", folder / f"{site}{SITE_ELEVATION_SUFFIX}", site
    )


def _release_placement(source: _Source, sidecar: CamaReleaseGeoreference) -> _Placement:
    """Version 2: release pixels -> global through the world origin -> the set's site frame."""
    frame = ReleaseFrame(sidecar.world_origin_global, sidecar.map_side_m, sidecar.resolution_m)
    if frame.cells != sidecar.cells:
        raise ValueError(
            f"{source.sidecar}: cells {sidecar.cells} != map_side_m / resolution_m {frame.cells}"
        )
    raster_georef = frame.our_georeference(sidecar.georeference.site_origin_xy)
    shape = (frame.cells, frame.cells)
    path = source.elevation or source.labels.parent.parent / SCENE_ELEVATION
    raster, unobserved = None, None
    if path.is_file():
        release = _load_npy(path)
        if release.shape != shape:
            raise ValueError(
                f"{path}: shape {release.shape} != ({frame.cells}, {frame.cells}) of {source.sidecar}"
            )
        raster = our_view(release)
        unobserved = _filled_mask(source.sidecar.parent / sidecar.elevation_filled, shape)
    return _Placement(
        lambda uv: site_from_pixel_points(our_pixels_from_uv(uv, shape), raster_georef),
        sidecar.georeference,
        sidecar.site_id,
        raster,
        raster_georef,
        unobserved,
        densified=sidecar.label_spacing_m is not None,
    )


def _v1_placement(source: _Source, sidecar: CamaGeoreferenceFile) -> _Placement:
    """Version 1 (older layout): pixels of the stored georeference, z from maps/elevation.npy when present."""
    georef = sidecar.georeference
    folder = source.labels.parent.parent
    raster = None
    if (folder / ELEVATION).is_file():
        raster = _load_npy(folder / ELEVATION)
        if raster.shape != georef.shape:
            raise ValueError(
                f"{folder / ELEVATION}: shape {raster.shape} != georeference (height, width) {georef.shape}"
            )
    return _Placement(lambda uv: site_from_pixel_points(uv, georef), georef, sidecar.site_id, raster, georef)


def _plain_placement(source: _Source, resolution_m: float) -> _Placement:
    """A plain release: the release's own world frame, fixed by its (required) elevation raster."""
    path = source.elevation or release_elevation_path(source.labels.parent.parent)
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: the site map's elevation raster is missing (needed to place the labels)"
        )
    release = _load_npy(path)
    if release.ndim != 2 or 0 in release.shape:
        raise ValueError(f"{path}: expected a non-empty (H, W) raster, got shape {release.shape}")
    georef = release_georeference(release.shape, resolution_m)
    shape = release.shape
    return _Placement(
        lambda uv: site_from_pixel_points(our_pixels_from_uv(uv, shape), georef),
        georef,
        source.name,
        our_view(release),
        georef,
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
            f"{folder}: cannot place the CAMA labels: need {SCENE_SIDECAR} (our export) or, for a plain CAMA "
            f"release, the elevation raster as a .npy in {maps} beside map_labels.json"
        )
    names = [p.name for p in candidates]
    raise ValueError(
        f"{maps}: several .npy files {names} and no elevation.npy; keep one or name it elevation.npy"
    )


def _load_npy(path: Path) -> np.ndarray:
    """A numeric numpy array file, memory-mapped (a site map is 144 MB; the lift reads a few cells of it);
    ValueError naming it when it is not one."""
    try:
        array = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a numpy array file: {error}") from error
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"{path}: expected a numeric raster, got dtype {array.dtype}")
    return array


def _filled_mask(path: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """Our view of the filled-cells PNG (True = filled), or None when it is absent; ValueError when unreadable."""
    if not path.is_file():
        return None
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None or mask.shape != shape:
        got = None if mask is None else mask.shape
        raise ValueError(f"{path}: expected a {shape} mask image, got {got}")
    return our_view(mask > 0)


def _element(instance: CamaInstance, cls: ElementClass, placement: _Placement, where: str) -> MapElement:
    """One imported element (a reviewable human label), lifted when the placement has a raster."""
    uv = np.asarray(instance.data, dtype=float)
    if cls in POLYGON_CLASSES and not np.array_equal(uv[0], uv[-1]):
        uv = np.vstack([uv, uv[:1]])  # release crosswalk lines may be open: close the ring
    xy = placement.site_from_uv(uv)
    if placement.densified:
        xy = simplify(xy, DENSIFIED_TOLERANCE_M)
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
    if placement.raster is None or placement.raster_georeference is None:
        return element
    return lift_element(
        element,
        placement.raster,
        placement.raster_georeference,
        unobserved=placement.unobserved,
        strict=False,
    )
