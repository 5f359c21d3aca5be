"""What the 3D view shows, read from a site's files: the road surface, the keyframe cameras, the sparse SfM
points and the BEV elevation that lifts 2D vectors. Everything is returned in the view's local frame.

A site folder written by `cama synth` and its workspace are the inputs. The reconstructed rasters
(`workspace/surface/<site>/bev/`, `cama surface`) are preferred; the generator's ground truth is used when the
surface stage has not run, and the view says so.
"""

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

from annotations.lift import lift_points
from annotations.schema import Georeference
from app.viewer.geometry import LocalFrame, frustum_segments
from app.viewer.style import semantic_rgb
from cama_pipeline.bev import is_raster_folder, read_bev, read_layer
from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import load_dataset
from cama_pipeline.semantics import Semantic
from cama_pipeline.site.io import manifest_scenes, read_site_ids, read_site_manifest
from cama_pipeline.surface.outputs import read_kerb_step
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


class ViewInputError(ValueError):
    """A file the 3D view needs is missing or unreadable; the message names it."""


@dataclass(frozen=True, eq=False)
class Surface:
    """The BEV elevation used to lift vectors, with its raster georeference (site origin 0: global xy)."""

    elevation: np.ndarray
    unobserved: np.ndarray
    georeference: Georeference
    folder: Path
    reconstructed: bool
    """False when these are the generator's ground-truth rasters (the surface stage has not run)."""
    kerb_step: np.ndarray | None = None
    """Metres the ground stands above `elevation` (the surface stage's kerb steps), for the road mesh only:
    vectors lie on the road and are lifted through `elevation` alone. None: no steps known."""


@dataclass(frozen=True, eq=False)
class SparsePointsView:
    """Sparse SfM points in the view frame with colours by semantic label."""

    xyz: np.ndarray
    rgb: np.ndarray


def first_site(workspace: Path) -> str:
    """The workspace's first site (`sites/index.json`), shown when none is named; errors name the index."""
    index = Workspace(workspace).sites_index()
    site_ids = read_site_ids(index)
    if not site_ids:
        raise ViewInputError(f"{index}: no sites (every scene was dropped)")
    return site_ids[0]


def surface_folder(site_dir: Path, workspace: Path, site_id: str) -> tuple[Path, bool]:
    """The raster folder to show: the reconstructed one when present, else the ground truth; (folder, reconstructed)."""
    reconstructed = Workspace(workspace).surface_bev(site_id)
    if is_raster_folder(reconstructed):
        return reconstructed, True
    ground_truth = Path(site_dir) / "ground_truth" / "bev"
    if is_raster_folder(ground_truth):
        logger.warning(
            "no reconstructed surface in %s: showing the ground-truth rasters", reconstructed.parent
        )
        return ground_truth, False
    raise ViewInputError(
        f"{reconstructed}: no BEV rasters (run `cama surface`), and no ground truth in {site_dir}"
    )


def load_surface(folder: Path, *, reconstructed: bool) -> Surface:
    """Read the elevation and semantic layers of a raster folder; ViewInputError naming the file."""
    try:
        bev = read_bev(folder, ("semantic", "elevation"))
    except (OSError, ValueError) as err:
        raise ViewInputError(str(err)) from None
    georeference = Georeference.of(bev.georeference, site_origin_xy=(0.0, 0.0))
    elevation = bev.require("elevation").astype(np.float64)
    unobserved = (bev.require("semantic") == int(Semantic.UNOBSERVED)) | ~np.isfinite(elevation)
    kerb_step = _kerb_step(folder, elevation.shape) if reconstructed else None
    return Surface(elevation, unobserved, georeference, folder, reconstructed, kerb_step)


