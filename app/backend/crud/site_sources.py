"""Where a site's camera images and poses come from, decided once at registration.

A site may name a nuScenes-layout data set (`dataset_root`) and a pipeline workspace with the reconstruction's
site id (`workspace_dir`, `recon_site_id`) whose SfM poses pose those images. Nothing is required: a site
without them registers and its camera panel says why it shows nothing. The sources, by precedence:

- `dataset_root` / `workspace_dir` given in the request: checked against the data roots like `raster_dir`
  (a refusal names the field);
- a `raster_dir` that is a surface stage's output `<workspace>/surface/<site>/bev` (`Workspace.locate`): that
  workspace and reconstruction site;
- a `synthetic_dir`: its data set `synthetic_dir/nuscenes` and, when it holds a site with SfM poses, its
  workspace `synthetic_dir/workspace`;
- a workspace named `workspace` with a data set `nuscenes` beside it (the pipeline's default layout).

Derived folders outside the data roots are left out (logged), never stored.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from app.backend.data_roots import data_folder, inside
from app.backend.errors import InvalidInputError
from app.backend.schemas import SiteCreate
from cama_pipeline.data.loader import find_version
from cama_pipeline.workspace import WORKSPACE_DIRNAME, Workspace

logger = logging.getLogger(__name__)

DATASET_DIRNAME = "nuscenes"
"""The data set folder of a `cama synth` site, beside its default workspace."""


@dataclass(frozen=True)
class CameraSources:
    """A site's data set, workspace and reconstruction site id (resolved paths), each None when unknown."""

    dataset_root: Path | None = None
    workspace_dir: Path | None = None
    recon_site_id: str | None = None


def _readable(path: Path, roots: Sequence[Path]) -> Path | None:
    """`path` resolved when it is a readable folder inside the roots; None (logged) otherwise."""
    try:
        return data_folder(str(path), roots=roots, field="derived")
    except InvalidInputError:
        logger.info("%s: not used for the camera panel (missing, unreadable or outside the data roots)", path)
        return None


def posed_sites(workspace: Path) -> list[str]:
    """The reconstruction site ids of a workspace that have SfM poses, sorted."""
    ws = Workspace(workspace)
    sfm = ws.stage_dir("sfm")
    if not sfm.is_dir():
        return []
    return sorted(p.name for p in sfm.iterdir() if ws.sfm_poses(p.name).is_file())


def _given_dataset(value: str, roots: Sequence[Path]) -> Path:
    """The requested data set folder, checked: inside the roots and holding a version folder with tables."""
    folder = data_folder(value, roots=roots, field="dataset_root")
    try:
        find_version(folder)
    except ValueError:
        raise InvalidInputError(
            "dataset_root", "not a nuScenes-layout data set (no version folder with scene.json)"
        ) from None
    return folder


def _located(raster_dir: Path, roots: Sequence[Path]) -> tuple[Path | None, str | None]:
    """The workspace and reconstruction site of a surface stage's raster folder, when it is one."""
    try:
        location = Workspace.locate(raster_dir)
    except ValueError:
        return None, None
    workspace = _readable(location.workspace.root, roots)
    return (workspace, location.site_id) if workspace is not None else (None, None)


def camera_sources(
    site_in: SiteCreate, *, raster_dir: Path, synthetic_dir: Path | None, roots: Sequence[Path]
) -> CameraSources:
    """The camera sources of a registration (see the module docstring); InvalidInputError naming
    `dataset_root` or `workspace_dir` when a folder given in the request is refused."""
    dataset = _given_dataset(site_in.dataset_root, roots) if site_in.dataset_root is not None else None
    workspace = (
        data_folder(site_in.workspace_dir, roots=roots, field="workspace_dir")
        if site_in.workspace_dir is not None
        else None
    )
    located, recon_site = _located(raster_dir, roots)
    if workspace is None:
        workspace = located
    elif located is None or located != workspace:
        recon_site = None
    if synthetic_dir is not None:
        if dataset is None:
            dataset = _readable(synthetic_dir / DATASET_DIRNAME, roots)
        if workspace is None and posed_sites(synthetic_dir / WORKSPACE_DIRNAME):
            workspace = _readable(synthetic_dir / WORKSPACE_DIRNAME, roots)
    if workspace is not None and recon_site is None:
        sites = posed_sites(workspace)
        recon_site = sites[0] if sites else None
        if len(sites) > 1:
            logger.info(
                "%s: several reconstructions %s; the camera panel uses %s", workspace, sites, sites[0]
            )
    if dataset is None and workspace is not None and workspace.name == WORKSPACE_DIRNAME:
        beside = workspace.parent / DATASET_DIRNAME
        dataset = _readable(beside, roots) if beside.is_dir() else None
    return CameraSources(dataset, workspace, recon_site)


def within(path: Path, roots: Sequence[Path]) -> bool:
    """Whether a stored folder still lies inside the data roots (they may have changed since registration)."""
    return inside(path.resolve(), roots)
