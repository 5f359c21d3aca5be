"""The SfM outputs of a site in the workspace (`Workspace.sfm_model`, `sfm_clips`, `sfm_poses`, `sfm_points`,
`sfm_report`): the only module that reads or writes them.

<workspace>/sfm/<site_id>/model/          the merged site model, COLMAP binary (`Reconstruction.write`):
                                          cameras.bin, images.bin, points3D.bin (+ rigs.bin, frames.bin);
                                          global metres, image names relative to the data set root
<workspace>/sfm/<site_id>/clips/<scene>/  each clip's own model (parallel reconstruction), same format
<workspace>/sfm/<site_id>/poses.json      schema "cama.sfm/1": refined ego poses
    {"schema", "site_id", "fingerprint",
     "images": {sample_data token: {"name": image path relative to the data set root, "scene", "channel",
                                    "translation": [x, y, z] global m, "rotation": [w, x, y, z],
                                    "flagged": bool}}}
    translation/rotation: the refined world_from_ego (global_from_ego) at the image's time. Flagged images
    were dropped by BA (moved implausibly, or high reprojection error): their pose is the one they had going
    in, not to be trusted. Images of clips whose SfM failed are absent.
<workspace>/sfm/<site_id>/points.npz      the sparse points of the merged model, one row per point:
    xyz (N, 3) float64 global m; label (N,) uint8 BEV raster class (0 bg, 1 road, 2 curb, 3 lane marking,
    4 crosswalk; majority of the semantic masks at the point's observations); error_px (N,) float64 mean
    reprojection error; track_length (N,) int32 observations
<workspace>/sfm/<site_id>/report.json     schema "cama.sfm-report/1", written last (marks completion)
    {"schema", "site_id", "fingerprint", "config": {...}, "merge_config": {...}, "executor", "workers",
     "clips": {scene: {"status": "ok" | "failed", "error": str | null, "images", "registered_images",
                       "points", "reprojection_error_px", "iterations" (BA passes), "stop" (why the BA
                       loop ended), "flagged", "seconds"}},
     "merge": {"groups": [[scene]] (clips joined by shared points),
               "alignments": {scene: {"reference": scene | null, "method": "points" | "poses",
                                      "correspondences", "scale", "rotation_deg", "shift_m"}},
               "height_ties_before_alignment": {scene: {"offset_m", "pairs", "tied"}} (free-height clips,
                                      each moved on its own before the alignment),
               "height_ties": {scene: {"offset_m", "pairs", "tied"}} (free-height groups no point joins,
                                      moved after it)},
     "merged": {"images", "registered_images", "points", "reprojection_error_px", "iterations", "stop",
                "flagged", "seconds"},
     "seconds": {"clips", "merge", "total"}}
    A clip is a moving scene of the site with the stationary scenes merged into it.
"""

import io
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from cama_pipeline.data import Pose
from cama_pipeline.io import WorkspaceError, atomic_write_bytes, atomic_write_json, field, read_json

POSES_SCHEMA = "cama.sfm/1"
REPORT_SCHEMA = "cama.sfm-report/1"
POINT_FIELDS = ("xyz", "label", "error_px", "track_length")


@dataclass(frozen=True, eq=False)
class SparsePoints:
    """The sparse points of a site model (see the module docstring for units)."""

    xyz: np.ndarray
    label: np.ndarray
    error_px: np.ndarray
    track_length: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.xyz)
        if np.shape(self.xyz) != (n, 3) or any(len(getattr(self, f)) != n for f in POINT_FIELDS[1:]):
            raise ValueError("SparsePoints: xyz must be (N, 3) and label/error_px/track_length (N,)")


@dataclass(frozen=True)
class PoseEntry:
    """One image's refined pose as stored in poses.json."""

    name: str
    scene: str
    channel: str
    world_from_ego: np.ndarray
    flagged: bool


def write_model(folder: Path, reconstruction: pycolmap.Reconstruction) -> None:
    """Write a COLMAP binary model into `folder`, replacing any old one only once the new one is complete."""
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}."))
    try:
        reconstruction.write(str(staging))
        if folder.exists():
            shutil.rmtree(folder)
        staging.rename(folder)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def read_model(folder: Path) -> pycolmap.Reconstruction:
    """A COLMAP model folder; FileNotFoundError naming it when absent."""
    folder = Path(folder)
    if not (folder / "images.bin").is_file():
        raise FileNotFoundError(f"{folder}: no COLMAP model (images.bin) here; run `cama sfm` first")
    return pycolmap.Reconstruction(str(folder))