def _kerb_step(folder: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """The kerb steps beside a surface stage's raster folder, None when it has none (an older workspace)."""
    try:
        workspace, site_id = Workspace.locate(folder)
    except ValueError:
        return None
    path = workspace.surface_kerb_step(site_id)
    if not path.is_file():
        return None
    try:
        return read_kerb_step(path, shape)
    except (OSError, ValueError) as err:
        raise ViewInputError(str(err)) from None


def local_frame_of(surface: Surface) -> LocalFrame:
    """A view origin at the raster's centre, at the median observed elevation."""
    geo = surface.georeference
    centre_x, centre_y = geo.global_from_pixel([(geo.width - 1) / 2, (geo.height - 1) / 2])[0]
    observed = surface.elevation[~surface.unobserved]
    z = float(np.median(observed)) if observed.size else 0.0
    return LocalFrame(np.array([centre_x, centre_y, z]))


def raster_mesh(
    surface: Surface, photometric: np.ndarray, frame: LocalFrame, *, max_faces: int
) -> trimesh.Trimesh:
    """A coloured grid mesh of the observed cells standing on their kerb steps, subsampled so it has at most
    `max_faces` triangles."""
    valid = ~surface.unobserved
    stride = max(1, int(np.ceil(np.sqrt(2 * valid.sum() / max(max_faces, 1)))))
    rows, cols = np.arange(0, valid.shape[0], stride), np.arange(0, valid.shape[1], stride)
    grid_valid = valid[np.ix_(rows, cols)]
    index = np.full(grid_valid.shape, -1, dtype=np.int64)
    index[grid_valid] = np.arange(int(grid_valid.sum()))
    rr, cc = np.nonzero(grid_valid)
    xy = surface.georeference.global_from_pixel(np.column_stack([cols[cc], rows[rr]]))
    ground = surface.elevation
    if surface.kerb_step is not None:
        ground = ground + np.nan_to_num(surface.kerb_step)
    vertices = frame.from_global(np.column_stack([xy, ground[rows[rr], cols[cc]]]))
    a, b, c, d = index[:-1, :-1], index[:-1, 1:], index[1:, :-1], index[1:, 1:]
    quad = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    faces = np.concatenate(
        [np.column_stack([a[quad], c[quad], b[quad]]), np.column_stack([b[quad], c[quad], d[quad]])]
    )
    colors = photometric[rows[rr], cols[cc]]
    return trimesh.Trimesh(vertices=vertices, faces=faces, vertex_colors=colors, process=False)


def road_mesh(
    workspace: Path, site_id: str, surface: Surface, frame: LocalFrame, *, max_faces: int
) -> trimesh.Trimesh:
    """The surface stage's `mesh.ply` when it fits the face budget, else a grid mesh made from the rasters."""
    path = Workspace(workspace).surface_mesh(site_id)
    if path.is_file():
        mesh = trimesh.load(path, process=False)
        if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces) <= max_faces:
            mesh.vertices = frame.from_global(mesh.vertices)
            return mesh
        logger.info("%s has more than %d faces: showing a grid mesh made from the rasters", path, max_faces)
    try:
        photometric = read_layer(surface.folder, "photometric")
    except (OSError, ValueError) as err:
        raise ViewInputError(str(err)) from None
    return raster_mesh(surface, photometric, frame, max_faces=max_faces)


def keyframe_cameras(dataset_root: Path, workspace: Path, site_id: str) -> list[CameraView]:
    """The site's keyframe cameras, posed by SfM when `cama sfm` has run, else by the site manifest (WIGO)."""
    ws = Workspace(workspace)
    manifest = read_site_manifest(ws.site_manifest(site_id))
    views = site_views(load_dataset(dataset_root, scenes=manifest_scenes(manifest)), manifest)
    poses_path = ws.sfm_poses(site_id)
    if not poses_path.is_file():
        return views
    from cama_pipeline.sfm.io import read_refined_poses

    refined = read_refined_poses(poses_path)
    return [replace(v, world_from_ego=refined[v.token]) for v in views if v.token in refined]


def camera_segments(views: list[CameraView], frame: LocalFrame, *, depth_m: float) -> np.ndarray:
    """(8 x cameras, 2, 3) frustum wireframes of the views in the view frame."""
    if not views:
        return np.zeros((0, 2, 3))
    parts = []
    for view in views:
        view_from_cam = view.world_from_cam.copy()
        view_from_cam[:3, 3] = frame.from_global(view_from_cam[:3, 3])
        parts.append(frustum_segments(view_from_cam, view.intrinsic, view.width, view.height, depth_m))
    return np.concatenate(parts)


def sparse_points(workspace: Path, site_id: str, frame: LocalFrame) -> SparsePointsView | None:
    """The SfM points coloured by label, or None before `cama sfm` has run."""
    path = Workspace(workspace).sfm_points(site_id)
    if not path.is_file():
        return None
    from cama_pipeline.sfm.io import read_points

    points = read_points(path)
    return SparsePointsView(frame.from_global(points.xyz), semantic_rgb(points.label))


def lift_polyline(points_xy: np.ndarray, surface: Surface, frame: LocalFrame) -> np.ndarray | None:
    """(N, 3) view-frame polyline lifted through the elevation; vertices with no elevation nearby take the
    element's median; None when no vertex has any."""
    result = lift_points(
        points_xy, surface.elevation, surface.georeference, unobserved=surface.unobserved, search_radius_m=2.0
    )
    points = result.points_3d.copy()
    known = np.isfinite(points[:, 2])
    if not known.any():
        return None
    points[~known, 2] = np.median(points[known, 2])
    return frame.from_global(points)