def _pose_json(entry: PoseEntry) -> dict[str, Any]:
    rotation = matrix_to_quaternion(entry.world_from_ego[:3, :3])
    return {
        "name": entry.name,
        "scene": entry.scene,
        "channel": entry.channel,
        "translation": [float(v) for v in entry.world_from_ego[:3, 3]],
        "rotation": [float(v) for v in rotation],
        "flagged": bool(entry.flagged),
    }


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """[w, x, y, z] of a rotation matrix (positive w)."""
    xyzw = pycolmap.Rotation3d(np.asarray(rotation, dtype=np.float64)).quat
    quaternion = np.array([xyzw[3], xyzw[0], xyzw[1], xyzw[2]])
    return quaternion if quaternion[0] >= 0 else -quaternion


def write_poses(path: Path, *, site_id: str, digest: str, poses: dict[str, PoseEntry]) -> None:
    """Write poses.json atomically (schema in the module docstring)."""
    images = {token: _pose_json(entry) for token, entry in sorted(poses.items())}
    atomic_write_json(
        path, {"schema": POSES_SCHEMA, "site_id": site_id, "fingerprint": digest, "images": images}
    )


def _vector(raw: dict[str, Any], name: str, size: int, path: Path, where: str) -> np.ndarray:
    """raw[name] as `size` finite floats, else a WorkspaceError naming the file and field."""
    try:
        vector = np.asarray(field(raw, name, list, path, where), dtype=np.float64)
    except (TypeError, ValueError):
        vector = np.zeros(0)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise WorkspaceError(f"{path}: field {where}{name!r} must be {size} finite numbers")
    return vector


def _pose_entry(raw: Any, path: Path, token: str) -> PoseEntry:
    where = f"images[{token!r}]."
    if not isinstance(raw, dict):
        raise WorkspaceError(f"{path}: images[{token!r}] must be an object")
    translation = _vector(raw, "translation", 3, path, where)
    rotation = _vector(raw, "rotation", 4, path, where)
    if np.linalg.norm(rotation) < 1e-9:
        raise WorkspaceError(f"{path}: field {where}'rotation' must be a non-zero quaternion")
    return PoseEntry(
        name=field(raw, "name", str, path, where),
        scene=field(raw, "scene", str, path, where),
        channel=field(raw, "channel", str, path, where),
        world_from_ego=Pose(translation, rotation).matrix(),
        flagged=field(raw, "flagged", bool, path, where),
    )


def read_pose_entries(path: Path) -> dict[str, PoseEntry]:
    """Every image of poses.json, checked; FileNotFoundError / WorkspaceError naming the file and field."""
    data = read_json(path, POSES_SCHEMA, "cama sfm")
    images = field(data, "images", dict, path)
    return {token: _pose_entry(raw, path, token) for token, raw in images.items()}


def read_refined_poses(path: Path, *, include_flagged: bool = False) -> dict[str, np.ndarray]:
    """sample_data token -> (4, 4) refined world_from_ego of poses.json; flagged (untrusted) images left out
    unless asked."""
    entries = read_pose_entries(path)
    return {
        token: entry.world_from_ego
        for token, entry in entries.items()
        if include_flagged or not entry.flagged
    }


def write_points(path: Path, points: SparsePoints) -> None:
    """Write points.npz atomically (uncompressed: fast to read, a few MB per site)."""
    buffer = io.BytesIO()
    np.savez(
        buffer,
        xyz=np.asarray(points.xyz, dtype=np.float64),
        label=np.asarray(points.label, dtype=np.uint8),
        error_px=np.asarray(points.error_px, dtype=np.float64),
        track_length=np.asarray(points.track_length, dtype=np.int32),
    )
    atomic_write_bytes(path, buffer.getvalue())


def read_points(path: Path) -> SparsePoints:
    """A site's points.npz; FileNotFoundError / WorkspaceError naming the file and the bad array."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found; run `cama sfm` first")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.asarray(data[name]) for name in POINT_FIELDS}
    except KeyError as err:
        raise WorkspaceError(f"{path}: array {err} missing") from None
    except (OSError, ValueError) as err:
        raise WorkspaceError(f"{path}: not a readable .npz ({err})") from None
    try:
        return SparsePoints(**arrays)
    except ValueError as err:
        raise WorkspaceError(f"{path}: {err}") from None


def write_report(path: Path, report: dict[str, Any]) -> dict[str, Any]:
    """Write report.json atomically (last: it carries the fingerprint that marks the site done); returns what
    was written."""
    stored = {"schema": REPORT_SCHEMA, **report}
    atomic_write_json(path, stored, indent=1)
    return stored


def read_report(path: Path) -> dict[str, Any]:
    """A site's report.json, schema-checked."""
    data = read_json(path, REPORT_SCHEMA, "cama sfm")
    field(data, "clips", dict, path)
    return data
